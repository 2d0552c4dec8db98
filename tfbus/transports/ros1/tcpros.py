"""TCPROS for ``tf2_msgs/TFMessage``: connection headers and length-prefixed frames (ROS
wiki "ROS/TCPROS", "ROS/Connection Header"). The message itself is (de)serialised by
:mod:`tfbus.codecs.ros1` (:class:`~tfbus.codecs.ros1.TFCodec`)."""

from __future__ import annotations

import contextlib
import socket
import struct
from collections import deque
from collections.abc import Callable, Mapping
from typing import Final

import anyio
import anyio.abc
from anyio.streams.buffered import BufferedByteReceiveStream

from tfbus._aio import asyncio_transport_of, running_asyncio_loop

__all__ = [
    "MAX_HEADER_BYTES",
    "DirectWrite",
    "FrameQueue",
    "FrameSplitter",
    "decode_header",
    "direct_writer",
    "encode_header",
    "frame",
    "read_frame",
    "serve_subscriber",
]

MAX_HEADER_BYTES: Final = 64 * 1024
"""Largest connection header accepted from a peer."""

_U32: Final = struct.Struct("<I")


def encode_header(fields: Mapping[str, str]) -> bytes:
    """A TCPROS connection header: ``u32 total`` then ``u32 len`` + ``key=value`` per field
    (ROS wiki "ROS/Connection Header")."""
    body = b"".join(_U32.pack(len(f := f"{k}={v}".encode())) + f for k, v in fields.items())
    return _U32.pack(len(body)) + body


def decode_header(body: bytes) -> dict[str, str]:
    """Parse the body of a connection header (without its total-length prefix). A field
    given twice keeps its last value, as roscpp's ``Header::parse`` does (each
    ``key=value`` line is stored into one map in order).

    Raises:
        ValueError: a field runs past the end, has no ``=``, or is not UTF-8; the message
            names the field (its first bytes) and its byte offset in ``body``.
    """
    out: dict[str, str] = {}
    off, n = 0, len(body)
    while off < n:
        if off + 4 > n:
            raise ValueError(
                f"connection header: truncated field length at byte {off} "
                f"({n - off} bytes left, 4 needed)"
            )
        (flen,) = _U32.unpack_from(body, off)
        off += 4
        if flen > n - off:
            raise ValueError(
                f"connection header: field of {flen} bytes at byte {off} runs past the end "
                f"({n - off} bytes left)"
            )
        field = body[off : off + flen]
        key, eq, value = field.partition(b"=")
        if not eq:
            raise ValueError(
                f"connection header: field {field[:60]!r} at byte {off} has no '='"
            )
        try:
            name = key.decode()
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"connection header: the name of field {field[:60]!r} at byte {off} is not "
                f"UTF-8 ({exc.reason} at byte {off + exc.start})"
            ) from None
        try:
            out[name] = value.decode()
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"connection header: field {name[:60]!r} at byte {off} is not UTF-8 "
                f"({exc.reason} at byte {off + len(key) + 1 + exc.start})"
            ) from None
        off += flen
    return out


async def read_frame(stream: BufferedByteReceiveStream, limit: int, what: str) -> bytes:
    """One length-prefixed frame (few system calls: the stream is buffered).

    Raises:
        ValueError: the length prefix exceeds ``limit`` bytes.
        anyio.EndOfStream, anyio.IncompleteRead: the peer closed the connection.
    """
    (n,) = _U32.unpack(await stream.receive_exactly(4))
    if n > limit:
        raise ValueError(f"{what} of {n} bytes exceeds the limit of {limit}")
    return await stream.receive_exactly(n)


