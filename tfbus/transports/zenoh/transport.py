"""ZenohTransport: a :class:`~tfbus.bus.Transport` carrying a bus over Zenoh.

Threads: Zenoh calls back on its own threads. The callbacks only append ``(kind, key,
bytes)`` to a bounded deque and, if no wake-up is pending, write one byte to a socket pair
(:class:`~tfbus.transports._base.ThreadWakeup`); the event loop, woken by that socket
(:meth:`~tfbus.transports._base.ThreadWakeup.serve`: asyncio's read callback, or
``anyio.wait_readable`` on trio), decodes and delivers everything queued, in batches of
``max_batch`` -- one wake-up per burst, never a blocked Zenoh thread, and
per-publisher order kept (one FIFO). When the deque is full (``max_pending``), the oldest
entries are dropped and counted.

A topic a :class:`~tfbus.clock.SimClock` follows (``/clock``) is kept newest-only
(:meth:`ZenohTransport.keep_newest`): Zenoh's thread reads each stamp and keeps the newest
sample, whose stamp the clock reads as its time, waking the loop only when it reaches the
clock's earliest deadline or steps back (and every :data:`NEWEST_MAX_DELAY` while the bus
has other listeners on the topic) -- a ``/clock`` at 1 kHz is not a wake-up per message.

Received bytes never end the bus: every payload that does not decode, of any kind, is a
counted, dropped message (:class:`ZenohStatistics`), and sequence numbers that jump
implausibly are reported as resets, not as billions of lost messages.

Late joiners: each transport serves the latched topics it has *itself* published
(``/tf_static`` merged per child frame by a :class:`~tfbus.latch.StaticLatch`) on a
queryable answered in Zenoh's thread from the latched snapshot of what it has handed to
Zenoh, numbered as its last payload handed over
(:mod:`tfbus.transports.zenoh.queryable`, the home of tfbus's Zenoh queryables); when
a node appears (liveliness), the others query it, so a listener started after a static
broadcaster -- or a broadcaster whose first publish raced the connection --
still gets its static transforms.

Sending: latched topics (``/tf_static``) are put with ``CongestionControl.BLOCK`` and
``Reliability.RELIABLE`` from a worker thread (``anyio.to_thread``), never from the event
loop; at most one of their messages waits per topic (a newer one is merged into it, as
tf2_ros' StaticTransformBroadcaster republishes the merged set), so they are never
dropped by tfbus nor by Zenoh. Other topics are put with ``CongestionControl.DROP`` from
the event loop (Zenoh drops under congestion and does not tell the sender: receivers count
the gap in ``lost``), or, with ``congestion_control="block"``, through the same worker
with ``BLOCK``: then the only drops are tfbus' own, from a bounded send queue
(``max_send_pending``), counted in ``send_dropped``.

Errors of Zenoh itself (``zenoh.ZError``) are raised as
:class:`~tfbus.errors.TransportError` with the ``ZError`` as ``__cause__``.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Final

import anyio
import anyio.abc
import msgspec
import zenoh

from tfbus.codecs.native import (
    MAGIC,
    WIRE_VERSION,
    Decoded,
    WireCodec,
    WireEncodeError,
    WireLimits,
    _compiled_clock_stamp,
    new_sender_id,
)
from tfbus.errors import TransportError, WireLimitError, WireVersionError
from tfbus.latch import StaticLatch
from tfbus.messages import TFMessage
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import TIME_MAX_NS
from tfbus.topics import TF_STATIC_TOPIC
from tfbus.transports._base import BusLike, ThreadWakeup, heard_beyond
from tfbus.transports._newest import NEWEST_MAX_DELAY as NEWEST_MAX_DELAY
from tfbus.transports._newest import any_due
from tfbus.transports.zenoh.config import (
    DEFAULT_PORT,
    ZenohConfigSource,
    default_name,
    open_waiting,
    zenoh_config,
)
from tfbus.transports.zenoh.counters import ZenohStatistics
from tfbus.transports.zenoh.fleet_keys import key_space
from tfbus.transports.zenoh.keys import DEFAULT_PREFIX
from tfbus.transports.zenoh.peers import PEERS_TOPIC, PeerInfo, PeerTable
from tfbus.transports.zenoh.queryable import declare_answering_queryable
from tfbus.transports.zenoh.sequence import SequenceTracker

if TYPE_CHECKING:
    from tfbus.transports.zenoh.lookups import BufferClient, BufferServer

__all__ = ["ZenohStatistics", "ZenohTransport"]

log = logging.getLogger("tfbus.transports.zenoh")

_LATCHED_DEFAULT: Final = (TF_STATIC_TOPIC,)
_SAMPLE: Final = 0
_REPLY: Final = 1
_ALIVE_PUT: Final = 2
_ALIVE_DEL: Final = 3
_MATCHING: Final = 4
_REQUERY: Final = 5
_NEWEST: Final = 6  # a sample of a newest-only topic: no gap counted in ``lost``
_PUT: Final = zenoh.SampleKind.PUT  # looked up once: compared on every sample
LATCH_QUERY_RETRIES: Final = 3
"""Times a late-joiner query that got no reply at all is asked again (after 0.1, 0.2 and
0.4 s): a node's liveliness token can reach a peer before the route to its latch
queryable does, and such a query ends with nothing."""
_CONGESTION: Final = ("drop", "block")
MAX_ROUTE_KEYS: Final = 256
"""Most data keys a :class:`ZenohTransport` declares to its session as key expressions of
their own (:meth:`zenoh.Session.declare_keyexpr`), one for each topic it receives, the
first ones first. The transport subscribes to every topic with one wildcard expression;
Zenoh keeps the route of a sample (which local subscribers it reaches) on a resource of
the session's, and a key no local declaration names has none, so Zenoh's receiving
thread computes its route again for every sample (measured: following ``/clock`` at
1 kHz cost about 1 % of a core more than with an exact subscriber;
``benchmarks/bench_sim_clock.py``). A key declared once keeps its route cached; keys
beyond the bound (a peer inventing topic names) are received as before, uncached."""


class NewestOnly:
    """A newest-only topic of a :class:`ZenohTransport` (:meth:`ZenohTransport.keep_newest`):
    Zenoh's thread keeps only the newest sample and wakes the event loop when a follower
    says a sample is due, on a step back, or :data:`NEWEST_MAX_DELAY` after the last
    wake-up while the bus has other listeners on the topic. :attr:`kept_ns` is the
    stamp the followers read as the time meanwhile. :meth:`poke` (event loop) delivers
    the sample kept, if any; :meth:`close` ends one follower's interest (with none left,
    every sample is delivered again)."""

    __slots__ = ("_dues", "_key", "_last_ns", "_lock", "_topic", "_transport", "_waked",
                 "kept_ns", "payload")

    def __init__(self, transport: ZenohTransport, topic: str, key: str) -> None:
        self._transport = transport
        self._topic = topic
        self._key = key
        self._dues: tuple[Callable[[int], bool], ...] = ()
        self._lock = threading.Lock()
        self._last_ns = -1  # the stamp of the last sample, -1 before one
        self._waked = 0.0  # time.monotonic() of the last wake-up (or listeners check)
        self.payload: bytes | None = None  # the newest sample not delivered yet
        self.kept_ns = -1
        """The newest stamp (ns) of a sample Zenoh's thread kept because no follower
        needed it yet: a step forward from every sample before it, within every
        follower's bounds, so a follower may read it as the time; -1 before one, and
        again after :meth:`stepped_back`. Raised only by Zenoh's thread, never lowered
        but by the event loop (a jump back it has delivered)."""

    @property
    def topic(self) -> str:
        """The topic kept newest-only."""
        return self._topic

    def poke(self) -> None:
        """Deliver the sample kept, if any, at the event loop's next turn (call it after
        filing a new deadline: a sample kept before the deadline existed may reach it)."""
        if self.payload is not None:
            wakeup = self._transport._wakeup
            if wakeup is not None:
                wakeup.wake()

    def follow(self, due: Callable[[int], bool]) -> NewestFollower:
        """Add a follower whose ``due`` is asked at each sample."""
        self._dues = (*self._dues, due)
        return NewestFollower(self, due)

    def unfollow(self, due: Callable[[int], bool]) -> None:
        """Remove a follower; with none left the topic is delivered sample by sample
        again (the sample kept is delivered)."""
        dues = list(self._dues)
        if due in dues:
            dues.remove(due)
        self._dues = tuple(dues)
        transport = self._transport
        if not dues and transport._newest.get(self._key) is self:
            del transport._newest[self._key]
        self.poke()

    def stepped_back(self) -> None:
        """The event loop delivered a jump back: the stamps kept before it are no longer
        the time (:attr:`kept_ns` is -1 until a sample after it is kept)."""
        self.kept_ns = -1

    def offer(self, payload: bytes) -> None:
        """A sample of the topic (Zenoh's thread): kept, or queued and the loop woken --
        after the one kept before it when it steps back or does not decode (the jump is
        seen from the newest time; a bad sample does not replace a good one)."""
        transport = self._transport
        with self._lock:
            pending, self.payload = self.payload, payload  # stored before ``due`` reads
            # clock_stamp, its compiled reader inline (one Python call fewer a sample)
            fast = (_COMPILED_STAMP(payload, MAGIC, WIRE_VERSION)
                    if _COMPILED_STAMP is not None and type(payload) is bytes else -1)
            ns = fast if fast >= 0 else _clock_stamp_schema(payload)
            now = time.monotonic()
            ordered = ns is None or ns < self._last_ns
            # a step back, no Clock (ns None), or a follower's due (any_due, inline for
            # the one follower a topic has but with several SimClocks on one bus)
            dues = self._dues
            wake = ns is None or ordered or (
                dues[0](ns) if len(dues) == 1 else any_due(dues, ns))
            if not wake and now - self._waked >= NEWEST_MAX_DELAY:
                self._waked = now  # the bus's listeners are counted at most this often
                wake = heard_beyond(transport._bus, self._topic, len(self._dues))
            if wake:
                self.payload = None
                self._waked = now
                if ns is not None:
                    self._last_ns = ns
                if pending is not None:
                    if ordered:
                        transport._push((_NEWEST, self._key, pending))
                    else:
                        transport._stats.coalesced += 1
                transport._push((_NEWEST, self._key, payload))
                return
            assert ns is not None  # a sample with no stamp woke the loop
            self._last_ns = ns
            if ns > self.kept_ns:
                self.kept_ns = ns
            if pending is not None:
                transport._stats.coalesced += 1

    def take(self) -> bytes | None:
        """The sample kept, removed (event loop)."""
        if self.payload is None:
            return None
        with self._lock:
            payload, self.payload = self.payload, None
            return payload


class NewestFollower:
    """One follower of a newest-only topic (what :meth:`ZenohTransport.keep_newest`
    returns)."""

    __slots__ = ("_due", "_newest")

    def __init__(self, newest: NewestOnly, due: Callable[[int], bool]) -> None:
        self._newest: NewestOnly | None = newest
        self._due = due

    @property
    def newest_ns(self) -> int:
        """The stamp (ns) of the newest sample Zenoh's thread kept for no follower's
        need yet (:attr:`NewestOnly.kept_ns`): a time the follower may read as now; -1
        when there is none (or once closed)."""
        newest = self._newest
        return -1 if newest is None else newest.kept_ns

    def stepped_back(self) -> None:
        """The follower took a jump back (:meth:`NewestOnly.stepped_back`)."""
        if self._newest is not None:
            self._newest.stepped_back()

    def poke(self) -> None:
        """Deliver the sample kept, if any, at the event loop's next turn (call it when
        filing a deadline: a sample kept before the deadline existed may reach it)."""
        if self._newest is not None:
            self._newest.poke()

    def close(self) -> None:
        """End this follower (idempotent)."""
        newest, self._newest = self._newest, None
        if newest is not None:
            newest.unfollow(self._due)


_CLOCK_PAYLOAD: Final = msgspec.msgpack.Decoder(tuple[int, int, str, tuple[int]])
_INT64_MAX: Final = 2**63 - 1  # the largest sender id and sequence number of the wire


_COMPILED_STAMP: Final = _compiled_clock_stamp()
"""The compiled reader of a ``Clock`` payload's stamp in the form tfbus writes it (-1
for anything else), where there is one: :func:`clock_stamp`'s fast path."""


