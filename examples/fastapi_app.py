"""tfbus in a FastAPI (Starlette) application: the bus lives in the lifespan.

Run: ``uvicorn examples.fastapi_app:app --host 127.0.0.1 --port 8000``, then
``curl '127.0.0.1:8000/transform/odom/base_link?ahead=0.2'``.

* start-up: the lifespan opens the bus, the listener and the application's own tasks (the
  simulated odometry here) in that order, and leaves them in the reverse order;
* a request awaits a transform up to 0.2 s in the future; its timeout becomes HTTP 504,
  a frame the buffer has never heard of HTTP 404 (the timeout's ``__cause__``);
* a client that disconnects cancels its request's task, and with it the wait;
* shutdown: leaving the lifespan ends the tasks, then the listener, then the bus.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
from fastapi import FastAPI, HTTPException, Request

from tfbus import (
    Buffer,
    Bus,
    Duration,
    Header,
    LookupException,
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
    """Stands in for the robot: odom -> base_link at 50 Hz, driving along x at 1 m/s."""
    broadcaster = TransformBroadcaster(bus)
    start = clock.now()
    async for _ in every(0.02, clock=clock, immediate=True):
        now = clock.now()
        await broadcaster.send_transform(TransformStamped(
            Header(now, "odom"), "base_link",
            Transform(Vector3((now - start).to_sec(), 0.0, 0.0), Quaternion())))


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    clock = SystemClock()
    buffer = Buffer(clock=clock)
    # Bus outermost, the application's task group innermost: tasks that publish end
    # before the bus closes.  Pass Bus(ZenohTransport(...)) to listen to other processes.
    async with Bus() as bus, TransformListener(buffer, bus), anyio.create_task_group() as tg:
        tg.start_soon(odometry, bus, clock)
        app.state.buffer, app.state.clock = buffer, clock
        yield
        tg.cancel_scope.cancel()


app = FastAPI(lifespan=lifespan)


@app.get("/transform/{target}/{source}")
async def transform(
    request: Request, target: str, source: str, ahead: float = 0.0, timeout: float = 1.0
) -> dict[str, object]:
    """The transform ``source`` -> ``target`` at now + ``ahead`` seconds, awaited."""
    buffer: Buffer = request.app.state.buffer
    when = request.app.state.clock.now() + Duration.from_sec(ahead)
    try:
        t = await buffer.lookup_transform_async(target, source, when, timeout=timeout)
    except TimeoutException as exc:
        # The reason at the deadline, exc.__cause__, tells "never heard of it" (a
        # LookupException: 404) from "not yet" (ForwardExtrapolationException ...: 504).
        if isinstance(exc.__cause__, LookupException):
            unknown = next(f for f in (target, source) if not buffer.frame_exists(f))
            raise HTTPException(404, f"unknown frame {unknown!r}") from exc
        raise HTTPException(504, f"no transform within {timeout} s: {exc}") from exc
    v = t.transform.translation
    return {"stamp_ns": t.header.stamp.ns, "translation": [v.x, v.y, v.z]}


@app.get("/waits")
async def waits(request: Request) -> dict[str, int]:
    """Lookups waiting now (back to 0 when their clients disconnect)."""
    return {"pending": request.app.state.buffer.pending_waits}
