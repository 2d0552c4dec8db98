"""Transforms from a live bus: :class:`BusSource` (``--bus SPEC``), a
:class:`~tfbus.listener.TransformListener` feeding a :class:`~tfbus.buffer.Buffer` and
:class:`~tfbus.monitor.TfSummary` at once (:class:`~tfbus.monitor.MonitoredSink`), plus,
on a transport that knows its peers, the liveliness of broadcasters.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from typing import TYPE_CHECKING, Any

from tfbus.cli import _bus_spec
from tfbus.cli._common import SafeLogFormatter
from tfbus.cli._tf_source import TfSource
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC, TF_TOPICS
from tfbus.transports._base import PeerAware
from tfbus.transports.spec import schemes

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus, Subscription, Transport
    from tfbus.core.policy import ExpireAfter
    from tfbus.fleet import FleetBuffer
    from tfbus.listener import TransformListener
    from tfbus.monitor import TfSummary
    from tfbus.transports._base import PeerEvent, PeerInfo

__all__ = ["BusSource"]

_UNKNOWN_AUTHORITY = "unknown"
_SHARED_AUTHORITY = "unattributed"


class BusSource(TfSource):
    """Transforms from a live bus (``--bus SPEC``: Zenoh, ROS 2, ROS 1, ...).

    While :meth:`attach` is open, a :class:`~tfbus.listener.TransformListener` stores every
    ``/tf`` and ``/tf_static`` message other processes broadcast in :meth:`buffer` (a
    :class:`~tfbus.buffer.Buffer`, so lookups can be awaited) through a
    :class:`~tfbus.monitor.MonitoredSink`, which accounts it in :meth:`summary`
    (receive time = wall clock, delay = receive time - header stamp, as tf_monitor), and
    over Zenoh, liveliness changes of broadcasters are tracked (:attr:`gone`).

    Authority: the wire format does not say which node sent a message, so a message is
    attributed to the one live broadcaster publishing its topic; when several publish it,
    to the one its frames were attributed to while it was alone (tf_monitor's frame ->
    authority map, kept), and ``"unattributed"`` only when that does not decide. Before
    any is known a message is ``"unknown"``, and accounted to the broadcaster once its
    liveliness arrives (no row of its own). Transports without liveliness
    (:attr:`has_liveliness` False) name every sender ``"unknown_publisher"`` on ROS 1,
    as tf_monitor does there, else ``"unknown"``.

    Args:
        spec: a ``--bus`` value (:func:`tfbus.transports.spec.parse_bus_spec`).
        name: this node's name unless ``spec`` gives one (``zenoh?name=...``).
        cache_time: seconds of history the buffer keeps.
        scan_topics: ``sensor_msgs/LaserScan`` topics the transport must also carry
            (``tfbus view --scan``; :func:`tfbus.transports.spec.open_transport`).
        use_sim_time: the clock (:attr:`clock`: receive times, timers, lookups) is a
            :class:`~tfbus.clock.SimClock` following ``/clock`` on the bus once attached
            (ROS's ``use_sim_time``), instead of the wall clock.
        cache_policy: the buffer's frame expiry (``expire_after(seconds)``), or None.
    """

    def __init__(self, spec: str, *, name: str = "tfbus-cli", cache_time: float = 10.0,
                 scan_topics: Sequence[str] = (), use_sim_time: bool = False,
                 cache_policy: ExpireAfter | None = None) -> None:
        from tfbus.buffer import Buffer
        from tfbus.clock import Clock, SimClock, SystemClock
        from tfbus.monitor import MonitoredSink, TfSummary

        self.spec = spec
        self.bus_spec = _bus_spec.parse_spec(spec, name=name)
        self.name = name
        self.scan_topics = tuple(scan_topics)
        self.label = f"the bus {spec!r}"
        self.use_sim_time = use_sim_time
        self.sim_clock: SimClock | None = SimClock() if use_sim_time else None
        """The simulated clock with ``use_sim_time`` (entered while attached), else None."""
        self.clock: Clock = self.sim_clock if self.sim_clock is not None else SystemClock()
        self._buffer: Buffer = Buffer(cache_time=cache_time, clock=self.clock,
                                      cache_policy=cache_policy)
        self._summary = TfSummary()
        self.sink = MonitoredSink(self._buffer, self._summary, self.clock,
                                  attribute=self._attribute)
        self.transport: Transport | None = None
        self.bus: Bus | None = None
        """The open bus while attached (other topics can be subscribed on it)."""
        self.listener: TransformListener | None = None
        self.broadcasters_seen: dict[str, PeerInfo] = {}
        """Every broadcaster heard of through liveliness, by node id."""
        self.gone: dict[str, PeerInfo] = {}
        """Broadcasters whose liveliness went away (exited, killed or unreachable)."""
        self._problem: str | None = None
        self.fleet: FleetBuffer | None = None
        """The robots of a fleet bus (``namespace=*``) while attached."""
        self._scheme = schemes().get(self.bus_spec.scheme)
        self._peer_aware = self._scheme is not None and self._scheme.peer_aware
        # The attached transport when it is PeerAware (checked once: an isinstance of a
        # runtime-checkable Protocol costs microseconds, and the authority of every
        # message asks for the live broadcasters).
        self._peers: PeerAware | None = None
        # The live broadcasters' names on /tf and /tf_static, with the transport's
        # ``peers_version`` they were read at: every message asks for them, and they
        # change only when the transport's peers do.
        self._names: tuple[int, frozenset[str], frozenset[str]] | None = None

    def buffer(self) -> Buffer:
        return self._buffer

    def summary(self) -> TfSummary:
        return self._summary

    @property
    def invalid(self) -> int:
        """Transforms the buffer rejected (NaN, bad quaternion, bad frame ids)."""
        return self.listener.statistics().invalid if self.listener is not None else 0

    @property
    def problem(self) -> str | None:
        return self._problem

    def report_problem(self, message: str) -> None:
        """Record a one-line warning (printed at the end, exit status 1)."""
        self._problem = message

    @property
    def is_fleet(self) -> bool:
        """Whether the bus is a fleet bus (its scheme's
        :meth:`~tfbus.transports.spec.TransportScheme.is_fleet`: Zenoh's ``namespace=*``):
        every robot's frames, prefixed ``robot/`` (:class:`~tfbus.fleet.FleetBuffer`)."""
        return self._scheme is not None and self._scheme.is_fleet(self.bus_spec)

    @property
    def has_liveliness(self) -> bool:
        """Whether the transport tells which nodes broadcast (it is
        :class:`~tfbus.transports._base.PeerAware`: Zenoh's liveliness): the scheme
        table's word until attached, then the transport's own."""
        return self._peer_aware

    def alive_broadcasters(self) -> dict[str, PeerInfo]:
        """The live broadcasters now (a :class:`~tfbus.transports._base.PeerAware`
        transport's ``broadcasters()``); empty when detached or on a transport without
        liveliness."""
        peers = self._peers
        return dict(peers.broadcasters()) if peers is not None else {}

    @contextlib.asynccontextmanager
    async def attach(
        self, on_peer: Callable[[str, PeerInfo], None] | None = None
    ) -> AsyncIterator[BusSource]:
        """Open the bus and collect until the block ends.

        ``on_peer(what, info)`` is called with ``what`` = ``"alive"`` when a node starts
        broadcasting (its first ``/tf`` or ``/tf_static``) and ``"gone"`` when a known
        broadcaster's liveliness disappears.

        Raises:
            TransportError, OSError: the transport cannot be opened (endpoint in use,
                bad config, extra not installed).
        """
        import anyio

        from tfbus.bus import Bus
        from tfbus.listener import TransformListener

        transport = _bus_spec.open_spec_transport(self.bus_spec, name=self.name,
                                                  scan_topics=self.scan_topics,
                                                  use_sim_time=self.use_sim_time)
        peer_aware = transport if isinstance(transport, PeerAware) else None
        self._peer_aware = peer_aware is not None
        with _literal_logging():
            async with Bus(transport=transport, queue_size=10_000) as bus, \
                    self._following_clock(bus):
                self.transport = transport
                self._peers = peer_aware
                self.bus = bus
                if self.is_fleet:
                    from tfbus.fleet import FleetBuffer
                    from tfbus.monitor import MonitoredSink

                    # every robot's frames, robot/-prefixed, accounted to its broadcaster
                    sink = MonitoredSink(self._buffer, self._summary, self.clock)
                    self.fleet = FleetBuffer(bus, merged=True, sink=sink)
                    self.listener = None
                    receiver: Any = self.fleet
                else:
                    receiver = self.listener = TransformListener(self.sink, bus, clock=self.clock)
                async with receiver, anyio.create_task_group() as tg:
                    if peer_aware is not None:
                        peers = bus.subscribe(peer_aware.peers_topic, queue_size=1000)
                        tg.start_soon(self._watch, peers, on_peer)
                    try:
                        yield self
                    finally:
                        tg.cancel_scope.cancel()
        self.transport = None
        self._peers = None
        self._names = None
        self.bus = None

    def _following_clock(self, bus: Bus) -> contextlib.AbstractAsyncContextManager[object]:
        """The simulated clock attached to ``bus`` and entered (``use_sim_time``), else
        nothing to enter."""
        if self.sim_clock is None:
            return contextlib.nullcontext()
        return self.sim_clock.attach(bus)

    def _broadcaster_names(self, static: bool) -> frozenset[str]:
        """The names of the live broadcasters publishing ``/tf_static`` (``static``) or
        ``/tf`` (:meth:`alive_broadcasters`): read again only when the transport's
        ``peers_version`` changed (every time, on a transport without one)."""
        version = getattr(self._peers, "peers_version", None)
        cached = self._names
        if isinstance(version, int) and cached is not None and cached[0] == version:
            return cached[2] if static else cached[1]
        alive = list(self.alive_broadcasters().values())
        dynamic = frozenset(p.name for p in alive if TF_TOPIC in p.topics)
        latched = frozenset(p.name for p in alive if TF_STATIC_TOPIC in p.topics)
        self._names = (version, dynamic, latched) if isinstance(version, int) else None
        return latched if static else dynamic

    def _authority(self, static: bool) -> str:
        if not self.has_liveliness:
            named = self._scheme.unknown_authority if self._scheme is not None else None
            return named or _UNKNOWN_AUTHORITY
        names = self._broadcaster_names(static)
        if len(names) == 1:
            return next(iter(names))
        return _SHARED_AUTHORITY if names else _UNKNOWN_AUTHORITY

    def _attribute(self, static: bool, transforms: Sequence[object]) -> str:
        name = self._authority(static)
        if name != _SHARED_AUTHORITY:
            return name
        names = self._broadcaster_names(static)
        frames = self._summary.frames
        owners = set()
        for ts in transforms:
            child = getattr(ts, "child_frame_id", None)
            fs = frames.get(child) if isinstance(child, str) else None
            if fs is not None and fs.authority in names:
                owners.add(fs.authority)
        return owners.pop() if len(owners) == 1 else _SHARED_AUTHORITY

    def _attribute_unknown(self) -> None:
        """What arrived before any broadcaster was known goes to the broadcaster, when
        exactly one is known now (a single "unknown" row would otherwise stay)."""
        names = {p.name for p in self.broadcasters_seen.values()}
        if len(names) == 1 and _UNKNOWN_AUTHORITY in self._summary.authorities:
            self._summary.rename_authority(_UNKNOWN_AUTHORITY, names.pop())

    async def _watch(
        self, sub: Subscription[Any], on_peer: Callable[[str, PeerInfo], None] | None
    ) -> None:
        from tfbus.transports._base import PeerInfo

        async for event in sub:
            ev: PeerEvent = event
            known = self.broadcasters_seen.get(ev.node_id)
            if ev.alive and ev.topic.endswith(TF_TOPICS):
                topics = (known.topics if known else frozenset()) | {ev.topic}
                info = PeerInfo(ev.node_id, ev.name, topics)
                self.broadcasters_seen[ev.node_id] = info
                self.gone.pop(ev.node_id, None)
                self._attribute_unknown()
                if known is None and on_peer is not None:
                    on_peer("alive", info)
            elif (
                not ev.alive and not ev.topic and known is not None
                and ev.node_id not in self.gone
            ):
                self.gone[ev.node_id] = known
                if on_peer is not None:
                    on_peer("gone", known)


@contextlib.contextmanager
def _literal_logging() -> Any:
    """While attached, tfbus's log lines (a peer's bad transform, ...) go to stderr with
    control characters escaped, instead of Python's raw last-resort handler."""
    log = logging.getLogger("tfbus")
    handler = logging.StreamHandler()
    handler.setFormatter(SafeLogFormatter("%(name)s: %(levelname)s: %(message)s"))
    previous = log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.propagate = previous
