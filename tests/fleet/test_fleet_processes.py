"""A fleet as separate processes through ``tfbus router`` (127.0.0.1 only).

``tfbus router``, two robots in their namespaces (``tfbus demo broadcaster`` and
``tfbus static-transform``), ``tfbus monitor --bus "zenoh:...&namespace=*"`` and
``tfbus serve-buffer`` answering a thin :class:`~tfbus.remote.BufferClient` here. A robot
is SIGKILLed (the monitor reports it gone) and restarted (alive again, its static
transform served again). Every wait is on an output line or an answer, with a bound;
every child is killed by its PID in ``finally``.
"""

from __future__ import annotations

import signal
import socket

import anyio
import pytest

pytest.importorskip("zenoh")

from fleet_procs import Proc

from tfbus.bus import Bus
from tfbus.remote import BufferClient
from tfbus.time import Time
from tfbus.transports.zenoh import ZenohTransport


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_router_robots_monitor_and_served_lookups() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def spec(namespace: str) -> str:
        return f"zenoh:mode=client&connect={endpoint}&namespace={namespace}"

    procs: list[Proc] = []

    def start(*args: str) -> Proc:
        procs.append(Proc(*args))
        return procs[-1]

    try:
        router = start("router", "--listen", endpoint)
        router.expect(lambda s: f"listening on {endpoint}" in s)
        monitor = start("monitor", "--bus", spec("*"), "--interval", "3600")
        start("demo", "broadcaster", "--bus", spec("robotA"), "--rate", "20")
        static = ("static-transform", "1", "0", "0", "0", "0", "0", "base", "laser",
                  "--bus", spec("robotB"))
        robot_b = start(*static)
        server = start("serve-buffer", "--bus", spec("robotB"))
        server.expect(lambda s: "buffer server on tfbus/robotB/@buffer/tf2_buffer_server" in s)
        monitor.expect(lambda s: s.startswith("[alive] broadcaster robotA/"))
        monitor.expect(lambda s: s.startswith("[alive] broadcaster robotB/"))

        async def lookups() -> float:
            transport = ZenohTransport(connect=endpoint, config={"mode": "client"},
                                       namespace="robotB", topics=())
            async with Bus(transport=transport) as bus:
                client = BufferClient(bus, timeout_padding=10.0)
                t = await client.lookup_transform("base", "laser", Time(0), timeout=20.0)
                return t.transform.translation.x

        assert anyio.run(lookups) == 1.0
        # robot B is killed: gone; restarted: alive again, its static served again
        robot_b.stop(signal.SIGKILL)
        dead = monitor.expect(lambda s: s.startswith("[dead] broadcaster robotB/"))
        start(*static)
        monitor.expect(lambda s: s.startswith("[alive] broadcaster robotB/"), start=dead)
        assert anyio.run(lookups) == 1.0
        assert monitor.stop() == 0
        out = "\n".join(monitor.rest())
        assert "Robots" in out
        cells = [[c for c in line.replace("│", " ").split()] for line in out.splitlines()]
        rows = {c[0]: c[1] for c in cells if c and c[0] in ("robotA", "robotB")}
        assert rows == {"robotA": "alive", "robotB": "alive"}, out
        assert "robotA/base_laser" in out and "robotB/laser" in out, out
        assert server.stop() == 0
        assert "answered" in server.rest()[-1]
    finally:
        for p in procs:
            p.kill()


@pytest.mark.parametrize(
    ("args", "status", "message"),
    [
        (("serve-buffer", "--bus", "zenoh:namespace=*"), 2,
         "tfbus serve-buffer: error: --bus 'zenoh:namespace=*': a remote buffer needs one "
         "namespace, not a fleet bus (namespace=*)"),
        (("serve-buffer", "--bus", "memory"), 2,
         "tfbus serve-buffer: error: --bus 'memory': the 'memory' transport does not serve "
         "lookups (Zenoh, ROS 1 and ROS 2 do)"),
        (("monitor", "--bus", "zenoh:mode=router"), 2,
         "tfbus monitor: error: --bus 'zenoh:mode=router': mode must be one of peer, client, "
         "got 'router'"),
        (("router", "--listen", "bogus/1.2", "--duration", "5"), 1,
         "tfbus router: error: cannot open the bus: cannot start the Zenoh router: "),
    ],
)
def test_bad_arguments_are_one_line(args: tuple[str, ...], status: int, message: str) -> None:
    p = Proc(*args)
    assert p.proc.wait(60) == status
    lines = p.rest()
    assert len(lines) == 1 and lines[0].startswith(message), lines
