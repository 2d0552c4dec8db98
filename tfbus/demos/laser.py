"""The laser demo: the tutorial's robot with a real sensor stream (``tfbus demo laser``).

The robot of ROS's "Setting up your robot using tf" tutorial drives a circle (radius
2 m, 1 rad/s, so 2 m/s) in a square room (walls at x, y = ±5 m in ``odom``). On one
bus:

* the **odometry** node sends odom → base_link at 50 Hz (the exact pose at each tick);
* the **static** broadcaster sends base_link → base_laser as in the tutorial (0.1 m
  forward, 0.2 m up);
* the **laser** node simulates a 40 Hz scanner: 720 beams over a full turn, one beam every
  ``1 / 40 / 720`` s (non-zero ``time_increment``), each range ray-cast against the room
  from the laser's exact pose at that beam's time; the scan is published when its sweep
  ends, stamped with its first beam's time;
* the **mapper** feeds the scans through a :class:`~tfbus.filters.MessageFilter` (target
  ``odom``, tolerance = the sweep, so it waits for odometry covering the last beam) and
  projects each one into ``odom`` three ways: one transform at the header stamp,
  laser_geometry's start/end interpolation, and per-beam lookups.

Once a second it prints the scans processed and, per method, the mean and maximum
distance of the projected points from the room's walls (the known geometry)::

    t=  1.0 s  scans 40  wall error mean/max mm: stamp 27.66/122.85  laser_geometry 0.11/0.29
    per_beam 0.05/0.19

(one line, wrapped here).

Run with ``tfbus demo laser --duration 10`` or ``python demos/laser_scan.py --duration 10``
(the same click command, :mod:`tfbus.cli.demo`, parses the options).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import anyio
import numpy as np
import numpy.typing as npt

from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import Clock, SystemClock, every
from tfbus.filters import MessageFilter
from tfbus.laser import LaserProjection
from tfbus.listener import TransformListener
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.sensor_msgs import LaserScan, read_points
from tfbus.time import Duration, Time
from tfbus.topics import SCAN_TOPIC

__all__ = ["METHODS", "LaserDemoStatistics", "run_laser_demo", "simulate_scan"]

ROOM_HALF = 5.0  # metres: walls at x = ±5 and y = ±5
RADIUS = 2.0  # metres
OMEGA = 1.0  # rad/s
LASER_OFFSET = (0.1, 0.0, 0.2)  # the tutorial's base_link -> base_laser
METHODS = ("stamp", "laser_geometry", "per_beam")


def base_pose(t: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], ...]:
    """Exact pose of base_link in odom at times ``t`` (s since the demo started):
    ``(x, y, yaw)`` in metres and radians."""
    a = OMEGA * t
    return RADIUS * np.cos(a), RADIUS * np.sin(a), a + math.pi / 2


def _odom(t_ns: int, epoch_ns: int) -> TransformStamped:
    x, y, yaw = (float(v[0]) for v in base_pose(np.array([(t_ns - epoch_ns) / 1e9])))
    return TransformStamped(
        Header(Time.from_ns(t_ns), "odom"), "base_link",
        Transform(Vector3(x, y, 0.0), Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))),
    )  # fmt: skip


def simulate_scan(
    stamp_ns: int, beams: int = 720, scan_rate: float = 40.0, epoch_ns: int = 0
) -> LaserScan:
    """A scan of the room whose first beam is at ``stamp_ns``: beam i is ray-cast from
    the laser's exact pose at ``stamp + i * time_increment`` (the motion starts at
    ``epoch_ns``)."""
    inc = 2 * math.pi / beams
    time_inc = float(np.float32(1.0 / scan_rate / beams))
    i = np.arange(beams)
    t = ((stamp_ns - epoch_ns) / 1e9 + i * time_inc).astype(np.float64)
    bx, by, yaw = base_pose(t)
    lx = bx + LASER_OFFSET[0] * np.cos(yaw)
    ly = by + LASER_OFFSET[0] * np.sin(yaw)
    angle_min = float(np.float32(-math.pi))
    ang = yaw + angle_min + i * float(np.float32(inc))
    c, s = np.cos(ang), np.sin(ang)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (ROOM_HALF - lx) / c, (-ROOM_HALF - lx) / c)
        ty = np.where(s > 0, (ROOM_HALF - ly) / s, (-ROOM_HALF - ly) / s)
    ranges = np.minimum(np.where(tx > 0, tx, np.inf), np.where(ty > 0, ty, np.inf))
    return LaserScan(
        header=Header(Time.from_ns(stamp_ns), "base_laser"), angle_min=angle_min,
        angle_max=angle_min + (beams - 1) * inc, angle_increment=inc,
        time_increment=time_inc, scan_time=1.0 / scan_rate, range_min=0.05, range_max=30.0,
        ranges=ranges.astype(np.float32),
    )  # fmt: skip


def wall_error(x: npt.NDArray[np.float32], y: npt.NDArray[np.float32]) -> npt.NDArray[np.float64]:
    """Distance (m) of points from the square room's boundary."""
    return np.abs(np.maximum(np.abs(x.astype(np.float64)), np.abs(y.astype(np.float64)))
                  - ROOM_HALF)  # fmt: skip


