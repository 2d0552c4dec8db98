"""Carry a :class:`~tfbus.bus.Bus` across processes and machines over Zenoh.

::

    from tfbus.bus import Bus
    from tfbus.transports.zenoh import ZenohTransport

    async with Bus(transport=ZenohTransport()) as bus:   # one machine, no configuration
        ...

Every local publish goes to the other processes on the same *prefix/namespace*; their
publishes are delivered to this bus's subscribers as if published here. In-process
subscribers work exactly as without a transport. Needs the ``tfbus[zenoh]`` extra.

One module per concern (anyio's ``_core`` style; the public names are re-exported here):

* :mod:`~tfbus.transports.zenoh.keys` -- key expressions (data, latched queryables,
  liveliness) and the topic <-> key mapping;
* :mod:`~tfbus.transports.zenoh.config` -- the loopback-only defaults, config files and
  overrides (:func:`zenoh_config`, :data:`DEFAULT_PORT`);
* :mod:`~tfbus.transports.zenoh.peers` -- liveliness: :class:`PeerInfo`,
  :class:`PeerEvent` on :data:`PEERS_TOPIC`;
* :mod:`~tfbus.transports.zenoh.transport` -- :class:`ZenohTransport` (threads, receive
  path, late joiners, matching status, ``/clock`` kept newest-only for a
  :class:`~tfbus.clock.SimClock`);
* :mod:`~tfbus.transports.zenoh.queryable` -- every Zenoh queryable and query of tfbus:
  queries handed to the event loop through ``ThreadWakeup`` and a bounded queue
  (``LoopQueryable``), queryables answered in Zenoh's thread (the late-joiner latch), and
  ``get`` replies waited for on a socket, no thread per query (``get_replies``);
* :mod:`~tfbus.transports.zenoh.counters` -- :class:`ZenohStatistics`;
* :mod:`~tfbus.transports.zenoh.sequence` -- the per-publisher sequence numbers a session
  received (``SequenceTracker``: messages lost, resets, late-joiner replies);
* :mod:`~tfbus.transports.zenoh.lookups` -- lookups served to thin clients on a
  queryable (its ``BufferServer`` / ``BufferClient``; :meth:`ZenohTransport.serve_lookups`
  and :meth:`ZenohTransport.lookup_client`, the ``LookupServing`` capability behind
  :class:`tfbus.remote.BufferServer` / :class:`tfbus.remote.BufferClient`);
* :mod:`~tfbus.transports.zenoh.options` -- the ``zenoh`` bus spec of the command line
  (:class:`ZenohOptions`; parsing and opening are :mod:`tfbus.transports.spec`'s:
  ``open_bus("zenoh?name=planner")``).

Zenoh's own errors are raised as :class:`~tfbus.errors.TransportError`. See
``docs/zenoh.md`` for multi-host set-ups, TLS and access control.
"""

from tfbus._extras import require

require(__name__, "zenoh", "msgspec")

from tfbus.transports.zenoh.config import DEFAULT_PORT, zenoh_config
from tfbus.transports.zenoh.counters import ZenohStatistics
from tfbus.transports.zenoh.keys import DEFAULT_PREFIX
from tfbus.transports.zenoh.options import ZenohOptions, transport_from_spec
from tfbus.transports.zenoh.peers import PEERS_TOPIC, PeerEvent, PeerInfo
from tfbus.transports.zenoh.transport import ZenohTransport

__all__ = [
    "DEFAULT_PORT",
    "DEFAULT_PREFIX",
    "PEERS_TOPIC",
    "PeerEvent",
    "PeerInfo",
    "ZenohOptions",
    "ZenohStatistics",
    "ZenohTransport",
    "transport_from_spec",
    "zenoh_config",
]
