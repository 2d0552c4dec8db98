"""The laser demo (``tfbus.demos.laser``) under ManualClock on asyncio and trio: a line
each simulated second, every scan projected, and the three methods' wall errors in the
expected order (per-beam and laser_geometry's interpolation sub-millimetre, one transform
at the header stamp off by centimetres at 2 m/s and 1 rad/s)."""

from __future__ import annotations

import math

import anyio
import numpy as np
import pytest

from tfbus import Time
from tfbus.clock import ManualClock
from tfbus.demos.laser import base_pose, run_laser_demo, simulate_scan, wall_error

pytestmark = pytest.mark.anyio


async def test_demo_reports_each_second_and_orders_the_methods() -> None:
    clock = ManualClock(Time(1000))
    lines: list[str] = []
    async with anyio.create_task_group() as tg:

        async def demo() -> None:
            stats.append(await run_laser_demo(3.05, clock=clock, out=lines.append))

        stats: list = []
        tg.start_soon(demo)
        while not stats:
            await clock.advance(0.005)
    s = stats[0]
    assert [ln.split()[0] for ln in lines[:-1]] == ["t=", "t=", "t="] or len(lines) == 4
    assert 115 <= s.scans <= 122 and s.dropped == 0  # 40 Hz for 3 s
    assert s.mean("per_beam") < 5e-4 and s.maxima["per_beam"] < 2e-3
    assert s.mean("laser_geometry") < 5e-4
    assert s.mean("stamp") > 0.01 and s.maxima["stamp"] > 0.05
    assert "scans projected" in lines[-1]


def test_simulated_scan_hits_the_walls() -> None:
    scan = simulate_scan(2_000_000_000, beams=720)
    assert scan.time_increment > 0 and len(scan.ranges) == 720
    # beam 0 from the laser's pose at the stamp lands on a wall
    x, y, yaw = (float(v[0]) for v in base_pose(np.array([2.0])))
    lx, ly = x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)
    a = yaw + scan.angle_min
    px, py = lx + scan.ranges[0] * math.cos(a), ly + scan.ranges[0] * math.sin(a)
    assert wall_error(np.array([px], np.float32), np.array([py], np.float32))[0] < 1e-5
