"""A fleet viewer process for the multi-host test (``python fleet_viewer_side.py ENDPOINT``).

Opens a fleet bus (``namespace=*``, Zenoh client of the router at ENDPOINT) with a
:class:`~tfbus.fleet.FleetBuffer` and prints one line per event, flushed:

    ready                                  the bus is open
    alive ROBOT / gone ROBOT               liveliness of each robot
    result ROBOT TARGET SOURCE X           a lookup resolved (X: translation.x)
    error ROBOT TARGET SOURCE CLASS        a lookup failed

Commands on stdin, one per line: ``lookup ROBOT TARGET SOURCE TIMEOUT`` starts a lookup
at ``Time(0)`` (waits for the robot, then for the transform, ``TIMEOUT`` seconds each);
``ahead ROBOT TARGET SOURCE SECONDS TIMEOUT`` one at the system time ``SECONDS`` from
now (resolved by transforms stamped later than that); ``quit``.
"""

from __future__ import annotations

import sys

import anyio

from tfbus.bus import Bus
from tfbus.clock import SystemClock
from tfbus.fleet import FleetBuffer, RobotInfo
from tfbus.time import Duration, Time
from tfbus.transports.zenoh import ZenohTransport


def say(line: str) -> None:
    print(line, flush=True)


async def lookup(fleet: FleetBuffer, robot: str, target: str, source: str, timeout: float,
                 ahead: float | None = None) -> None:
    what = f"{robot} {target} {source}"
    try:
        at = Time(0) if ahead is None else SystemClock().now() + Duration(ahead)
        buffer = await fleet.wait_for_robot(robot, timeout)
        t = await buffer.lookup_transform_async(target, source, at, timeout)
        say(f"result {what} {t.transform.translation.x:g}")
    except Exception as exc:  # reported to the test, which decides
        say(f"error {what} {type(exc).__name__}")


async def main(endpoint: str) -> None:
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace="*",
                               name="viewer")
    # 60 s of history: a lookup at a time inside a 10 s partition interpolates between
    # the last transform before it and the first after it (tf2 drops older ones)
    async with Bus(transport=transport) as bus, FleetBuffer(bus, cache_time=60) as fleet, \
            anyio.create_task_group() as tg:

        def changed(what: str, info: RobotInfo) -> None:
            say(f"{what} {info.name}")

        fleet.on_change(changed)
        for name, info in fleet.robots().items():
            if info.alive:
                say(f"alive {name}")
        say("ready")
        async for line in anyio.wrap_file(sys.stdin):
            words = line.split()
            if words[:1] == ["lookup"] and len(words) == 5:
                tg.start_soon(lookup, fleet, words[1], words[2], words[3], float(words[4]))
            elif words[:1] == ["ahead"] and len(words) == 6:
                tg.start_soon(lookup, fleet, words[1], words[2], words[3], float(words[5]),
                              float(words[4]))
            elif words[:1] == ["quit"]:
                break
        tg.cancel_scope.cancel()


if __name__ == "__main__":
    anyio.run(main, sys.argv[1])
