"""Carry a :class:`~tfbus.bus.Bus`'s ``/tf`` and ``/tf_static`` to and from ROS 2 nodes on
rmw_zenoh (the Tier-1 Zenoh middleware of ROS 2), with no ROS installation.

::

    from tfbus.bus import Bus
    from tfbus.transports.rmw_zenoh import RmwZenohTransport

    async with Bus(transport=RmwZenohTransport()) as bus:   # router at 127.0.0.1:7447
        ...

or ``--bus rmw_zenoh[:domain=N&connect=tcp/HOST:7447&namespace=robot1]`` on the command
line. Needs the ``tfbus[zenoh]`` extra (eclipse-zenoh, whose ``zenoh.ext`` has the
AdvancedPublisher and AdvancedSubscriber rmw_zenoh uses). Spec-tested: the wire is
taken from rmw_zenoh's source and checked against golden vectors and an independent
implementation (``docs/rmw_zenoh.md``). One module per concern:

* :mod:`~tfbus.transports.rmw_zenoh.wire` -- key expressions, the attachment, liveliness
  tokens and QoS strings (sans-I/O);
* :mod:`~tfbus.transports.rmw_zenoh.transport` -- :class:`RmwZenohTransport` and
  :class:`RmwZenohStatistics` (session, publishers, subscribers, graph);
* :mod:`~tfbus.transports.rmw_zenoh.options` -- the ``rmw_zenoh`` bus spec.

Samples are (de)serialised by :mod:`tfbus.codecs.cdr`.
"""

from tfbus._extras import require

require(__name__, "zenoh")

from tfbus.transports.rmw_zenoh.transport import (  # noqa: E402 (after require)
    DEFAULT_ROUTER,
    RmwZenohStatistics,
    RmwZenohTransport,
    rmw_zenoh_config,
)
from tfbus.transports.rmw_zenoh.wire import TF_TYPE_HASH  # noqa: E402

__all__ = [
    "DEFAULT_ROUTER",
    "TF_TYPE_HASH",
    "RmwZenohStatistics",
    "RmwZenohTransport",
    "rmw_zenoh_config",
]
