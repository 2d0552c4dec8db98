"""Two processes over Zenoh: a robot broadcasting, a monitor awaiting its transforms.

Run (two terminals; loopback, multicast scouting off):
``python examples/zenoh_two_processes.py robot --endpoint tcp/127.0.0.1:7448`` and
``python examples/zenoh_two_processes.py monitor --endpoint tcp/127.0.0.1:7448``.

* start-up: each process opens ``Bus(ZenohTransport(...))``; the monitor waits until the
  robot is seen (``transport.alive()``), with a bound;
* the monitor awaits base_link 0.1 s ahead of its clock: answered when the robot's
  broadcast for that time arrives; a frame nobody sends times out into a message;
* cancellation and shutdown: SIGTERM/SIGINT cancel the robot's scope, then the bus closes;
  the monitor leaves its ``async with`` after ``--count`` lookups.
"""

from __future__ import annotations

import argparse
import signal

import anyio

from tfbus import (
    Buffer,
    Bus,
    Duration,
    Header,
    Quaternion,
    SystemClock,
    TimeoutException,
    Transform,
    TransformBroadcaster,
    TransformListener,
    TransformStamped,
    Vector3,
    every,
)
from tfbus.transports.zenoh import ZenohTransport


async def robot(endpoint: str, rate: float) -> None:
    clock = SystemClock()
    async with Bus(ZenohTransport(listen=endpoint, name="robot")) as bus:
        broadcaster = TransformBroadcaster(bus)
        with anyio.open_signal_receiver(signal.SIGTERM, signal.SIGINT) as signals:
            async with anyio.create_task_group() as tg:

                async def on_signal() -> None:
                    async for _ in signals:
                        tg.cancel_scope.cancel()

                tg.start_soon(on_signal)
                print(f"robot: listening on {endpoint}", flush=True)
                start = clock.now()
                async for _ in every(1.0 / rate, clock=clock, immediate=True):
                    now = clock.now()
                    await broadcaster.send_transform(TransformStamped(
                        Header(now, "odom"), "base_link",
                        Transform(Vector3((now - start).to_sec(), 0.0, 0.0), Quaternion())))
    print("robot: closed", flush=True)


async def monitor(endpoint: str, count: int) -> None:
    clock = SystemClock()
    buffer = Buffer(clock=clock)
    transport = ZenohTransport(connect=endpoint, name="monitor")
    async with Bus(transport) as bus, TransformListener(buffer, bus):
        with anyio.fail_after(30):  # the robot must be up within 30 s
            while "robot" not in {peer.name for peer in transport.alive().values()}:
                await anyio.sleep(0.05)
        for _ in range(count):
            when = clock.now() + Duration.from_sec(0.1)
            try:
                t = await buffer.lookup_transform_async("odom", "base_link", when, timeout=2.0)
            except TimeoutException as exc:
                print("monitor: no transform:", exc, flush=True)
                continue
            print(f"monitor: x = {t.transform.translation.x:.2f} m", flush=True)
        try:
            await buffer.lookup_transform_async("odom", "gripper", clock.now(), timeout=0.5)
        except TimeoutException:
            print(f"monitor: gripper unknown: {not buffer.frame_exists('gripper')}", flush=True)
    print("monitor: closed", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("role", choices=["robot", "monitor"])
    parser.add_argument("--endpoint", default="tcp/127.0.0.1:7448")
    parser.add_argument("--rate", type=float, default=50.0, help="robot: broadcasts per second")
    parser.add_argument("--count", type=int, default=10, help="monitor: lookups to make")
    parser.add_argument("--backend", default="asyncio", choices=["asyncio", "trio"])
    args = parser.parse_args()
    if args.role == "robot":
        anyio.run(robot, args.endpoint, args.rate, backend=args.backend)
    else:
        anyio.run(monitor, args.endpoint, args.count, backend=args.backend)
