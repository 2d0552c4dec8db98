"""TCPROS for ``tf2_msgs/TFMessage``: connection headers and length-prefixed frames (ROS
wiki "ROS/TCPROS", "ROS/Connection Header"). The message itself is (de)serialised by
:mod:`tfbus.codecs.ros1` (:class:`~tfbus.codecs.ros1.TFCodec`)."""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from typing import Final

from anyio.streams.buffered import BufferedByteReceiveStream

__all__ = [
    "MAX_HEADER_BYTES",
    "FrameSplitter",
    "decode_header",
    "encode_header",
    "frame",
    "read_frame",
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
    """Parse the body of a connection header (without its total-length prefix).

    Raises:
        ValueError: a field runs past the end, has no ``=``, or is not UTF-8.
    """
    out: dict[str, str] = {}
    off, n = 0, len(body)
    while off < n:
        if off + 4 > n:
            raise ValueError(f"connection header: truncated field length at byte {off}")
        (flen,) = _U32.unpack_from(body, off)
        off += 4
        if flen > n - off:
            raise ValueError(
                f"connection header: field of {flen} bytes at byte {off} runs past the end"
            )
        key, eq, value = body[off : off + flen].partition(b"=")
        off += flen
        if not eq:
            raise ValueError("connection header: a field without '='")
        try:
            out[key.decode()] = value.decode()
        except UnicodeDecodeError as exc:
            raise ValueError(f"connection header: not UTF-8 ({exc})") from exc
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

    __slots__ = ("_buf", "_first", "_limit", "_need", "_rest", "_sink")

    def __init__(
        self, sink: Callable[[bytes | memoryview], object], first_limit: int, limit: int
    ) -> None:
        self._sink = sink
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
        sink = self._sink
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
            sink(payload)
        else:
            self._need = 4
        if off < n:
            self._buf += data[off:] if off else data


def frame(payload: bytes) -> bytes:
    """``payload`` with its TCPROS length prefix (u32, little endian)."""
    return _U32.pack(len(payload)) + payload
