"""TCPROS for ``tf2_msgs/TFMessage``: connection headers, length-prefixed frames, and
ROS 1 serialisation by rosbags and decoding by the bag reader's struct decoder (ROS wiki
"ROS/TCPROS", "ROS/Connection Header")."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Mapping
from typing import Final

from anyio.streams.buffered import BufferedByteReceiveStream

from tfbus.bag.decode import decode_ros1, from_rosbags
from tfbus.messages import TransformStamped
from tfbus.time import NSEC_PER_SEC

__all__ = [
    "MAX_HEADER_BYTES",
    "TF_MD5SUM",
    "TF_TYPE",
    "FrameSplitter",
    "TFCodec",
    "decode_header",
    "encode_header",
    "frame",
    "read_frame",
]

TF_TYPE: Final = "tf2_msgs/TFMessage"
"""The ROS 1 type of ``/tf`` and ``/tf_static``."""
TF_MD5SUM: Final = "94810edda583a504dfda3829e70d7eec"
"""md5 of ``tf2_msgs/TFMessage``'s full definition (checked against rosbags' at start)."""
MAX_HEADER_BYTES: Final = 64 * 1024
"""Largest connection header accepted from a peer."""

_U32: Final = struct.Struct("<I")
_SEC_MAX: Final = 2**31 - 1  # rosbags serialises ROS 1 time.sec as int32 (2038-01-19)


class TFCodec:
    """ROS 1 (de)serialisation of ``tf2_msgs/TFMessage`` by rosbags' typestore."""

    def __init__(self) -> None:
        try:
            from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        except ImportError as exc:
            raise ImportError(
                "the ROS 1 transport needs rosbags: pip install 'tfbus[ros1]'"
            ) from exc

        store = get_typestore(Stores.ROS1_NOETIC)
        store.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
        self._store = store
        self._name = "tf2_msgs/msg/TFMessage"
        definition, md5 = store.generate_msgdef(self._name, ros_version=1)
        if md5 != TF_MD5SUM:  # pragma: no cover - a rosbags regression, not an input error
            raise RuntimeError(f"rosbags gives md5 {md5} for {TF_TYPE}, expected {TF_MD5SUM}")
        self.definition: str = definition
        t = store.types
        self._msg = t[self._name]
        self._stamped = t["geometry_msgs/msg/TransformStamped"]
        self._header = t["std_msgs/msg/Header"]
        self._time = t["builtin_interfaces/msg/Time"]
        self._transform = t["geometry_msgs/msg/Transform"]
        self._vector = t["geometry_msgs/msg/Vector3"]
        self._quat = t["geometry_msgs/msg/Quaternion"]

    def encode(self, transforms: Iterable[TransformStamped]) -> bytes:
        """Serialise transforms as one ROS 1 ``TFMessage``.

        Raises:
            ValueError: a stamp before 1970 or from 2038-01-19 on (rosbags writes ROS 1's
                ``time.sec`` as int32; ROS 1 itself reads uint32), or a field of the
                wrong type, naming the frame.
        """
        items = []
        for ts in transforms:
            ns = ts.header.stamp.ns
            sec, nsec = divmod(ns, NSEC_PER_SEC)
            if not 0 <= sec <= _SEC_MAX:
                raise ValueError(
                    f"header.stamp {ns} ns of {ts.child_frame_id!r} is outside ROS 1's time "
                    "as sent (0 .. 2**31-1 s)"
                )
            tr, q = ts.transform.translation, ts.transform.rotation
            items.append(
                self._stamped(
                    header=self._header(
                        seq=0, stamp=self._time(sec=sec, nanosec=nsec), frame_id=ts.header.frame_id
                    ),
                    child_frame_id=ts.child_frame_id,
                    transform=self._transform(
                        translation=self._vector(x=float(tr.x), y=float(tr.y), z=float(tr.z)),
                        rotation=self._quat(x=float(q.x), y=float(q.y), z=float(q.z), w=float(q.w)),
                    ),
                )
            )
        try:
            return bytes(self._store.serialize_ros1(self._msg(transforms=items), self._name))
        except (struct.error, UnicodeEncodeError, TypeError, AttributeError) as exc:
            raise ValueError(f"cannot serialise a TFMessage for ROS 1: {exc}") from exc

    def decode(self, raw: bytes | memoryview) -> list[TransformStamped]:
        """Deserialise one ROS 1 ``TFMessage`` with the bag reader's struct decoder
        (:func:`tfbus.bag.decode.decode_ros1`, the same fixed layout: valid because the
        connection's md5sum is checked to be :data:`TF_MD5SUM`). It is 3-5x faster than
        rosbags' generic deserialiser (:meth:`decode_generic`, the reference it is tested
        against), which is what keeps a 50-transform message's latency near roscpp's.

        Raises:
            ValueError: the bytes are not a whole ``TFMessage`` (short, bad UTF-8).
        """
        try:
            return decode_ros1(raw)
        except Exception as exc:  # struct.error, UnicodeDecodeError, ...
            raise ValueError(f"malformed {TF_TYPE}: {type(exc).__name__}: {exc}") from exc

    def decode_generic(self, raw: bytes) -> list[TransformStamped]:
        """Deserialise one ROS 1 ``TFMessage`` with rosbags' generic deserialiser.

        Raises:
            ValueError: the bytes are not a whole ``TFMessage``.
        """
        try:
            return from_rosbags(self._store.deserialize_ros1(raw, self._name))
        except Exception as exc:  # rosbags raises struct.error, UnicodeDecodeError, ...
            raise ValueError(f"malformed {TF_TYPE}: {type(exc).__name__}: {exc}") from exc


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