def clock_stamp(payload: bytes) -> int | None:
    """The stamp (int ns) of a tfbus wire payload of a ``Clock`` (:mod:`tfbus.codecs.native`:
    magic byte, version, then ``[sender, seq, "Clock", [ns]]``); None for anything else,
    and for every payload :meth:`WireCodec.decode <tfbus.codecs.native.WireCodec.decode>`
    refuses (a sender id or sequence number outside [1, 2**63), as it checks them): a
    sample the event loop will drop must never take the place of the good one kept.
    Zenoh's thread reads one per ``/clock`` sample: with the compiled core, a payload in
    the form tfbus writes it is read in C (``_cwire._clock_stamp_native``, about 0.1 us);
    any other by one typed msgspec decoder (:func:`_clock_stamp_schema`, about 0.5 us)."""
    if _COMPILED_STAMP is not None and type(payload) is bytes:
        ns = _COMPILED_STAMP(payload, MAGIC, WIRE_VERSION)
        if ns >= 0:
            return ns
    return _clock_stamp_schema(payload)


def _clock_stamp_schema(payload: bytes) -> int | None:
    """:func:`clock_stamp` read by msgspec's typed decoder (every payload; the compiled
    reader's answer equals it wherever that one gives a stamp: tested)."""
    if len(payload) < 2 or payload[0] != MAGIC or payload[1] != WIRE_VERSION:
        return None
    try:
        sender, seq, tag, (ns,) = _CLOCK_PAYLOAD.decode(memoryview(payload)[2:])
    except (msgspec.DecodeError, ValueError):
        return None
    if tag != "Clock" or not (0 < sender <= _INT64_MAX and 0 < seq <= _INT64_MAX):
        return None
    return ns if 0 <= ns <= TIME_MAX_NS else None


