"""TCPROS publisher side: a frame put while the subscriber's connection is idle is written
by the publishing task itself (roscpp's ``SubscriberLink::enqueueMessage`` writes from the
publishing thread); what the socket does not take goes to the connection's task, whole
frames in order, the rest of a begun frame never dropped."""

from __future__ import annotations

import contextlib
import socket
import struct
from collections.abc import AsyncIterator

import anyio
import anyio.abc
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus.transports.ros1.tcpros import FrameQueue, frame, serve_subscriber

pytestmark = pytest.mark.anyio


@contextlib.asynccontextmanager
async def _served(
    frames: FrameQueue, sent: list[int]
) -> AsyncIterator[tuple[socket.socket, anyio.abc.TaskGroup]]:
    """A real loopback connection: ``serve_subscriber`` on the accepted side, the
    subscriber a plain socket the test reads without yielding to the event loop."""
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    async with listener:
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        sub = socket.create_connection(("127.0.0.1", port), timeout=10)
        inner = listener.listeners[0]
        assert isinstance(inner, anyio.abc.SocketListener)
        stream = await inner.accept()
        with sub:
            async with stream, anyio.create_task_group() as tg:
                tg.start_soon(serve_subscriber, stream, frames, lambda: sent.append(1))
                # One frame through, read: once it is counted, the connection's task
                # waits with nothing to send (it does not yield between the two).
                hello = frame(b"hello")
                frames.put(hello)
                assert await anyio.to_thread.run_sync(_read_all, sub, len(hello)) == hello
                await _until(lambda: len(sent) == 1, "the first frame to be counted")
                yield sub, tg
                tg.cancel_scope.cancel()


async def _until(condition: object, what: str) -> None:
    with anyio.fail_after(10):  # a bound on a hung wait only
        while not condition():  # type: ignore[operator]
            await anyio.sleep(0.001)


def _read_all(sub: socket.socket, n: int) -> bytes:
    """``n`` bytes from the subscriber's socket (in a worker thread; 30 s bound)."""
    sub.settimeout(30)
    got = bytearray()
    while len(got) < n:
        chunk = sub.recv(1 << 20)
        assert chunk, "the connection closed early"
        got += chunk
    return bytes(got)


def _read_now(sub: socket.socket) -> bytes:
    """What the subscriber's socket holds right now (no wait)."""
    try:
        return sub.recv(1 << 20, socket.MSG_DONTWAIT)
    except (BlockingIOError, TimeoutError):  # EAGAIN (TimeoutError on a timed socket)
        return b""


async def test_a_frame_put_on_an_idle_connection_is_written_before_put_returns(
    anyio_backend: str,
) -> None:
    frames = FrameQueue(100)
    sent: list[int] = []
    async with _served(frames, sent) as (sub, _):
        for k in range(5):
            data = frame(b"message %d" % k)
            # No checkpoint between put and the read: loopback TCP delivers in send().
            assert frames.put(data) == 0
            assert _read_now(sub) == data
            assert (len(sent), len(frames)) == (k + 2, 0)


async def test_what_the_socket_does_not_take_goes_whole_and_in_order_from_the_task(
    anyio_backend: str,
) -> None:
    """An 8 MiB frame the socket takes only in part, then 10 frames into a queue of 3: the
    subscriber reads the big frame whole, then the newest 3; 7 counted as dropped, and
    the big frame's unsent end was not among them."""
    frames = FrameQueue(3)
    sent: list[int] = []
    big = frame(bytes(range(256)) * (8 * 4096))
    small = [frame(b"small %d" % k) for k in range(10)]
    async with _served(frames, sent) as (sub, _):
        assert frames.put(big) == 0
        dropped = sum(frames.put(data) for data in small)
        assert dropped == 7
        expected = big + b"".join(small[7:])
        got = await anyio.to_thread.run_sync(_read_all, sub, len(expected))
        assert got == expected
        await _until(lambda: len(sent) == 5, "the four frames to be counted as sent")
        assert struct.unpack_from("<I", got)[0] == len(big) - 4
