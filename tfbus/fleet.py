"""A fleet listener: one :class:`~tfbus.buffer.Buffer` per robot (``FleetBuffer[robot]``).

Each robot runs its bus in its own namespace (``--bus "zenoh:namespace=robot7&..."``);
a fleet listener opens its bus with ``namespace=*`` and sees every robot's topics
prefixed by the robot's name (``/robot7/tf``, ``/robot7/tf_static``;
:mod:`tfbus.transports.zenoh.fleet_keys`)::

    transport = ZenohTransport(connect="tcp/127.0.0.1:7447", config={"mode": "client"},
                               namespace="*")
    async with Bus(transport=transport) as bus, FleetBuffer(bus) as fleet:
        await fleet.wait_for_robot("robot7", timeout=5)
        t = await fleet["robot7"].lookup_transform_async("map", "base_link", Time(0), 1.0)

Robots are found through Zenoh liveliness (a node named ``robot7/<name>`` appears, see
:class:`~tfbus.transports.zenoh.PeerEvent`) or added with :meth:`FleetBuffer.add_robot`
(any bus, e.g. an in-process one). A robot whose last node goes away is reported gone
(:meth:`FleetBuffer.robots`), its buffer kept (its frames age, as in ``tfbus monitor``);
when it comes back, its nodes' latched ``/tf_static`` arrive again (the transport asks
every node that appears for them).

What peers announce is bounded: at most ``max_robots`` robots are kept (a buffer and two
subscriptions each). A robot gone for ``forget_after`` seconds of the fleet's clock is
released (buffer, subscriptions and entry; counted in
:attr:`FleetStatistics.released`); if it comes back it is followed anew. When
``max_robots`` robots are kept, a newly announced robot takes the place of the one gone
the longest (released early, counted in :attr:`FleetStatistics.evicted`), so names that
were announced and went away cannot keep a live robot out; a namespace is refused
(counted in :attr:`FleetStatistics.robots_refused`) only when every kept robot is
alive.

With ``merged=True`` there is one buffer (:attr:`FleetBuffer.merged`) holding every
robot's frames with the robot's name as a prefix (``robot7/base_link``, tf_prefix style),
so lookups can cross robots once something links their trees.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING, Any

import anyio

from tfbus.buffer import Buffer
from tfbus.clock import Clock, SystemClock, timeout_ns
from tfbus.messages import Header, TFMessage, TransformStamped
from tfbus.time import Duration
from tfbus.topics import PEERS_TOPIC, TF_STATIC_TOPIC, TF_TOPIC, TF_TOPICS

if TYPE_CHECKING:
    from tfbus.bus import Bus
    from tfbus.listener import TransformSink
    from tfbus.subscription import CallbackSubscription

__all__ = ["FleetBuffer", "FleetStatistics", "RobotInfo", "prefix_frames"]



@dataclass(frozen=True, slots=True)
class RobotInfo:
    """One robot of the fleet (:meth:`FleetBuffer.robots`).

    Attributes:
        name: the robot's namespace (``"robot7"``).
        alive: True while at least one of its nodes is alive (or it was added by hand).
        nodes: its live nodes' names (``"robot7/talker-42"``).
        broadcasters: of those, the nodes that published ``/tf`` or ``/tf_static``.
        messages: ``TFMessage`` s received from it (``/tf`` and ``/tf_static``).
        transforms: transforms received from it.
    """

    name: str
    alive: bool
    nodes: frozenset[str]
    broadcasters: frozenset[str]
    messages: int
    transforms: int


@dataclass(slots=True)
class FleetStatistics:
    """Counters of a :class:`FleetBuffer`.

    Attributes:
        messages: ``TFMessage`` s stored (every robot).
        transforms: transforms in them.
        refused: transforms the buffers did not store (invalid, old or repeated data).
        dropped: messages on a robot's tf topics that were not a ``TFMessage``.
        gone: times a robot was reported gone.
        robots_refused: namespaces announced by a peer (liveliness) that were not
            followed because ``max_robots`` robots were kept and every one of them was
            alive.
        released: robots released after being gone for ``forget_after`` seconds.
        evicted: gone robots released before ``forget_after`` to make room for a newly
            announced (or added) robot when ``max_robots`` robots were kept, the one
            gone the longest first.
    """

    messages: int = 0
    transforms: int = 0
    refused: int = 0
    dropped: int = 0
    gone: int = 0
    robots_refused: int = 0
    released: int = 0
    evicted: int = 0


@dataclass(slots=True)
class _Robot:
    name: str
    buffer: Buffer | None
    nodes: dict[str, str] = field(default_factory=dict)  # node id -> name
    broadcasters: set[str] = field(default_factory=set)  # node ids
    pinned: bool = False
    gone_ns: int | None = None  # the fleet clock's time when its last node went away
    gone_seq: int = 0  # the order of going away (ties of gone_ns)
    messages: int = 0
    transforms: int = 0
    callbacks: list[CallbackSubscription] = field(default_factory=list)


def prefix_frames(robot: str, transforms: Iterable[TransformStamped]) -> list[TransformStamped]:
    """The transforms with ``robot/`` before both frame ids (tf_prefix style; a leading
    ``/`` of an id is dropped first): ``base_link`` -> ``robot7/base_link``."""
    head = robot + "/"
    return [
        t._replace(
            header=Header(t.header.stamp, head + t.header.frame_id.removeprefix("/")),
            child_frame_id=head + t.child_frame_id.removeprefix("/"),
        )
        for t in transforms
    ]


class FleetBuffer:
    """One :class:`~tfbus.buffer.Buffer` per robot of a fleet bus (module doc).

    Use ``async with FleetBuffer(bus) as fleet:`` inside ``async with bus:``.

    Args:
        bus: an open bus: over Zenoh with ``namespace=*`` (robots found by liveliness),
            or any bus (robots added with :meth:`add_robot`; their topics are
            ``/<robot>/tf`` and ``/<robot>/tf_static``).
        merged: one buffer (:attr:`merged`) with ``robot/``-prefixed frame ids instead
            of one buffer per robot.
        cache_time: seconds of history of each buffer.
        clock: the buffers' clock (default: the system clock).
        sink: (merged only) where the prefixed transforms go instead of the merged
            buffer's ``set_transforms`` (e.g. a :class:`~tfbus.monitor.MonitoredSink`
            around it); the authority given is the robot's broadcaster name.
        max_robots: most robots kept at once (alive, gone or added); when that many are
            kept, a newly announced robot takes the place of the one gone the longest
            (released early, counted in ``evicted``), and is refused and counted
            (``robots_refused``) only when every kept robot is alive.
        forget_after: seconds of ``clock`` time after which a gone robot is released
            (``math.inf``: never). With ``merged=True`` the merged buffer keeps the
            frames it already stored (dynamic ones leave it after ``cache_time``).

    Raises:
        ValueError: ``cache_time`` or ``forget_after`` not positive, ``max_robots``
            below 1, or ``sink`` without ``merged``.
    """

    def __init__(
        self,
        bus: Bus,
        *,
        merged: bool = False,
        cache_time: float | Duration = 10.0,
        clock: Clock | None = None,
        sink: TransformSink | None = None,
        max_robots: int = 1000,
        forget_after: float = 300.0,
    ) -> None:
        seconds = cache_time.to_sec() if isinstance(cache_time, Duration) else float(cache_time)
        if not seconds > 0:
            raise ValueError(f"cache_time must be positive seconds, got {cache_time!r}")
        if not max_robots >= 1:
            raise ValueError(f"max_robots must be at least 1, got {max_robots!r}")
        if not float(forget_after) > 0:
            raise ValueError(f"forget_after must be positive seconds, got {forget_after!r}")
        self._max_robots = max_robots
        self._forget_after = float(forget_after)
        self._forget_ns = timeout_ns(self._forget_after, name="forget_after")
        self._time: Clock = clock if clock is not None else SystemClock()
        self._release_scheduled = False
        if sink is not None and not merged:
            raise ValueError("sink= is for merged=True only")
        self._bus = bus
        self._cache_time = cache_time
        self._clock = clock
        self._merged = Buffer(cache_time, clock=clock) if merged else None
        self._sink: TransformSink | None = sink if sink is not None else self._merged
        self._robots: dict[str, _Robot] = {}
        self._node_robot: dict[str, str] = {}
        self._stats = FleetStatistics()
        self._peer_callback: CallbackSubscription | None = None
        self._changed = anyio.Event()
        self._on_change: list[Callable[[str, RobotInfo], None]] = []

    # -- information -----------------------------------------------------------------

    @property
    def merged(self) -> Buffer | None:
        """The merged buffer (``merged=True``), else None."""
        return self._merged

    def __getitem__(self, robot: str) -> Buffer:
        """The buffer of ``robot`` (with ``merged=True``: the merged buffer).

        Raises:
            KeyError: no such robot has been seen or added.
        """
        entry = self._robots[robot]
        buffer = entry.buffer if entry.buffer is not None else self._merged
        assert buffer is not None
        return buffer

    def __contains__(self, robot: object) -> bool:
        """Whether ``robot`` has been seen or added."""
        return robot in self._robots

    def __iter__(self) -> Iterator[str]:
        """The robots' names, in the order they were found."""
        return iter(list(self._robots))

    def __len__(self) -> int:
        """How many robots have been seen or added (gone ones included)."""
        return len(self._robots)

    def robots(self) -> dict[str, RobotInfo]:
        """Every robot kept, alive or gone, by name (a snapshot; robots gone for
        ``forget_after`` are released first)."""
        self._release_due()
        return {name: self._info(r) for name, r in self._robots.items()}

    def statistics(self) -> FleetStatistics:
        """A copy of the counters."""
        return replace(self._stats)

    def on_change(self, callback: Callable[[str, RobotInfo], None]) -> None:
        """Call ``callback(what, info)`` with ``what`` ``"alive"`` when a robot appears
        (or comes back) and ``"gone"`` when its last node goes away. It must not raise."""
        self._on_change.append(callback)

    async def wait_for_robot(self, robot: str, timeout: float | None = None) -> Buffer:
        """Wait until ``robot`` is alive, and return its buffer.

        Args:
            timeout: wall-clock seconds (None: forever).

        Raises:
            TimeoutError: not alive within ``timeout``.
        """
        with anyio.fail_after(timeout):
            while True:
                entry = self._robots.get(robot)
                if entry is not None and self._info(entry).alive:
                    return self[robot]
                await self._changed.wait()

    # -- lifecycle -----------------------------------------------------------------

    async def __aenter__(self) -> FleetBuffer:
        """Subscribe to liveliness events and add the robots already alive; a fleet
        transport then delivers the static transforms it kept for those robots before
        they had a subscriber (``deliver_kept_statics``).

        Raises:
            RuntimeError: already entered.
            anyio.ClosedResourceError: the bus is closed.
        """
        if self._peer_callback is not None:
            raise RuntimeError("this FleetBuffer is already running")
        self._peer_callback = self._bus.subscribe_callback(PEERS_TOPIC, self._on_peer)
        transport = self._bus.transport
        alive = getattr(transport, "alive", None)
        if callable(alive):
            for node_id, info in alive().items():
                self._node_seen(node_id, info.name, info.topics)
        # statics a fleet transport kept for those robots before they had a subscriber
        kept = getattr(transport, "deliver_kept_statics", None)
        if callable(kept):
            kept()
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Unsubscribe from everything (the buffers stay readable)."""
        if self._peer_callback is not None:
            self._peer_callback.close()
            self._peer_callback = None
        for entry in self._robots.values():
            for cb in entry.callbacks:
                cb.close()
            entry.callbacks.clear()

    def add_robot(self, robot: str) -> Buffer:
        """Follow ``robot``'s ``/robot/tf`` and ``/robot/tf_static`` (kept alive until
        the fleet closes: for buses without liveliness); returns its buffer.

        Raises:
            ValueError: an empty name or one containing ``/``.
            RuntimeError: ``max_robots`` robots are kept already, every one alive (a gone
                one makes room, as for an announced robot).
        """
        entry = self._robot(robot)
        if entry is None:
            raise RuntimeError(
                f"cannot add robot {robot!r}: max_robots={self._max_robots} robots are kept"
            )
        entry.pinned = True
        self._notify("alive", entry)
        return self[robot]

    # -- internals -----------------------------------------------------------------

    def _info(self, r: _Robot) -> RobotInfo:
        return RobotInfo(
            r.name,
            r.pinned or bool(r.nodes),
            frozenset(r.nodes.values()),
            frozenset(r.nodes[n] for n in r.broadcasters if n in r.nodes),
            r.messages,
            r.transforms,
        )

    def _robot(self, robot: str) -> _Robot | None:
        """The robot's entry, made if there is room (None if ``max_robots`` are kept)."""
        entry = self._robots.get(robot)
        if entry is not None:
            return entry
        if not robot or "/" in robot:
            raise ValueError(f"robot name must be one non-empty chunk, got {robot!r}")
        if len(self._robots) >= self._max_robots:
            self._release_due()
            if len(self._robots) >= self._max_robots and not self._release_longest_gone():
                return None
        buffer = None if self._merged is not None else Buffer(self._cache_time, clock=self._clock)
        entry = self._robots[robot] = _Robot(robot, buffer)
        for static in (True, False):
            topic = f"/{robot}{TF_STATIC_TOPIC if static else TF_TOPIC}"
            entry.callbacks.append(
                self._bus.subscribe_callback(topic, partial(self._on_tf, entry, static))
            )
        return entry

    def _notify(self, what: str, entry: _Robot) -> None:
        changed, self._changed = self._changed, anyio.Event()
        changed.set()
        info = self._info(entry)
        for callback in self._on_change:
            callback(what, info)

    def _node_seen(self, node_id: str, name: str, topics: frozenset[str]) -> None:
        robot = name.split("/", 1)[0] if "/" in name else ""
        if not robot:
            return
        try:
            entry = self._robot(robot)
        except ValueError:
            return
        if entry is None:
            self._stats.robots_refused += 1
            return
        was_alive = self._info(entry).alive
        entry.gone_ns = None
        entry.nodes[node_id] = name
        self._node_robot[node_id] = robot
        if any(t.endswith(TF_TOPICS) for t in topics):
            entry.broadcasters.add(node_id)
        if not was_alive:
            self._notify("alive", entry)

    def _on_peer(self, event: Any) -> None:
        alive, node_id, name, topic = event
        if alive:
            self._node_seen(node_id, name, frozenset({topic}) if topic else frozenset())
            return
        robot = self._node_robot.get(node_id)
        entry = self._robots.get(robot) if robot is not None else None
        if entry is None:
            return
        if topic:
            return  # a topic token went away; the node's own token says when it leaves
        entry.nodes.pop(node_id, None)
        entry.broadcasters.discard(node_id)
        self._node_robot.pop(node_id, None)
        if not self._info(entry).alive:
            self._stats.gone += 1
            entry.gone_ns = self._time.now_ns()
            entry.gone_seq = self._stats.gone
            self._schedule_release()
            self._notify("gone", entry)

    def _schedule_release(self) -> None:
        """Wake :meth:`_release_due` when the earliest gone robot is due (a clock that
        cannot schedule, the system clock under trio, leaves it to the next event)."""
        if self._release_scheduled or self._forget_ns is None:
            return
        gone = [r.gone_ns for r in self._robots.values() if r.gone_ns is not None]
        if not gone:
            return
        wait_ns = min(gone) + self._forget_ns - self._time.now_ns()
        self._release_scheduled = True
        if self._time.call_later(max(wait_ns, 0) / 1e9, self._on_release_timer) is None:
            self._release_scheduled = False

    def _on_release_timer(self) -> None:
        self._release_scheduled = False
        if self._peer_callback is not None:  # the fleet is running
            self._release_due()

    def _release_due(self) -> None:
        """Release every robot gone for ``forget_after`` (its buffer and subscriptions)."""
        if self._forget_ns is None:
            return
        now = self._time.now_ns()
        for name, entry in list(self._robots.items()):
            if entry.gone_ns is not None and now - entry.gone_ns >= self._forget_ns:
                self._release(name)
                self._stats.released += 1
        self._schedule_release()

    def _release(self, name: str) -> None:
        """Release one robot: its subscriptions closed, its buffer closed (waits on it
        fail with BufferClosedException; what it stored stays readable by whoever holds
        it) and its entry dropped."""
        entry = self._robots.pop(name)
        for cb in entry.callbacks:
            cb.close()
        if entry.buffer is not None:
            entry.buffer.close()

    def _release_longest_gone(self) -> bool:
        """Make room (``max_robots`` kept): release the robot gone the longest, before its
        ``forget_after`` (counted in ``evicted``); False when every kept robot is alive."""
        gone = [(r.gone_ns, r.gone_seq, name) for name, r in self._robots.items()
                if r.gone_ns is not None]
        if not gone:
            return False
        self._release(min(gone)[2])
        self._stats.evicted += 1
        return True

    def _authority(self, entry: _Robot) -> str:
        names = sorted(entry.nodes[n] for n in entry.broadcasters if n in entry.nodes)
        return names[0] if len(names) == 1 else f"{entry.name}/unknown"

    def _on_tf(self, entry: _Robot, static: bool, message: object) -> None:
        if not isinstance(message, TFMessage):
            self._stats.dropped += 1
            return
        transforms = message.transforms
        entry.messages += 1
        entry.transforms += len(transforms)
        self._stats.messages += 1
        self._stats.transforms += len(transforms)
        authority = self._authority(entry)
        if entry.buffer is not None:
            result = entry.buffer.set_transforms(transforms, authority, static)
        else:
            assert self._sink is not None
            result = self._sink.set_transforms(
                prefix_frames(entry.name, transforms), authority, static
            )
        self._stats.refused += result.refused + len(result.errors)