@dataclass
class LaserDemoStatistics:
    """What the demo measured: scans projected, and per method every point's wall
    error (m) of the last reporting period and overall mean / max."""

    scans: int = 0
    dropped: int = 0
    sums: dict[str, float] = field(default_factory=lambda: dict.fromkeys(METHODS, 0.0))
    maxima: dict[str, float] = field(default_factory=lambda: dict.fromkeys(METHODS, 0.0))
    points: int = 0

    def mean(self, method: str) -> float:
        """Mean wall error (m) over every projected point so far."""
        return self.sums[method] / self.points if self.points else math.nan

    def summary(self) -> str:
        """One line: scans and overall mean / max error per method (mm)."""
        per = "  ".join(f"{m} {1e3 * self.mean(m):.2f}/{1e3 * self.maxima[m]:.2f}" for m in METHODS)
        return (
            f"{self.scans} scans projected, {self.dropped} dropped; wall error mean/max mm: {per}"
        )


async def _odometry(bus: Bus, clock: Clock, rate: float, epoch_ns: int) -> None:
    broadcaster = TransformBroadcaster(bus)
    async for _ in every(1.0 / rate, clock=clock, immediate=True):
        await broadcaster.send_transform(_odom(clock.now().ns, epoch_ns))


async def _laser(bus: Bus, clock: Clock, beams: int, scan_rate: float, epoch_ns: int) -> None:
    sweep_ns = round(1e9 / scan_rate)
    async for _ in every(1.0 / scan_rate, clock=clock):
        # The sweep that just ended: its first beam was one sweep ago.
        scan = simulate_scan(clock.now().ns - sweep_ns, beams, scan_rate, epoch_ns)
        await bus.publish(SCAN_TOPIC, scan)


async def _mapper(
    buffer: Buffer,
    bus: Bus,
    clock: Clock,
    stats: LaserDemoStatistics,
    out: Callable[[str], None],
    scan_rate: float,
    beams: int,
) -> None:
    projector = LaserProjection()
    sub = bus.subscribe(SCAN_TOPIC, queue_size=10)
    sweep = Duration.from_sec(1.0 / scan_rate)
    period = LaserDemoStatistics()
    start = clock.now().ns
    next_report = start + 1_000_000_000

    def dropped(_: LaserScan, __: object) -> None:
        stats.dropped += 1

    async with MessageFilter(buffer, "odom", sub, tolerance=sweep, on_failure=dropped) as mf:
        async for scan in mf:
            for acc in (stats, period):
                acc.scans += 1
            for method in METHODS:
                cloud = projector.transform_laser_scan_to_point_cloud(
                    "odom",
                    scan,
                    buffer,
                    interpolation=method,  # type: ignore[arg-type]
                )
                pts = read_points(cloud, ["x", "y"])
                err = wall_error(pts["x"], pts["y"])
                for acc in (stats, period):
                    acc.sums[method] += float(err.sum())
                    acc.maxima[method] = max(acc.maxima[method], float(err.max(initial=0.0)))
            for acc in (stats, period):
                acc.points += len(pts)
            now = clock.now().ns
            if now >= next_report:
                per = "  ".join(
                    f"{m} {1e3 * period.mean(m):.2f}/{1e3 * period.maxima[m]:.2f}" for m in METHODS
                )
                out(f"t={(now - start) / 1e9:5.1f} s  scans {period.scans}  "
                    f"wall error mean/max mm: {per}")  # fmt: skip
                period = LaserDemoStatistics()
                next_report += 1_000_000_000


async def run_laser_demo(
    duration: float | None,
    *,
    clock: Clock | None = None,
    out: Callable[[str], None] = print,
    bus: Bus | None = None,
    beams: int = 720,
    scan_rate: float = 40.0,
    odom_rate: float = 50.0,
) -> LaserDemoStatistics:
    """Run the laser demo for ``duration`` seconds of ``clock`` time (default: the
    system clock; None: until cancelled), print a line each second and a summary line
    through ``out``, and return the statistics.

    Args:
        bus: an open bus to run on; by default a new in-process Bus.
        beams, scan_rate, odom_rate: the simulated laser (beams per sweep, Hz) and
            odometry rate (Hz).

    Raises:
        ValueError: a non-positive duration, rate or beam count.
    """
    if (duration is not None and duration <= 0) or beams < 2 or scan_rate <= 0 or odom_rate <= 0:
        raise ValueError(
            f"duration, scan_rate and odom_rate must be > 0 and beams >= 2, got {duration}, "
            f"{scan_rate}, {odom_rate}, {beams}"
        )
    clock = clock if clock is not None else SystemClock()
    stats = LaserDemoStatistics()
    buffer = Buffer(cache_time=10.0, clock=clock)
    own = bus is None
    the_bus = Bus() if bus is None else bus
    try:
        if own:
            await the_bus.__aenter__()
        try:
            async with TransformListener(buffer, the_bus, clock=clock), \
                    anyio.create_task_group() as tg:  # fmt: skip
                await StaticTransformBroadcaster(the_bus).send_transform(
                    TransformStamped(
                        Header(clock.now(), "base_link"),
                        "base_laser",
                        Transform(Vector3(*LASER_OFFSET), Quaternion(0.0, 0.0, 0.0, 1.0)),
                    )
                )
                tg.start_soon(_mapper, buffer, the_bus, clock, stats, out, scan_rate, beams)
                epoch = clock.now().ns
                tg.start_soon(_odometry, the_bus, clock, odom_rate, epoch)
                tg.start_soon(_laser, the_bus, clock, beams, scan_rate, epoch)
                if duration is not None:
                    await clock.sleep(duration)
                    tg.cancel_scope.cancel()
        finally:
            if own:
                await the_bus.__aexit__(None, None, None)
    finally:
        buffer.close()
        out(stats.summary())
    return stats

