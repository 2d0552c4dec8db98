"""The seed demo: ROS's "Setting up your robot using tf" tutorial on a tfbus bus.

A mobile base ``base_link`` carries a laser ``base_laser`` mounted 10 cm forward and
20 cm up. Two timed tasks share one bus, as the tutorial's two nodes share ROS:

* the **broadcaster** (``robot_tf_publisher``) sends base_link → base_laser, translation
  (0.1, 0.0, 0.2) m, identity rotation, stamped with the clock's now, at 100 Hz;
* the **listener** (``robot_tf_listener``) every second transforms the point
  (1.0, 0.2, 0.0) in base_laser at ``Time(0)`` (latest) into base_link and prints::

    [ INFO] 1248138528.200823000: base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20) at time 1248138528.19

  (the tutorial's typo ``0.20. 0.00`` kept), or, when the transform is not available::

    [ERROR] ...: Received an exception trying to transform a point from "base_laser" to "base_link": <tf2 message>

Run it with ``tfbus demo``, ``make demo`` or ``python demos/robot_setup_tf.py`` (the same
click command, :mod:`tfbus.cli.demo`, parses the options once); ``--duration`` (default:
until Ctrl-C, which exits cleanly), ``--rate``, ``--listen-rate``.
On exit it prints one summary line: transforms sent, measured broadcast rate, and the
broadcaster's timer jitter (p50/p99 lateness of its ticks).

The tutorial's three terminals -- the two nodes as separate processes, over Zenoh::

    tfbus demo listener                 # prints the ERROR line each second ...
    tfbus demo broadcaster              # ... until this one is up, then the INFO lines
    tfbus monitor --bus zenoh           # a third terminal: rates, delays, live broadcasters

(or ``python demos/robot_setup_tf.py listener``). ``--bus SPEC`` picks the bus
(:mod:`tfbus.transports.spec`: ``zenoh``, ``ros2``, ``ros1``; default ``zenoh``: this machine, no
configuration). :func:`run_broadcaster` and :func:`run_listener` run one node on any open
bus; each prints its summary line on exit (Ctrl-C / SIGTERM exit cleanly).
"""

from __future__ import annotations

import signal
from collections import deque
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Final

import anyio
import anyio.abc

