"""tfbus in a trio WebSocket server (trio-websocket): one lookup per request message.

Run: ``python examples/trio_websocket_server.py 8765``; a client sends
``{"target": "odom", "source": "base_link", "ahead": 0.2, "timeout": 1.0}`` and gets
``{"x": ...}`` back, ``{"error": "timeout", ...}`` (504's meaning) or
``{"error": "unknown frame", ...}`` (404's).

* start-up: the bus, the listener, then the nursery of the server and the robot, nested in
  that order (tasks end before the bus closes);
* each connection's lookups run in its handler's task: a client that goes away cancels the
  wait with the handler;
* shutdown: cancelling the nursery (Ctrl-C, or ``scope.cancel()`` as the test does) ends
  the server, then the listener, then the bus.
"""

from __future__ import annotations

import json
import sys

import trio
from trio_websocket import ConnectionClosed, WebSocketRequest, serve_websocket

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


async def answer(buffer: Buffer, clock: SystemClock, request: dict[str, str]) -> dict[str, object]:
    """One lookup; its timeout becomes an error reply (unknown frame, or not yet)."""
    target, source = str(request["target"]), str(request["source"])
    timeout = float(request.get("timeout", 1.0))
    when = clock.now() + Duration.from_sec(float(request.get("ahead", 0.0)))
    try:
        t = await buffer.lookup_transform_async(target, source, when, timeout=timeout)
    except TimeoutException as exc:
        unknown = [f for f in (target, source) if not buffer.frame_exists(f)]
        if unknown:
            return {"error": "unknown frame", "frame": unknown[0]}
        return {"error": "timeout", "detail": str(exc)}
    return {"x": t.transform.translation.x, "stamp_ns": t.header.stamp.ns}


async def serve(port: int, *, task_status: trio.TaskStatus[int] = trio.TASK_STATUS_IGNORED) -> None:
    clock = SystemClock()
    buffer = Buffer(clock=clock)

    async def handler(request: WebSocketRequest) -> None:
        ws = await request.accept()
        while True:
            try:
                message = json.loads(await ws.get_message())
                await ws.send_message(json.dumps(await answer(buffer, clock, message)))
            except ConnectionClosed:
                return
            except (ValueError, KeyError, TypeError) as exc:  # a malformed request
                await ws.send_message(json.dumps({"error": "bad request", "detail": str(exc)}))

    async with Bus() as bus, TransformListener(buffer, bus), trio.open_nursery() as nursery:
        nursery.start_soon(odometry, bus, clock)
        server = await nursery.start(serve_websocket, handler, "127.0.0.1", port, None)
        print(f"listening on ws://127.0.0.1:{server.port}", flush=True)
        task_status.started(server.port)


if __name__ == "__main__":
    trio.run(serve, int(sys.argv[1]) if len(sys.argv) > 1 else 8765)
