"""The two-process Zenoh recipe (examples/zenoh_two_processes.py): a robot and a monitor
on 127.0.0.1, on asyncio and on trio; the robot shuts down cleanly on SIGTERM."""

from __future__ import annotations

import re
import socket

import pytest

from .proc import Child

pytest.importorskip("zenoh")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_monitor_awaits_the_robots_broadcasts(backend: str) -> None:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    script = "examples/zenoh_two_processes.py"
    robot = Child(script, "robot", "--endpoint", endpoint, "--backend", backend)
    monitor = None
    try:
        robot.expect("robot: listening")
        monitor = Child(script, "monitor", "--endpoint", endpoint, "--count", "3",
                        "--backend", backend)
        xs = []
        for _ in range(3):
            line = monitor.expect("monitor: ")
            found = re.fullmatch(r"monitor: x = (-?\d+\.\d+) m", line)
            assert found is not None, monitor.seen
            xs.append(float(found.group(1)))
        assert xs == sorted(xs) and xs[0] >= 0.0
        assert monitor.expect("monitor: gripper") == "monitor: gripper unknown: True"
        monitor.expect("monitor: closed")
        assert monitor.proc.wait(timeout=30) == 0
        assert robot.terminate() == 0
        robot.expect("robot: closed")
        for child in (robot, monitor):
            assert not any("Traceback" in line for line in child.seen), child.seen
    finally:
        robot.kill()
        if monitor is not None:
            monitor.kill()