from tfbus.broadcaster import TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import Clock, SystemClock, every
from tfbus.convert import do_transform_point
from tfbus.errors import TransformException
from tfbus.listener import TransformListener
from tfbus.messages import (
    Header,
    Point,
    PointStamped,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time

__all__ = [
    "BROADCASTER_NAME",
    "LATENESS_WINDOW",
    "LISTENER_NAME",
    "BroadcasterStatistics",
    "LookupStatistics",
    "broadcaster_node",
    "format_error",
    "format_info",
    "listener_node",
    "run_broadcaster",
    "run_demo",
    "run_listener",
]

BROADCASTER_NAME = "robot_tf_publisher"
"""The broadcaster node's name on a Zenoh bus (the tutorial's node name)."""

LISTENER_NAME = "robot_tf_listener"
"""The listener node's name on a Zenoh bus (the tutorial's node name)."""

LASER_OFFSET = Transform(Vector3(0.1, 0.0, 0.2), Quaternion(0.0, 0.0, 0.0, 1.0))
"""base_laser in base_link: 10 cm forward, 20 cm up, no rotation (metres)."""

LASER_POINT = Point(1.0, 0.2, 0.0)
"""The point the tutorial's listener transforms, in base_laser (metres)."""


def _stamp(t: Time) -> str:
    return f"{t.sec}.{t.nanosec:09d}"


def format_info(now: Time, laser: PointStamped, base: PointStamped) -> str:
    """The tutorial listener's success line (``ROS_INFO`` in robot_tf_listener), typo kept."""
    p, q = laser.point, base.point
    return (
        f"[ INFO] {_stamp(now)}: base_laser: ({p.x:.2f}, {p.y:.2f}. {p.z:.2f}) -----> "
        f"base_link: ({q.x:.2f}, {q.y:.2f}, {q.z:.2f}) at time {base.header.stamp.to_sec():.2f}"
    )


def format_error(now: Time, error: TransformException) -> str:
    """The tutorial listener's failure line (``ROS_ERROR`` in robot_tf_listener)."""
    return (
        f"[ERROR] {_stamp(now)}: Received an exception trying to transform a point from "
        f'"base_laser" to "base_link": {error}'
    )


LATENESS_WINDOW: Final = 100_000
"""How many of the latest ticks' lateness :class:`BroadcasterStatistics` keeps (1000 s
at the tutorial's 100 Hz)."""


@dataclass
class BroadcasterStatistics:
    """What the broadcaster did: transforms ``sent``, clock times of the first and last
    send (ns), and the lateness (ns) of the latest :data:`LATENESS_WINDOW` ticks — the
    timer's jitter (a window, so that a broadcaster left running keeps its memory)."""

    sent: int = 0
    skipped: int = 0
    """Ticks the timer skipped because the loop was late for them by a period or more
    (:class:`~tfbus.clock.PeriodicTimer`'s overrun policy, ``rcl_timer``'s): on a
    starved machine the broadcast rate is ``rate * sent / (sent + skipped)``."""
    first_ns: int | None = None
    last_ns: int | None = None
    lateness_ns: deque[int] = field(default_factory=lambda: deque(maxlen=LATENESS_WINDOW))

    def rate(self) -> float:
        """Measured broadcast rate in Hz (sends per second of clock time)."""
        if self.first_ns is None or self.last_ns is None or self.last_ns == self.first_ns:
            return 0.0
        return (self.sent - 1) / ((self.last_ns - self.first_ns) / 1e9)

    def jitter_ms(self, quantile: float) -> float:
        """A quantile (0..1) of tick lateness, in milliseconds."""
        if not self.lateness_ns:
            return 0.0
        ordered = sorted(self.lateness_ns)
        return ordered[min(len(ordered) - 1, int(quantile * len(ordered)))] / 1e6

    def summary(self) -> str:
        """The one line printed on exit."""
        return (
            f"[ INFO] summary: {self.sent} transforms sent, broadcast rate "
            f"{self.rate():.2f} Hz, timer jitter p50 {self.jitter_ms(0.5):.3f} ms, "
            f"p99 {self.jitter_ms(0.99):.3f} ms"
        )


@dataclass
class LookupStatistics:
    """What the listener did: ``lookups`` attempted, of which ``transformed`` succeeded
    and ``failed`` raised a TransformException."""

    lookups: int = 0
    transformed: int = 0
    failed: int = 0

    def summary(self) -> str:
        """The one line printed on exit."""
        return (
            f"[ INFO] summary: {self.lookups} lookups, {self.transformed} transformed, "
            f"{self.failed} failed"
        )


async def broadcaster_node(
    bus: Bus, clock: Clock, rate: float = 100.0, stats: BroadcasterStatistics | None = None
) -> None:
    """The tutorial's ``robot_tf_publisher``: base_link → base_laser at ``rate`` Hz,
    stamped with the clock's now as each tick fires (the tick's ``actual`` time, the
    clock read that woke it: robot_tf_publisher's ``ros::Time::now()`` after its
    ``ros::Rate::sleep``), on absolute deadlines. Runs until cancelled."""
    broadcaster = TransformBroadcaster(bus)
    stats = stats if stats is not None else BroadcasterStatistics()
    send = broadcaster.send_transform_nowait
    async for tick in every(1.0 / rate, clock=clock, immediate=True):
        now = tick.actual  # one clock read a tick: the stamp, and the lateness below
        # The timer's wait is this loop's checkpoint: publish without another one
        # (``ros::Publisher::publish``, which robot_tf_publisher calls, never yields).
        send(TransformStamped(Header(now, "base_link"), "base_laser", LASER_OFFSET))
        now_ns = now.ns
        stats.sent += 1
        stats.skipped = tick.overruns
        if stats.first_ns is None:
            stats.first_ns = now_ns
        stats.last_ns = now_ns
        stats.lateness_ns.append(now_ns - tick.expected.ns)  # tick.lateness, without a Duration


async def listener_node(
    buffer: Buffer,
    clock: Clock,
    listen_rate: float = 1.0,
    out: Callable[[str], None] = print,
    stats: LookupStatistics | None = None,
) -> None:
    """The tutorial's ``robot_tf_listener``: every ``1/listen_rate`` s, transform
    (1.0, 0.2, 0.0) in base_laser at Time(0) (latest) into base_link and print the
    tutorial's line through ``out``. Runs until cancelled."""
    stats = stats if stats is not None else LookupStatistics()
    laser_point = PointStamped(Header(Time(0), "base_laser"), LASER_POINT)
    async for _ in every(1.0 / listen_rate, clock=clock):
        now = clock.now()
        stats.lookups += 1
        try:
            ts = buffer.lookup_transform("base_link", "base_laser", laser_point.header.stamp)
        except TransformException as exc:
            stats.failed += 1
            out(format_error(now, exc))
        else:
            stats.transformed += 1
            out(format_info(now, laser_point, do_transform_point(laser_point, ts)))


async def run_demo(
    *,
    clock: Clock | None = None,
    duration: float | None = None,
    rate: float = 100.0,
    listen_rate: float = 1.0,
    out: Callable[[str], None] = print,
    handle_signals: bool = False,
    bus: Bus | None = None,
) -> BroadcasterStatistics:
    """Run both nodes on one bus for ``duration`` seconds of ``clock`` time (None:
    until cancelled, or until SIGINT/SIGTERM when ``handle_signals``), print the summary
    line through ``out`` and return the broadcaster's statistics.

    ``bus`` is an open bus to run on (e.g. one carried over Zenoh); by default a new
    in-process :class:`~tfbus.bus.Bus`.
    """
    clock = clock if clock is not None else SystemClock()
    stats = BroadcasterStatistics()
    buffer = Buffer(cache_time=10.0, clock=clock)
    try:
        async with (
            Bus() if bus is None else _borrowed(bus) as the_bus,
            TransformListener(buffer, the_bus, clock=clock),
            anyio.create_task_group() as tg,
        ):
            tg.start_soon(broadcaster_node, the_bus, clock, rate, stats)
            tg.start_soon(listener_node, buffer, clock, listen_rate, out)
            await _stop_after(tg, clock, duration, handle_signals)
    finally:
        buffer.close()
        out(stats.summary())
    return stats


async def run_broadcaster(
    bus: Bus,
    *,
    clock: Clock | None = None,
    duration: float | None = None,
    rate: float = 100.0,
    out: Callable[[str], None] = print,
    handle_signals: bool = False,
) -> BroadcasterStatistics:
    """Run the broadcaster node alone on the open ``bus`` (one of the tutorial's
    terminals) for ``duration`` seconds of ``clock`` time (None: until cancelled, or
    until SIGINT/SIGTERM when ``handle_signals``); print its summary line through ``out``
    and return its statistics. It prints nothing else, as ``robot_tf_publisher``.

    Raises:
        Exception: whatever publishing on ``bus`` raises (e.g. the bus was closed).
    """
    clock = clock if clock is not None else SystemClock()
    stats = BroadcasterStatistics()
    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(broadcaster_node, bus, clock, rate, stats)
            await _stop_after(tg, clock, duration, handle_signals)
    finally:
        out(stats.summary())
    return stats


async def run_listener(
    bus: Bus,
    *,
    clock: Clock | None = None,
    duration: float | None = None,
    listen_rate: float = 1.0,
    out: Callable[[str], None] = print,
    handle_signals: bool = False,
) -> LookupStatistics:
    """Run the listener node alone on the open ``bus``: a Buffer fed by a
    TransformListener, and the tutorial's line (ERROR until a broadcaster is heard, then
    INFO) every ``1/listen_rate`` s through ``out``. Stops after ``duration`` seconds of
    ``clock`` time (None: when cancelled, or on SIGINT/SIGTERM when ``handle_signals``),
    prints its summary line and returns its statistics.

    Raises:
        Exception: whatever subscribing on ``bus`` raises (e.g. the bus is not open).
    """
    clock = clock if clock is not None else SystemClock()
    stats = LookupStatistics()
    buffer = Buffer(cache_time=10.0, clock=clock)
    try:
        async with (
            TransformListener(buffer, bus, clock=clock),
            anyio.create_task_group() as tg,
        ):
            tg.start_soon(listener_node, buffer, clock, listen_rate, out, stats)
            await _stop_after(tg, clock, duration, handle_signals)
    finally:
        buffer.close()
        out(stats.summary())
    return stats


async def _stop_after(
    tg: anyio.abc.TaskGroup, clock: Clock, duration: float | None, handle_signals: bool
) -> None:
    """Cancel ``tg`` after ``duration`` s of ``clock`` time and/or on SIGINT/SIGTERM."""
    if handle_signals:
        tg.start_soon(_cancel_on_signal, tg.cancel_scope)
    if duration is not None:
        await clock.sleep(duration)
        tg.cancel_scope.cancel()


async def _cancel_on_signal(scope: anyio.CancelScope) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            scope.cancel()
            return


@asynccontextmanager
async def _borrowed(bus: Bus) -> AsyncIterator[Bus]:
    """An already open bus, used as ``async with`` without closing it."""
    yield bus

