"""tfbus in a plain ``asyncio.run`` service (Python 3.11+: TaskGroup, asyncio.timeout).

Run: ``python examples/asyncio_service.py``; Ctrl-C or SIGTERM shuts it down cleanly.

* start-up: the bus, the listener, then the service's TaskGroup, nested in that order;
* a follower awaits the transform 0.1 s ahead; ``timeout=`` raises tf2's
  TimeoutException, and ``asyncio.timeout()`` around a lookup works as for any awaitable;
* cancellation: SIGTERM/SIGINT set an event; the tasks are cancelled, their waits removed;
* shutdown: the TaskGroup ends, then the listener, then the bus ("closed" is printed).
"""

from __future__ import annotations

import asyncio
import signal

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


async def odometry(bus: Bus, clock: SystemClock) -> None:
    """Stands in for the robot: odom -> base_link at 50 Hz, 1 m/s along x."""
    broadcaster = TransformBroadcaster(bus)
    start = clock.now()
    async for _ in every(0.02, clock=clock, immediate=True):
        now = clock.now()
        await broadcaster.send_transform(TransformStamped(
            Header(now, "odom"), "base_link",
            Transform(Vector3((now - start).to_sec(), 0.0, 0.0), Quaternion())))


async def follow(buffer: Buffer, clock: SystemClock) -> None:
    """Print base_link 0.1 s ahead, five times a second."""
    while True:
        when = clock.now() + Duration.from_sec(0.1)
        try:
            t = await buffer.lookup_transform_async("odom", "base_link", when, timeout=1.0)
        except TimeoutException as exc:
            print("no transform:", exc, flush=True)
        else:
            print(f"base_link: x = {t.transform.translation.x:.2f} m", flush=True)
        await asyncio.sleep(0.2)


async def gripper(buffer: Buffer, clock: SystemClock) -> None:
    """asyncio's own deadline around a lookup of a frame nobody broadcasts."""
    try:
        async with asyncio.timeout(0.5):
            await buffer.lookup_transform_async("odom", "gripper", clock.now())
    except TimeoutError:
        print(f"gripper: no transform within 0.5 s (known: {buffer.frame_exists('gripper')})",
              flush=True)


async def main() -> None:
    clock = SystemClock()
    buffer = Buffer(clock=clock)
    shutdown = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, shutdown.set)
    async with Bus() as bus, TransformListener(buffer, bus):
        async with asyncio.TaskGroup() as tg:
            tasks = [tg.create_task(odometry(bus, clock)), tg.create_task(follow(buffer, clock))]
            await gripper(buffer, clock)
            print("ready", flush=True)
            await shutdown.wait()
            for task in tasks:
                task.cancel()
        print("pending waits:", buffer.pending_waits, flush=True)
    print("closed", flush=True)


if __name__ == "__main__":
    asyncio.run(main())