class FrameSplitter:
    """TCPROS framing without I/O: bytes as they arrive go in, each whole frame (the
    connection header first, then messages) goes to ``sink`` in order.

    roscpp reads a frame as a 4-byte length, then that many bytes
    (``TransportPublisherLink::onMessageLength`` / ``onMessage``, each a
    ``Connection::read`` filled by ``Connection::readTransport``); here whatever one
    receive returned is split at once, so a read of several frames costs one wake-up
    and a frame that fits in one read is not copied at all: fed a ``memoryview`` (the
    asyncio pump's read buffer), the sink gets a view of it.

    Args:
        sink: called with each frame's payload (without its length prefix): ``bytes``,
            or a ``memoryview`` valid only during the call when :meth:`feed` was given
            one (the sink must not keep it); what it raises propagates from
            :meth:`feed`, after the frames before it.
        first_limit: largest first frame (the connection header).
        limit: largest later frame (a message).
    """

    __slots__ = ("_buf", "_first", "_limit", "_need", "_rest", "sink")

    def __init__(
        self, sink: Callable[[bytes | memoryview], object], first_limit: int, limit: int
    ) -> None:
        self.sink = sink
        """Called with each frame; may be replaced, e.g. by the first frame's call: the
        frames after it go to the new one."""
        self._first = True
        self._limit = first_limit
        self._rest = limit
        self._buf = bytearray()
        self._need = 4  # bytes the buffered frame needs before it can be split

    def feed(self, data: bytes | memoryview) -> None:
        """Add received bytes; hand every frame they complete to ``sink``. A
        ``memoryview`` is read during the call only (an incomplete frame's bytes are
        copied), so its buffer may be reused afterwards.

        Raises:
            ValueError: a length prefix over the limit (after the frames before it);
                the connection cannot be resynchronised and should be closed.
        """
        if self._buf:
            self._buf += data
            if len(self._buf) < self._need:
                return
            data, self._buf = bytes(self._buf), bytearray()
        off, n = 0, len(data)
        unpack = _U32.unpack_from
        while n - off >= 4:
            (size,) = unpack(data, off)
            if size > self._limit:
                what = "connection header" if self._first else "message"
                raise ValueError(f"{what} of {size} bytes exceeds the limit of {self._limit}")
            end = off + 4 + size
            if end > n:
                self._need = end - off
                break
            if self._first:
                self._first = False
                self._limit = self._rest
            payload = data[off + 4 : end]
            off = end
            self.sink(payload)
        else:
            self._need = 4
        if off < n:
            self._buf += data[off:] if off else data


def frame(payload: bytes) -> bytes:
    """``payload`` with its TCPROS length prefix (u32, little endian)."""
    return _U32.pack(len(payload)) + payload


DirectWrite = Callable[[bytes], int]
"""Write what a socket takes now without blocking: ``write(data)`` returns how many bytes
of ``data`` went (0 if it would block); raises ``OSError`` if the socket failed."""


