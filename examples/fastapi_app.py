"""tfbus in a FastAPI (Starlette) application: the bus lives in the lifespan.

Run: ``uvicorn examples.fastapi_app:app --host 127.0.0.1 --port 8000``, then
``curl '127.0.0.1:8000/transform/odom/base_link?ahead=0.2'``.

* start-up: the lifespan opens the bus, the listener and the application's own tasks (the
  simulated odometry here) in that order, and leaves them in the reverse order;
* a request awaits a transform up to 0.2 s in the future; its timeout becomes HTTP 504,
  a frame the buffer has never heard of HTTP 404 (the timeout's ``__cause__``);
* a client that disconnects cancels its request's task, and with it the wait;
* shutdown: SIGINT or SIGTERM closes the buffer at once, so requests still awaiting a
  transform are answered 503 before the server waits for its open requests
  (:func:`close_on_shutdown_signal`); leaving the lifespan then ends the tasks, the
  listener and the bus. Under hypercorn on trio, ``examples/fastapi_hypercorn_trio.py``
  runs this app with the same shutdown.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
from fastapi import FastAPI, HTTPException, Request

from tfbus import (
    Buffer,
    BufferClosedException,
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


async def close_on_shutdown_signal(buffer: Buffer, stopping: anyio.Event) -> None:
    """On SIGINT or SIGTERM: close ``buffer``, set ``stopping``, then hand the signal to
    the server's own handler (uvicorn's), if it has one.

    uvicorn (and hypercorn) first wait for the open requests to finish and only then run
    the lifespan's exit, so a request awaiting a far-future transform would hold the
    shutdown until its own timeout. Closed, the buffer ends every waiting lookup at once
    with BufferClosedException (answered 503 below) and refuses the lookups that would
    wait; the requests finish and the server's graceful shutdown goes on. A server run
    from code waits on ``stopping`` instead (hypercorn's ``shutdown_trigger``). The
    signals arrive here through anyio, in this task, not inside a signal handler.
    """
    if threading.current_thread() is not threading.main_thread():
        return  # signals reach the main thread only (a test client's thread: none)
    wanted = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.getsignal(s) for s in wanted}
    with anyio.open_signal_receiver(*wanted) as signals:
        async for signum in signals:
            buffer.close()
            stopping.set()
            handler = previous[signum]
            # Python's own SIGINT handler raises KeyboardInterrupt: not in this task.
            if callable(handler) and handler is not signal.default_int_handler:
                handler(signum, None)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    clock = SystemClock()
    buffer = Buffer(clock=clock)
    stopping = anyio.Event()
    # Bus outermost, the application's task group innermost: tasks that publish end
    # before the bus closes.  Pass Bus(ZenohTransport(...)) to listen to other processes.
    async with Bus() as bus, TransformListener(buffer, bus), anyio.create_task_group() as tg:
        tg.start_soon(odometry, bus, clock)
        tg.start_soon(close_on_shutdown_signal, buffer, stopping)
        app.state.buffer, app.state.clock, app.state.stopping = buffer, clock, stopping
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
    except BufferClosedException as exc:  # the server is shutting down
        raise HTTPException(503, "shutting down: no transform will come") from exc
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
