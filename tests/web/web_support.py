"""What the tests of ``tfbus web`` share: a served bus (:class:`Served`), a raw WebSocket
client on anyio + wsproto (:class:`RawClient`, for what no real client sends), and a
subprocess's output lines read with a bound (:class:`Lines`)."""

from __future__ import annotations

import json
import math
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import anyio
import anyio.abc
from wsproto import ConnectionType, WSConnection
from wsproto.events import (
    AcceptConnection,
    CloseConnection,
    RejectConnection,
    Request,
    TextMessage,
)

from tfbus import (
    Buffer,
    Bus,
    Header,
    Quaternion,
    Time,
    Transform,
    TransformListener,
    TransformStamped,
    Vector3,
)
from tfbus.clock import Clock
from tfbus.messages import TFMessage
from tfbus.web.rosbridge import Republisher
from tfbus.web.server import TfWebServer

BOUND = 60.0
"""Seconds any wait of these tests may take (generous: load 8 on 2 cores)."""


def ts(x: float, stamp_ns: int, *, child: str = "base_link", parent: str = "world",
       yaw: float = 0.0) -> TransformStamped:
    """``child`` at ``x`` metres along ``parent``'s x axis, turned by ``yaw`` rad."""
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), q))


class Served:
    """A bus, a buffer its listener fills, and a :class:`TfWebServer` on a free port."""

    def __init__(self, bus: Bus, buffer: Buffer, server: TfWebServer) -> None:
        self.bus, self.buffer, self.server = bus, buffer, server
        self.stamp = 0

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.port}"

    def move(self, x: float, child: str = "base_link", yaw: float = 0.0) -> None:
        """Publish ``child`` at ``x`` on ``/tf`` (stamps increase by 1 ms each)."""
        self.stamp += 1_000_000
        self.bus.publish_nowait("/tf", TFMessage([ts(x, self.stamp, child=child, yaw=yaw)]))

    def republishers(self) -> list[Republisher]:
        return [r for c in self.server.clients for r in c.session.republishers.values()]

    async def until(self, what: Callable[[], object], bound: float = BOUND) -> Any:
        """Wait (polling the server's state each 10 ms, at most ``bound`` s) for ``what()``
        to be true; return it."""
        with anyio.fail_after(bound):
            while not (got := what()):
                await anyio.sleep(0.01)
        return got

    async def next_tick(self, rep: Republisher) -> None:
        """Wait until ``rep`` has run one more lookup than now."""
        start = rep.ticks
        await self.until(lambda: rep.ticks > start)


@asynccontextmanager
async def served(**kw: Any) -> AsyncIterator[Served]:
    clock: Clock | None = kw.pop("clock", None)
    buffer = Buffer(cache_time=100.0)
    async with Bus() as bus, TransformListener(buffer, bus), anyio.create_task_group() as tg:
        server = TfWebServer(buffer, bus, port=0, clock=clock, **kw)
        await tg.start(server.serve)
        yield Served(bus, buffer, server)
        tg.cancel_scope.cancel()


class RawClient:
    """A WebSocket client speaking rosbridge JSON by hand (wsproto over an anyio stream)."""

    def __init__(self, stream: anyio.abc.SocketStream) -> None:
        self.stream = stream
        self.ws = WSConnection(ConnectionType.CLIENT)
        self.status: int | None = None
        self._pending: list[str] = []
        self._parts: list[str] = []
        self.closed = False

    @classmethod
    @asynccontextmanager
    async def connect(cls, port: int, *, host: str | None = None, origin: str | None = None,
                      path: str = "/") -> AsyncIterator[RawClient]:
        stream = await anyio.connect_tcp("127.0.0.1", port)
        async with stream:
            client = cls(stream)
            headers = [(b"Origin", origin.encode())] if origin is not None else []
            await stream.send(client.ws.send(Request(
                host=host or f"127.0.0.1:{port}", target=path, extra_headers=headers)))
            with anyio.fail_after(BOUND):
                while client.status is None:
                    client.ws.receive_data(await stream.receive())
                    for event in client.ws.events():
                        if isinstance(event, AcceptConnection):
                            client.status = 101
                        elif isinstance(event, RejectConnection):
                            client.status = event.status_code
            yield client

    async def send(self, message: object) -> None:
        text = message if isinstance(message, str) else json.dumps(message)
        await self.stream.send(self.ws.send(TextMessage(text)))

    async def receive(self, bound: float = BOUND) -> dict[str, Any]:
        """The next JSON message (within ``bound`` s)."""
        with anyio.fail_after(bound):
            while not self._pending:
                try:
                    data = await self.stream.receive()
                except anyio.EndOfStream:
                    self.closed = True
                    raise
                self.ws.receive_data(data)
                for event in self.ws.events():
                    if isinstance(event, TextMessage):
                        self._parts.append(event.data)
                        if event.message_finished:
                            self._pending.append("".join(self._parts))
                            self._parts = []
                    elif isinstance(event, CloseConnection):
                        self.closed = True
        out: dict[str, Any] = json.loads(self._pending.pop(0))
        return out

    async def receive_until(self, what: Callable[[dict[str, Any]], bool],
                            bound: float = BOUND) -> dict[str, Any]:
        """The first message for which ``what`` is true (others skipped)."""
        with anyio.fail_after(bound):
            while True:
                m = await self.receive(bound)
                if what(m):
                    return m


class Lines:
    """The stdout lines of a subprocess, collected by a task (``async with``)."""

    def __init__(self, process: anyio.abc.Process) -> None:
        self.process = process
        self.lines: list[str] = []
        self.changed = anyio.Event()

    async def _read(self) -> None:
        assert self.process.stdout is not None
        buf = b""
        async for chunk in self.process.stdout:
            buf += chunk
            *done, buf = buf.split(b"\n")
            self.lines += [d.decode() for d in done]
            self.changed.set()
            self.changed = anyio.Event()

    async def wait_for(self, what: Callable[[list[str]], bool], bound: float = BOUND) -> None:
        """Wait (at most ``bound`` s) until ``what(lines)`` is true."""
        with anyio.fail_after(bound):
            while not what(self.lines):
                await self.changed.wait()

    def transforms(self) -> list[dict[str, Any]]:
        """The JSON lines (transforms received), in order."""
        return [json.loads(line) for line in self.lines if line.startswith("{")]

    def xs(self, frame: str = "base_link") -> list[float]:
        return [round(t["translation"]["x"], 6) for t in self.transforms()
                if t["frame"] == frame]

    @classmethod
    @asynccontextmanager
    async def run(cls, argv: list[str], env: dict[str, str]) -> AsyncIterator[Lines]:
        process = await anyio.open_process(argv, env=env, stderr=None)
        async with process, anyio.create_task_group() as tg:
            lines = cls(process)
            tg.start_soon(lines._read)
            try:
                yield lines
            finally:
                if process.returncode is None:
                    process.kill()  # the client this test started, by its handle
                with anyio.move_on_after(BOUND):
                    await process.wait()
                tg.cancel_scope.cancel()