class FrameQueue:
    """The frames still to send to one subscriber, oldest first, bounded: beyond
    ``max_frames`` frames, or ``max_bytes`` bytes when given (the newest frame is always
    kept), the oldest are dropped, as roscpp's per-subscriber queue drops them.

    Filled without blocking by the publishing side (:meth:`put`) and emptied by that
    connection's own task only (:meth:`send_to`): a subscriber that does not read holds up
    no other, and no two tasks ever send on one stream at once.

    While that task is idle (nothing queued, nothing being sent) and it gave a direct
    writer, :meth:`put` writes the frame to the socket itself, as roscpp's
    ``SubscriberLink::enqueueMessage`` writes from the publishing thread
    (``Connection::write``, ``TransportTCP::write`` with a non-blocking socket): a message
    then costs no wake-up of the connection's task. What the socket does not take at once
    (the rest of a frame, or a frame it would block on) goes to that task; the rest of a
    begun frame is never dropped.

    ``max_frames`` and ``max_bytes`` may be changed at any time; the next :meth:`put`
    applies them.
    """

    def __init__(self, max_frames: int, max_bytes: int | None = None) -> None:
        self._frames: deque[bytes] = deque()
        self._size = 0
        self.max_frames = max_frames
        self.max_bytes = max_bytes
        self._wake = anyio.Event()
        self._rest = b""  # the unsent end of a frame put() began writing
        self._idle = False  # the connection's task waits with nothing to send
        self._direct: DirectWrite | None = None
        self._on_sent: Callable[[], None] | None = None

    def __len__(self) -> int:
        return len(self._frames)

    def put(self, data: bytes) -> int:
        """Send one frame (with its length prefix) now if the socket takes it, else queue
        it; returns how many old frames were dropped to keep within the bounds."""
        if self._idle and self._direct is not None:
            try:
                sent = self._direct(data)
            except OSError:
                sent = 0  # the connection's task meets the error and ends the connection
            if sent == len(data):
                if self._on_sent is not None:
                    self._on_sent()
                return 0
            self._idle = False
            self._wake.set()
            if sent:
                self._rest = data[sent:]
                return 0
        frames = self._frames
        frames.append(data)
        self._size += len(data)
        dropped = 0
        while len(frames) > self.max_frames or (
            self.max_bytes is not None and self._size > self.max_bytes and len(frames) > 1
        ):
            self._size -= len(frames.popleft())
            dropped += 1
        self._idle = False
        self._wake.set()
        return dropped

    async def send_to(
        self,
        stream: anyio.abc.ByteSendStream,
        on_sent: Callable[[], None] | None = None,
        direct: DirectWrite | None = None,
    ) -> None:
        """Send the frames as they are queued (``on_sent`` after each), until the
        subscriber's socket fails: ``OSError``, :class:`anyio.BrokenResourceError` (a reset
        or a broken pipe) or :class:`anyio.ClosedResourceError` end this connection only
        and are not raised. Caught here, inside the connection's task group, and not
        around it, where they would come out wrapped in an ``ExceptionGroup``.

        ``direct``: how :meth:`put` writes to ``stream``'s socket while this task is
        idle (see the class), or None to send every frame from this task."""
        frames = self._frames
        self._on_sent = on_sent
        self._direct = direct
        try:
            while True:
                if self._rest:
                    data, self._rest = self._rest, b""
                elif frames:
                    data = frames.popleft()
                    self._size -= len(data)
                else:
                    self._wake = anyio.Event()
                    self._idle = True
                    await self._wake.wait()
                    continue
                await stream.send(data)
                if on_sent is not None:
                    on_sent()
        except (OSError, anyio.BrokenResourceError, anyio.ClosedResourceError):
            return
        finally:
            self._idle = False
            self._direct = None


def direct_writer(stream: anyio.abc.SocketStream) -> DirectWrite | None:
    """How :meth:`FrameQueue.put` writes to ``stream`` without blocking, or None.

    On asyncio, the stream's transport (``transport.write`` while its buffer is empty:
    what ``stream.send`` does, without the checkpoint); under trio, the socket itself
    (``socket.send``: trio keeps no buffer of its own). A stream that gives neither (a
    test's) sends every frame from the connection's task.
    """
    transport = asyncio_transport_of(stream)
    if transport is not None:

        def write_transport(data: bytes) -> int:
            if transport.get_write_buffer_size() or transport.is_closing():
                return 0
            transport.write(data)
            return len(data)

        return write_transport
    if running_asyncio_loop() is not None:
        return None
    try:
        sock = stream.extra(anyio.abc.SocketAttribute.raw_socket, None)
    except Exception:  # a stream without a socket: sends from its task only
        return None
    if not isinstance(sock, socket.socket):
        return None
    send = sock.send

    def write_socket(data: bytes) -> int:
        try:
            return send(data)
        except (BlockingIOError, InterruptedError):
            return 0

    return write_socket


async def serve_subscriber(
    stream: anyio.abc.SocketStream, frames: FrameQueue, on_sent: Callable[[], None] | None = None
) -> None:
    """Send ``frames`` to a connected subscriber (its header already answered) until it
    leaves: a subscriber sends nothing after its header, so any end of reading (EOF, a
    reset, junk) means it left; a failed send ends the connection too. Frames are
    written from the publishing task while the connection is idle
    (:func:`direct_writer`). Returns, never raises for the peer's doing
    (``TransportPublisherLink``'s counterpart, roscpp's ``SubscriberLink``)."""
    async with anyio.create_task_group() as tg:
        tg.start_soon(_watch_closed, stream, tg.cancel_scope)
        await frames.send_to(stream, on_sent, direct_writer(stream))
        tg.cancel_scope.cancel()


async def _watch_closed(stream: anyio.abc.SocketStream, scope: anyio.CancelScope) -> None:
    with contextlib.suppress(Exception):  # any end of reading: the subscriber left
        while await stream.receive(4096):
            pass
    scope.cancel()