@dataclass(slots=True)
class _Pending:
    """One message waiting in the send queue for the worker thread."""

    outlet: _Outlet
    publisher: zenoh.Publisher
    payload: bytes
    latched: bytes | None = None  # what the latch serves once this one is handed over


@dataclass(slots=True)
class _Outlet:
    topic: str
    key: str
    latched: bool
    seq: int = 0
    publisher: zenoh.Publisher | None = None
    token: zenoh.LivelinessToken | None = None
    matching_listener: Any = None
    latch: StaticLatch = field(default_factory=StaticLatch)
    latched_payload: bytes | None = None
    queued: bool = False  # put by the worker thread (BLOCK), not by the event loop
    pending: _Pending | None = None  # a latched message not yet handed to the worker


class ZenohTransport:
    """A :class:`~tfbus.bus.Transport` over Zenoh (``Bus(transport=ZenohTransport())``).

    Args:
        connect: Zenoh endpoints to connect to, e.g. ``["tcp/192.168.1.10:7448"]``.
        listen: endpoints to listen on, e.g. ``["tcp/0.0.0.0:7448"]``.
        config: a Zenoh JSON5 config file path, a ``zenoh.Config`` or a mapping of config
            paths to values (see :func:`~tfbus.transports.zenoh.zenoh_config`).
        prefix: first key-expression chunk(s) (default ``"tfbus"``).
        namespace: optional chunk(s) after the prefix (``"robot1"``): buses only see
            buses with the same prefix and namespace; ``"*"`` is a fleet listener that
            sees every robot's topics as ``/robot1/tf`` (:mod:`.fleet_keys`).
        name: this node's name as others see it (default ``"<program>-<pid>"``).
        topics: the remote topics to receive (default: all under the namespace).
        latched_topics: topics whose last message (``TFMessage``: last valid transform
            per child frame) is served to late joiners (default ``("/tf_static",)``);
            a fleet listener reads them in every robot's namespace (``/tf_static``
            latches ``/robot1/tf_static``, and a robot starting to publish it is asked
            for it).
        limits: wire-format bounds applied to received payloads.
        max_pending: capacity of the inbound queue between Zenoh threads and the event
            loop, entries; when full the oldest are dropped and counted.
        max_batch: most entries delivered per event-loop turn before yielding.
        port: the rendezvous port of the no-configuration default.
        express: send each message at once instead of letting Zenoh batch small
            messages (lower latency under load, lower peak throughput).
        congestion_control: ``"drop"`` (default): topics other than the latched ones
            are put with Zenoh's ``CongestionControl.DROP`` -- a congested link drops
            them, unseen by the sender (receivers count ``lost``); ``"block"``: every
            topic is put with ``CongestionControl.BLOCK`` from a worker thread, and the
            only drops are from the send queue, counted in ``send_dropped``. Latched
            topics are always ``BLOCK`` and reliable.
        max_send_pending: capacity of the send queue (``congestion_control="block"``),
            messages of non-latched topics; when full, the oldest is dropped and
            counted in ``send_dropped``.
        max_peers: most other live nodes tracked (:attr:`alive`); liveliness tokens of
            further nodes are ignored and counted in ``peers_over_limit``, so a peer
            declaring tokens for made-up node ids cannot grow this node's memory or
            make it query them (:class:`~tfbus.transports.zenoh.peers.PeerTable`).
        connect_timeout: seconds to keep trying while none of the ``connect`` endpoints
            answers (a ``mode=client`` session whose router is not up yet: Zenoh refuses
            to open it, "Unable to connect to any of ..."). ``None`` (default) waits as
            long as it takes, as rmw_zenoh waits for its router, logging which endpoints
            it tries once every :data:`CONNECT_LOG_PERIOD` seconds; retries back off
            from 0.25 s to 2 s. Then :class:`~tfbus.errors.TransportError`.

    Raises:
        ValueError: if ``prefix`` / ``namespace`` / ``name`` / ``congestion_control``
            are not valid, or ``max_pending`` / ``max_batch`` / ``max_send_pending`` /
            ``max_peers`` is below 1, or ``connect_timeout`` is negative or not finite.
        TransportError: if Zenoh rejects the configuration (e.g. an unreadable file).
    """

    peers_topic: str = PEERS_TOPIC
    """The local bus topic of :class:`~tfbus.transports._base.PeerEvent` messages (this
    transport is :class:`~tfbus.transports._base.PeerAware`)."""

    def __init__(
        self,
        *,
        connect: str | Sequence[str] | None = None,
        listen: str | Sequence[str] | None = None,
        config: ZenohConfigSource | None = None,
        prefix: str = DEFAULT_PREFIX,
        namespace: str = "",
        name: str | None = None,
        topics: Iterable[str] | None = None,
        latched_topics: Iterable[str] = _LATCHED_DEFAULT,
        limits: WireLimits | None = None,
        max_pending: int = 50_000,
        max_batch: int = 64,
        port: int = DEFAULT_PORT,
        express: bool = False,
        congestion_control: str = "drop",
        max_send_pending: int = 10_000,
        max_peers: int = 4096,
        connect_timeout: float | None = None,
    ) -> None:
        self._keys = key_space(prefix, namespace)
        if max_pending < 1 or max_batch < 1:
            raise ValueError("max_pending and max_batch must be at least 1")
        if congestion_control not in _CONGESTION:
            raise ValueError(
                f"congestion_control must be 'drop' or 'block', got {congestion_control!r}"
            )
        if max_send_pending < 1:
            raise ValueError(f"max_send_pending must be at least 1, got {max_send_pending!r}")
        if connect_timeout is not None and not 0 <= connect_timeout < math.inf:
            raise ValueError(
                f"connect_timeout must be None or finite seconds >= 0, got {connect_timeout!r}"
            )
        self._connect_timeout = connect_timeout
        self._block = congestion_control == "block"
        self._max_send_pending = max_send_pending
        self._send_queue: deque[_Pending] = deque()
        self._send_unlatched = 0  # entries of non-latched topics in the send queue
        self._send_ready: anyio.Event | None = None
        self._name = name if name is not None else default_name()
        if not self._name:
            raise ValueError("name must not be empty")
        self._config, self._fallback = zenoh_config(
            connect=connect, listen=listen, config=config, port=port
        )
        self._topics = None if topics is None else tuple(topics)
        self._latched = frozenset(latched_topics)
        self._codec = WireCodec(limits)
        self._sender = new_sender_id()
        self._express = express
        self._max_pending = max_pending
        self._max_batch = max_batch
        self._stats = ZenohStatistics()
        self._outlets: dict[str, _Outlet] = {}
        self._seqs = SequenceTracker()
        self._peers = PeerTable(self._keys, self._latched, max_peers=max_peers)
        self._inbox: deque[tuple[int, str, bytes]] = deque(maxlen=max_pending)
        self._wakeup: ThreadWakeup | None = None
        # The bus being run (read by Zenoh's thread: its listeners of a newest-only topic).
        self._bus: BusLike | None = None
        self._session: zenoh.Session | None = None
        self._node_id = ""
        self._running = False
        # first line of each kind, then 1 in 1000 and at most one per 5 s
        self._log = CountLimitedLog(log, 1000, clock=time.monotonic)
        self._matching_changed: anyio.Event | None = None
        self._newest: dict[str, NewestOnly] = {}  # by key: topics kept newest-only
        # Data keys received, declared to the session (MAX_ROUTE_KEYS): each value is the
        # declared zenoh.KeyExpr, or None where Zenoh refused the declaration.
        self._route_keys: dict[str, zenoh.KeyExpr | None] = {}
        # The topic of each data key a valid sample came on (MAX_ROUTE_KEYS), its route
        # declared: the keys whose samples _drain takes without KeySpace.topic_of.
        self._sample_topics: dict[str, str] = {}
        self._tf_decoder = self._codec.tf_decoder()

    # -- public information -----------------------------------------------------------

    @property
    def key_prefix(self) -> str:
        """The key-expression base: ``prefix`` or ``prefix/namespace``."""
        return self._keys.base

    def node_label(self) -> tuple[str, str]:
        """(this node's name, its Zenoh session id; ``""`` while not running)
        (:class:`~tfbus.transports._base.NodeLabelled`)."""
        return self._name, self._node_id

    @property
    def name(self) -> str:
        """This node's name."""
        return self._name

    @property
    def node_id(self) -> str:
        """This node's Zenoh session id (hex) while running, else ``""``."""
        return self._node_id

    @property
    def peers_version(self) -> int:
        """A number that changes whenever the live peers or the topics they publish may
        have changed (:meth:`alive`, :meth:`broadcasters`): what a reader derived from
        them holds while it is the same."""
        return self._peers.version

    @property
    def session(self) -> zenoh.Session | None:
        """The open Zenoh session while running (for :mod:`tfbus.remote`'s queryables),
        else None."""
        return self._session

    @property
    def running(self) -> bool:
        """True between ``run``'s ``started()`` and its end."""
        return self._running

    def alive(self) -> dict[str, PeerInfo]:
        """The other live nodes on this prefix/namespace, by node id (a snapshot).

        A node appears once Zenoh links to it and disappears when it closes, crashes or
        is killed (its link drops; a silent network partition is detected after Zenoh's
        lease, ``transport/link/tx/lease``, 10 s by default).
        """
        return self._peers.alive()

    def broadcasters(self) -> dict[str, PeerInfo]:
        """The live nodes that have published ``/tf`` or ``/tf_static``."""
        return self._peers.broadcasters()

    def matching(self, topic: str) -> bool:
        """Whether a remote subscriber receives what this node publishes on ``topic``
        now (Zenoh's matching status of this node's publisher; declared if needed).

        Raises:
            RuntimeError: if the transport is not running.
        """
        if not self._running:
            raise RuntimeError("the ZenohTransport is not running")
        publisher = self._outlet(topic).publisher
        if publisher is None:
            return False
        status: Any = publisher.matching_status  # a MatchingStatus (the stub says bool)
        return bool(status.matching)

    async def wait_matching(self, topic: str, matching: bool = True) -> None:
        """Wait until :meth:`matching` is ``matching`` for ``topic`` (Zenoh's matching
        listener wakes it). Bound it with ``anyio.fail_after``.

        Raises:
            RuntimeError: if the transport is not running.
            anyio.get_cancelled_exc_class(): if cancelled.
        """
        while True:
            changed = self._matching_changed
            if changed is None:
                changed = self._matching_changed = anyio.Event()
            if self.matching(topic) is matching:
                return
            await changed.wait()

    @property
    def congestion_control(self) -> str:
        """``"drop"`` or ``"block"``: how topics other than the latched ones are put."""
        return "block" if self._block else "drop"

    @property
    def pending(self) -> int:
        """Entries received by Zenoh's threads and not yet delivered into the bus (the
        inbound queue, at most ``max_pending``; :class:`~tfbus.transports._base.Backlogged`)."""
        return len(self._inbox)

    def statistics(self) -> ZenohStatistics:
        """A copy of the counters (see :class:`ZenohStatistics`)."""
        return replace(
            self._stats,
            refused_tokens=self._peers.refused,
            peers_over_limit=self._peers.over_limit,
            send_queued=len(self._send_queue),
        )

    def keep_newest(self, topic: str, due: Callable[[int], bool]) -> NewestFollower:
        """Deliver ``topic``, a topic of ``rosgraph_msgs/Clock`` (``/clock``), newest-only
        (ROS 2 subscribes to it keep-last 1, rclpy ``time_source.py``): Zenoh's thread
        reads each sample's stamp (:func:`clock_stamp`) and keeps only the newest sample,
        waking the event loop when ``due(stamp_ns)`` (called in Zenoh's thread, must not
        block) is true, when a stamp is earlier than the previous one (a jump back: the
        kept sample and it are delivered in order), when a sample is not a tfbus ``Clock``
        payload (delivered at once: the loop decodes, counts and drops it), or
        :data:`NEWEST_MAX_DELAY` after the last wake-up while the bus has listeners on
        ``topic`` besides the followers; every wake-up also delivers whatever is kept.
        Samples replaced before the loop saw them are counted in ``coalesced``. The
        stamp of the newest sample kept is the follower's
        :attr:`~NewestFollower.newest_ns`. A :class:`~tfbus.clock.SimClock` on a Zenoh
        bus asks for this and reads that stamp as its time: the loop runs only when a
        sleeper's deadline is reached, not at every ``/clock``.

        Several followers may keep one topic: a sample is due when one says so.

        Returns:
            the follower: :meth:`NewestFollower.poke` after filing a deadline,
            :meth:`NewestFollower.close` to end it.
        """
        key = self._keys.data(topic)
        newest = self._newest.get(key)
        if newest is None:
            newest = self._newest[key] = NewestOnly(self, topic, key)
        return newest.follow(due)

    def serve_lookups(self, buffer: Any, bus: Any, **options: Any) -> BufferServer:
        """tf2_ros ``buffer_server`` over Zenoh: a queryable answering lookups from
        ``buffer`` (:class:`tfbus.transports.zenoh.lookups.BufferServer`, its options:
        ``name``, ``max_pending``, ``max_per_peer``, ``max_wait``);
        :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            TypeError: an unknown option. ValueError: as the server's constructor.
        """
        from tfbus.transports.zenoh.lookups import BufferServer

        return BufferServer(buffer, bus, **options)

    def lookup_client(self, bus: Any, **options: Any) -> BufferClient:
        """tf2_ros ``BufferClient`` over Zenoh
        (:class:`tfbus.transports.zenoh.lookups.BufferClient`, its options: ``name``,
        ``timeout_padding``, ``max_wait``); :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            TypeError: an unknown option. ValueError: as the client's constructor.
        """
        from tfbus.transports.zenoh.lookups import BufferClient

        return BufferClient(bus, **options)

    def __repr__(self) -> str:
        state = "running" if self._running else "stopped"
        return (
            f"<ZenohTransport {state} base={self._keys.base!r} name={self._name!r} "
            f"peers={len(self._peers)}>"
        )

    # -- Transport contract ------------------------------------------------------------

    async def run(
        self,
        bus: BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Open the Zenoh session, report started, deliver remote messages until cancelled.

        Closes the session (undeclaring this node's liveliness tokens) on the way out.

        Raises:
            RuntimeError: if this transport is already running.
            TransportError: if the session cannot be opened or declared (e.g. a listen
                endpoint is in use); the ``zenoh.ZError`` is the ``__cause__``.
        """
        if self._running or self._session is not None:
            raise RuntimeError("this ZenohTransport is already running")
        session = await self._open_waiting()
        wakeup = ThreadWakeup()
        declared: list[Any] = []
        self._bus = bus
        try:
            try:
                self._declare(session, declared, wakeup)
            except zenoh.ZError as err:
                raise TransportError(f"cannot declare on the Zenoh session: {err}") from err
            self._running = True
            self._send_ready = anyio.Event()
            task_status.started()
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._send_loop)
                await self._pump(bus)
        finally:
            self._running = False
            self._send_ready = None
            with anyio.CancelScope(shield=True):
                await self._flush_sends()
            # published while the flush ran: the session is closing
            self._stats.not_connected += len(self._take_sends())
            self._session = None
            self._wakeup = None
            self._bus = None
            for outlet in self._outlets.values():
                outlet.publisher = None
                outlet.token = None
                outlet.matching_listener = None
            self._node_id = ""
            self._peers.clear()
            self._route_keys.clear()  # declared on the session closing below
            self._sample_topics.clear()
            self._matching_changed = None  # bound to this event loop
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(_close_session, session, declared)
            wakeup.close()
            self._inbox.clear()

    def send_nowait(self, topic: str, message: object) -> None:
        """Put a locally published message on the network; never blocks, never raises.

        A message that cannot be encoded is dropped and counted in ``send_errors``
        (logged once per type); a message published while not running is counted in
        ``not_connected`` (latched topics still remember it for later late joiners).
        A latched message published while the previous one of its topic still waits for
        the worker thread replaces it by the latched snapshot (every valid transform
        per child frame; same sequence number), counted in ``send_merged``; a message
        of another topic that finds the send queue full (``congestion_control="block"``)
        pushes out the oldest one, counted in ``send_dropped``.
        """
        outlet = self._outlet(topic)
        pending = outlet.pending
        seq = outlet.seq if pending is not None else outlet.seq + 1
        try:
            payload = self._codec.encode(message, sender=self._sender, seq=seq)
        except WireEncodeError as exc:
            self._stats.send_errors += 1
            self._log.log(logging.WARNING, "dropping a message on %s: %s", topic, exc)
            return
        outlet.seq = seq
        latched = self._latch(outlet, message, payload) if outlet.latched else None
        if pending is not None and latched is not None:
            pending.payload = pending.latched = latched  # not yet handed to Zenoh
            self._stats.send_merged += 1
            return
        publisher = outlet.publisher
        if publisher is None:
            if latched is not None:
                outlet.latched_payload = latched  # never put: served to late joiners now
            if self._running:
                self._stats.send_errors += 1
            else:
                self._stats.not_connected += 1
            return
        if outlet.queued:
            self._enqueue(_Pending(outlet, publisher, payload, latched))
            return
        try:
            publisher.put(payload)
        except zenoh.ZError as exc:
            self._stats.send_errors += 1
            self._log.log(logging.WARNING, "zenoh put on %s failed: %s", outlet.key, exc)
            return
        self._stats.sent += 1

    # -- internals: the send queue (event loop) and its worker thread -----------------

    def _enqueue(self, item: _Pending) -> None:
        queue = self._send_queue
        if item.outlet.latched:
            item.outlet.pending = item
        else:
            if self._send_unlatched >= self._max_send_pending:
                for i, old in enumerate(queue):  # the oldest message of a non-latched topic
                    if not old.outlet.latched:
                        del queue[i]
                        self._send_unlatched -= 1
                        self._stats.send_dropped += 1
                        break
            self._send_unlatched += 1
        queue.append(item)
        ready = self._send_ready
        if ready is not None:
            ready.set()

    def _take_sends(self) -> list[_Pending]:
        batch = list(self._send_queue)
        self._send_queue.clear()
        self._send_unlatched = 0
        for item in batch:
            item.outlet.pending = None  # handed over: a newer latched message is queued anew
            if item.latched is not None:
                # One reference assignment: the queryable thread reads old or new bytes.
                item.outlet.latched_payload = item.latched
        return batch

    async def _send_loop(self) -> None:
        while True:
            ready = self._send_ready
            assert ready is not None
            await ready.wait()
            self._send_ready = anyio.Event()
            while self._send_queue:
                await self._send(self._take_sends())

    async def _send(self, batch: list[_Pending]) -> None:
        sent, failed = await anyio.to_thread.run_sync(_put_all, batch)
        self._stats.sent += sent
        self._stats.send_errors += len(failed)
        for key, exc in failed[:1]:
            self._log.log(logging.WARNING, "zenoh put on %s failed: %s", key, exc)

    async def _flush_sends(self) -> None:
        """Hand what is still queued to Zenoh before the session closes (each put is
        bounded by Zenoh's ``congestion_control/block/wait_before_close``)."""
        if self._send_queue:
            await self._send(self._take_sends())

    # -- internals: session -----------------------------------------------------------

    async def _open_waiting(self) -> zenoh.Session:
        """Open the session, waiting for a router while no ``connect`` endpoint answers
        (:func:`~tfbus.transports.zenoh.config.open_waiting`, bounded by
        ``connect_timeout``)."""
        return await open_waiting(self._open_session, self._config, self._connect_timeout, log)

    def _open_session(self) -> zenoh.Session:
        try:
            try:
                return zenoh.open(self._config)
            except zenoh.ZError:
                if self._fallback is None:
                    raise
                log.debug("rendezvous port taken: listening on an ephemeral port")
                return zenoh.open(self._fallback)
        except zenoh.ZError as err:
            raise TransportError(f"cannot open the Zenoh session: {err}") from err

    def _declare(
        self,
        session: zenoh.Session,
        declared: list[Any],
        wakeup: ThreadWakeup,
    ) -> None:
        keys = self._keys
        self._node_id = str(session.zid())
        self._peers.own_id = self._node_id
        self._session = session
        self._wakeup = wakeup
        data_keys = (
            [keys.all_data()] if self._topics is None else [keys.data(t) for t in self._topics]
        )
        for key in data_keys:
            declared.append(
                session.declare_subscriber(
                    key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE
                )
            )
        declared.append(
            declare_answering_queryable(
                session, keys.latch(self._node_id), self._on_query,
                allowed_origin=zenoh.Locality.REMOTE,
            )
        )
        liveliness = session.liveliness()
        declared.append(liveliness.declare_token(keys.alive(self._node_id, self._name)))
        for outlet in self._outlets.values():
            self._declare_outlet(outlet)
        declared.append(liveliness.declare_subscriber(keys.alive(), self._on_alive, history=True))

    def _outlet(self, topic: str) -> _Outlet:
        outlet = self._outlets.get(topic)
        if outlet is None:
            outlet = self._outlets[topic] = _Outlet(
                topic, self._keys.data(topic), self._keys.robot_topic(topic) in self._latched
            )
            if self._session is not None:
                try:
                    self._declare_outlet(outlet)
                except zenoh.ZError as exc:
                    self._log.log(logging.WARNING, "cannot publish on %s: %s", outlet.key, exc)
        return outlet

    def _declare_outlet(self, outlet: _Outlet) -> None:
        session = self._session
        assert session is not None
        outlet.queued = outlet.latched or self._block
        publisher = session.declare_publisher(
            outlet.key,
            congestion_control=(
                zenoh.CongestionControl.BLOCK if outlet.queued else zenoh.CongestionControl.DROP
            ),
            reliability=zenoh.Reliability.RELIABLE,
            allowed_destination=zenoh.Locality.REMOTE,
            express=self._express,
        )
        topic = outlet.topic
        outlet.matching_listener = publisher.declare_matching_listener(
            lambda _status: self._push((_MATCHING, topic, b""))
        )
        outlet.publisher = publisher
        outlet.token = session.liveliness().declare_token(
            self._keys.alive(self._node_id, self._name, outlet.topic)
        )

    def _latch(self, outlet: _Outlet, message: object, payload: bytes) -> bytes:
        """The payload a late joiner is served once ``message`` (numbered
        ``outlet.seq``, written as ``payload``) is handed to Zenoh: the latched snapshot
        (every valid transform per child frame) of a ``TFMessage``, else the message.

        It is served from the handover on, not before: a reply numbered ``n`` then
        holds what the stream's payloads 1..n held, no more, so that a receiver that
        got the reply can drop the live payload ``n`` as a copy of it (and the reply to
        a query that comes while ``n`` still waits is the previous snapshot, numbered
        ``n - 1``: ``n`` itself is still to be put)."""
        if isinstance(message, TFMessage):
            outlet.latch.add(message)
            snapshot = outlet.latch.message()
            payload = self._codec.encode(snapshot, sender=self._sender, seq=outlet.seq)
        return payload

    # -- internals: Zenoh threads (keep short, never block) ---------------------------

    def _push(self, item: tuple[int, str, bytes]) -> None:
        inbox = self._inbox
        if len(inbox) >= self._max_pending:
            self._stats.overflow += 1  # deque(maxlen) drops the oldest entry
        inbox.append(item)
        wakeup = self._wakeup
        if wakeup is not None:
            wakeup.wake()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # A DELETE (``session.delete`` on a data key) carries no payload and no message:
        # ignored. Its kind is asked only of an empty payload (an empty PUT is a message
        # that does not decode: counted as malformed): every sample read in Zenoh's thread
        # is one getter of zenoh-python fewer.
        payload = sample.payload.to_bytes()
        if not payload and sample.kind != _PUT:
            return
        key = str(sample.key_expr)
        newest = self._newest.get(key) if self._newest else None
        if newest is not None:
            newest.offer(payload)
            return
        self._push((_SAMPLE, key, payload))

    def _on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is not None:
            self._push((_REPLY, str(sample.key_expr), sample.payload.to_bytes()))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        kind = _ALIVE_PUT if sample.kind == zenoh.SampleKind.PUT else _ALIVE_DEL
        self._push((kind, str(sample.key_expr), b""))

    def _on_query(self, query: zenoh.Query) -> None:
        """A late joiner's query of the latch: the latched payloads (a Zenoh thread;
        :func:`~tfbus.transports.zenoh.queryable.declare_answering_queryable` finalizes
        the query)."""
        for outlet in list(self._outlets.values()):
            payload = outlet.latched_payload
            if payload is not None:
                key = self._keys.latch(self._node_id, outlet.topic)
                if query.key_expr.intersects(key):
                    query.reply(key, payload)

    # -- internals: event loop ------------------------------------------------------------

    async def _pump(self, bus: BusLike) -> None:
        wakeup = self._wakeup
        assert wakeup is not None

        await wakeup.serve(functools.partial(self._drain, bus))

    def _drain(self, bus: BusLike, woken: bool = False) -> bool:
        """Decode and deliver up to ``max_batch`` queued entries; True if more remain.

        ``woken``: called for a wake-up of the loop (counted in ``batches``), not to go
        on with a batch.

        A sample on a data key a valid sample came on before (its topic known here, its
        route declared) whose payload the compiled decoder takes, numbered next in its stream
        with no reply of that stream delivered at or after it, is taken here: the
        counters and the stream's number :meth:`_receive` and
        ``SequenceTracker.observe`` would update, updated inline, with no call of
        theirs (a Python frame each, on every message). Any other entry goes through
        them."""
        stats = self._stats
        if woken:
            stats.batches += 1
        inbox = self._inbox
        known = self._sample_topics
        compiled = self._tf_decoder
        decode = None
        if compiled is not None:
            decode, max_bytes, max_transforms, max_id, magic, version = compiled
        seqs = self._seqs
        last = seqs.last_seq
        replied = seqs.replied_seq
        reaches = bus.reaches
        run_topic: str | None = None
        run: list[object] = []
        for _ in range(min(len(inbox), self._max_batch)):
            kind, key, payload = inbox.popleft()
            if kind in (_SAMPLE, _REPLY, _NEWEST):
                topic = known.get(key) if kind == _SAMPLE else None
                if topic is None:
                    topic = self._keys.topic_of(key, reply=kind == _REPLY)
                if topic != run_topic and run:
                    # delivered first: a subscriber an event of the run makes (a fleet
                    # following a robot on its liveliness) is there for what follows
                    self._deliver(bus, run_topic, run)
                    run = []
                got = None
                if decode is not None and topic is not None and type(payload) is bytes:
                    got = decode(payload, max_bytes, max_transforms, max_id, magic, version)
                message: object = None
                if got is not None and topic is not None and kind == _SAMPLE:
                    sender, seq, message = got
                    stream = (sender, topic)
                    taken = last.get(stream, -1) == seq - 1 and replied.get(stream, 0) < seq
                else:
                    taken = False
                if taken:
                    stats.received += 1
                    last[stream] = seq
                    if not reaches(stream[1]):
                        seqs.unseen(sender, stream[1])
                else:
                    message = self._receive(kind, topic, payload, bus, got)
                    if message is None or topic is None:
                        continue
                    if kind != _REPLY and key not in self._route_keys:
                        self._declare_route(key)
                    if kind == _SAMPLE and len(known) < MAX_ROUTE_KEYS:
                        known[key] = topic  # its route declared (or refused, or the bound met)
            elif kind == _REQUERY:
                if self._running and key in self._peers.alive():
                    self._query_latched(key, payload[0])
                continue
            elif kind == _MATCHING:
                changed = self._matching_changed
                self._matching_changed = None
                if changed is not None:
                    changed.set()
                continue
            else:
                update = self._peers.update(kind == _ALIVE_PUT, key)
                if update is None:
                    continue
                event, query = update
                if query:
                    self._query_latched(event.node_id)
                topic, message = PEERS_TOPIC, event
            if topic != run_topic:
                if run:
                    self._deliver(bus, run_topic, run)
                    run = []
                run_topic = topic
            run.append(message)
        if run:
            self._deliver(bus, run_topic, run)
        if self._newest and not inbox:
            # what Zenoh's thread kept is newer than everything it queued before: taken
            # once the queue is empty (a sample it queues meanwhile comes next time)
            for newest in list(self._newest.values()):
                kept = newest.take()
                if kept is not None:
                    message = self._receive(_NEWEST, newest.topic, kept, bus)
                    if message is not None:
                        self._deliver(bus, newest.topic, [message])
        return bool(inbox)

    def _declare_route(self, key: str) -> None:
        """Declare ``key``, the data key of a topic received, to the session
        (:data:`MAX_ROUTE_KEYS`: Zenoh then keeps its samples' route), at most once."""
        session = self._session
        if session is None or len(self._route_keys) >= MAX_ROUTE_KEYS:
            return
        try:
            declared: zenoh.KeyExpr | None = session.declare_keyexpr(key)
        except zenoh.ZError as exc:  # never a reason to drop the sample: uncached
            declared = None
            self._log.log(logging.DEBUG, "cannot declare key %s: %s", key, exc)
        self._route_keys[key] = declared

    def _receive(
        self,
        kind: int,
        topic: str | None,
        payload: bytes,
        bus: BusLike | None = None,
        decoded_tf: tuple[int, int, TFMessage] | None = None,
    ) -> object | None:
        """Decode one received payload; None (counted) when it is dropped. A payload
        that will reach no one on ``bus`` is not remembered as delivered, so that a
        later copy of it (the reply to a late joiner) is not dropped as a duplicate.
        ``decoded_tf``: ``payload`` as the compiled decoder already decoded it."""
        stats = self._stats
        stats.received += 1
        if topic is None:
            stats.refused_keys += 1
            return None
        try:
            decoded = (
                self._codec.decode(payload) if decoded_tf is None else Decoded(*decoded_tf)
            )
        except WireVersionError:
            stats.wrong_version += 1
            return None
        except WireLimitError:
            stats.over_limit += 1
            return None
        except Exception:  # WireDecodeError -- or anything else: bytes never end the bus
            stats.malformed += 1
            return None
        seqs = self._seqs
        if kind in (_SAMPLE, _NEWEST):
            lost, reset = seqs.observe(decoded.sender, topic, decoded.seq)
            if kind == _SAMPLE:  # a newest-only topic skips samples on purpose
                stats.lost += lost
            stats.resets += reset
            if not seqs.live_is_news(decoded.sender, topic, decoded.seq):
                stats.duplicates += 1
                return None
        elif seqs.reply_is_news(decoded.sender, topic, decoded.seq):
            stats.latched_replies += 1
        else:
            stats.duplicates += 1
            return None
        if bus is not None and not bus.reaches(topic):
            seqs.unseen(decoded.sender, topic)
        return decoded.message

    def _deliver(self, bus: BusLike, topic: str | None, run: list[object]) -> None:
        assert topic is not None
        if len(run) == 1:
            bus.deliver_nowait(topic, run[0])
        else:
            bus.deliver_many_nowait(topic, run)
        self._stats.delivered += len(run)

    def _query_latched(self, node_id: str, attempt: int = 0) -> None:
        """Ask ``node_id``'s latch queryable for its latched messages (a late joiner's
        query); a query that ends with no reply at all is asked again, at most
        :data:`LATCH_QUERY_RETRIES` times, while the node is alive."""
        session = self._session
        if session is None:
            return
        replies = [0]

        def on_reply(reply: zenoh.Reply) -> None:  # a Zenoh thread
            replies[0] += 1
            self._on_reply(reply)

        def on_done() -> None:  # a Zenoh thread, once the query has ended
            if replies[0] == 0 and attempt < LATCH_QUERY_RETRIES:
                timer = threading.Timer(
                    0.1 * 2**attempt, self._push, ((_REQUERY, node_id, bytes((attempt + 1,))),)
                )
                timer.daemon = True
                timer.start()

        try:
            session.get(
                self._keys.latch(node_id),
                zenoh.handlers.Callback(on_reply, on_done),
                target=zenoh.QueryTarget.ALL,
                timeout=5.0,
            )
        except zenoh.ZError as exc:
            self._log.log(logging.WARNING, "late-joiner query to %s failed: %s", node_id, exc)


def _put_all(batch: list[_Pending]) -> tuple[int, list[tuple[str, Exception]]]:
    """Put every queued message in order (a worker thread; BLOCK puts may wait)."""
    sent = 0
    failed: list[tuple[str, Exception]] = []
    for item in batch:
        try:
            item.publisher.put(item.payload)
        except zenoh.ZError as exc:
            failed.append((item.outlet.key, exc))
        else:
            sent += 1
    return sent, failed


def _close_session(session: zenoh.Session, declared: list[Any]) -> None:
    for entity in reversed(declared):
        with contextlib.suppress(Exception):
            entity.undeclare()
    with contextlib.suppress(Exception):
        session.close()  # type: ignore[no-untyped-call]
