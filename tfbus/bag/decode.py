"""Decoding serialized ``TFMessage`` payloads into tfbus values.

A ``TFMessage`` has had the same wire layout since ROS 1 Hydro, so when a connection's
type hash is the standard one (ROS 1 MD5 ``94810edd...``, ROS 2 RIHS01 ``e369d0f0...``)
its payloads are decoded by a dedicated :mod:`struct` decoder, several times faster than
a generic deserializer; any other definition goes through a rosbags typestore built from
the definition stored in the bag (ROS 1 message text, ROS 2 ``.msg`` or IDL text).

Every decoder raises only ``Exception`` subclasses on a bad payload; the reader turns them
into :class:`~tfbus.errors.BagReadError`.
"""

from __future__ import annotations

import ast
import struct
from collections.abc import Callable, Iterable
from contextlib import suppress
from itertools import repeat
from typing import TYPE_CHECKING, Any, Final, NamedTuple

from tfbus.core._select import TF_FROM_ROS1
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "ROS1_TF_MD5",
    "ROS2_TF_RIHS01",
    "TF_MSGDEF",
    "Decoder",
    "RawItem",
    "SchemaParseError",
    "Source",
    "cdr_decoder",
    "decode_cdr",
    "decode_ros1",
    "decode_ros1_struct",
    "from_rosbags",
    "ros1_decoder",
]

#: ROS 1 MD5 of TFMessage (identical for tf2_msgs/TFMessage and tf/tfMessage).
ROS1_TF_MD5: Final = "94810edda583a504dfda3829e70d7eec"
#: ROS 2 RIHS01 type hash of tf2_msgs/msg/TFMessage.
ROS2_TF_RIHS01: Final = (
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
)
#: The body of tf2_msgs/TFMessage (and tf/tfMessage); its field types come from the store.
TF_MSGDEF: Final = "geometry_msgs/TransformStamped[] transforms\n"

Decoder = Callable[[bytes | memoryview], list[TransformStamped]]
"""Turns one serialized message into its transforms; raises on a malformed payload."""

_U32 = struct.Struct("<I")
_ROS1_HEAD = struct.Struct("<IIII")  # seq, sec, nsec, len(frame_id)
_F7LE = struct.Struct("<7d")
_F7BE = struct.Struct(">7d")


def _ts(ns: int, frame: str, child: str, v: tuple[float, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), frame),
        child,
        Transform(Vector3(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6])),
    )


_new: Callable[..., Any] = tuple.__new__  # a NamedTuple without its generated __new__
_STR_CACHE_MAX: Final = 4096
_STR_CACHE_KEY_MAX: Final = 256
_strings: dict[bytes, str] = {}
"""Frame ids seen, as UTF-8 bytes -> ``str`` (a tf stream repeats the same few names)."""
_tails: dict[int, Callable[[bytes, int], tuple[Any, ...]]] = {}
"""Per child-id length: ``u32 len, child bytes, 7 doubles`` in one struct call."""


def _text(raw: bytes) -> str:
    """``raw`` decoded as UTF-8, remembered (bounded) so a repeated frame id costs one
    dict lookup and every message shares one ``str`` per name."""
    text = _strings.get(raw)
    if text is None:
        text = raw.decode()
        if len(raw) <= _STR_CACHE_KEY_MAX and len(_strings) < _STR_CACHE_MAX:
            _strings[raw] = text
    return text


def _tail(clen: int) -> Callable[[bytes, int], tuple[Any, ...]]:
    unpack = _tails.get(clen)
    if unpack is None:
        unpack = struct.Struct(f"<4x{clen}s7d").unpack_from
        if len(_tails) < _STR_CACHE_MAX:
            _tails[clen] = unpack
    return unpack


_LAYOUT_MIN: Final = 12  # below, the walk is as fast (measured)
_LAYOUT_MAX: Final = 4096
_LAYOUT_BUDGET: Final = 16384
"""Transforms over all cached layouts (a struct costs ~0.3 kB per transform: ~5 MB at
most, whatever a peer sends)."""
_layout_room = _LAYOUT_BUDGET
_GROUP: Final = 14  # values per transform: seq sec nsec flen frame clen child x y z qx qy qz qw
_layouts: dict[tuple[int, int], tuple[Callable[[bytes], tuple[Any, ...]], tuple[int, ...]]] = {}
"""(transform count, message size) -> one struct unpacking a whole message of that
layout, and the frame id lengths then child id lengths it assumes."""


_compiled_ros1: Callable[[bytes | memoryview], list[TransformStamped]] | None = TF_FROM_ROS1
"""The compiled core's ROS 1 TFMessage decoder (objects built in C), where there is one."""


def decode_ros1(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a ROS 1 serialized TFMessage (little endian, Header with ``seq``).

    With the compiled core (on a little-endian host) the transforms are built in C
    (``tfbus.core._cwire._tf_from_ros1``, ~3x faster at 50 transforms); otherwise by
    :func:`decode_ros1_struct`. Equal values either way (tested).

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    if _compiled_ros1 is not None:
        return _compiled_ros1(raw)
    return decode_ros1_struct(raw)


def decode_ros1_struct(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a ROS 1 serialized TFMessage with :mod:`struct` (the pure-Python path).

    A publisher sends the same frames message after message, so the same layout (count,
    size and the length of every frame id): after a message of 12 to 4096 transforms was
    decoded one transform at a time, its layout is kept as a single :class:`struct.Struct`
    (16384 transforms over all layouts at most); a later message of the same count and
    size is unpacked by it in one call, used only if every length field it read equals
    the layout's (otherwise the transform-at-a-time decoder runs), and its values are
    built column by column (:func:`_columns`). Both paths give equal values.

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    buf = bytes(raw)
    (n,) = _U32.unpack_from(buf, 0)
    if n < _LAYOUT_MIN or n > _LAYOUT_MAX:
        return _walk_ros1(buf, n)
    key = (n, len(buf))
    layout = _layouts.get(key)
    if layout is not None:
        unpack, lengths = layout
        values = unpack(buf)
        if values[3::_GROUP] + values[5::_GROUP] == lengths:
            return _columns(values, n)
    out = _walk_ros1(buf, n)
    global _layout_room
    if layout is None and n <= _layout_room:
        _layout_room -= n
        _layouts[key] = _layout(buf, n)
    return out


def _layout(buf: bytes, n: int) -> tuple[Callable[[bytes], tuple[Any, ...]], tuple[int, ...]]:
    """The struct of a whole message shaped like ``buf`` (already decoded, so whole)."""
    frames, children, parts = [], [], ["<4x"]
    off = 4
    for _ in range(n):
        (flen,) = _U32.unpack_from(buf, off + 12)
        off += 16 + flen
        (clen,) = _U32.unpack_from(buf, off)
        off += 4 + clen + 56
        frames.append(flen)
        children.append(clen)
        parts.append(f"IIII{flen}sI{clen}s7d")
    return struct.Struct("".join(parts)).unpack_from, (*frames, *children)


def _columns(values: tuple[Any, ...], n: int) -> list[TransformStamped]:
    """Build the transforms from one flat unpack of ``n`` groups of :data:`_GROUP`
    values, a column at a time (``map`` over ``tuple.__new__``: no Python frame per
    value). Transforms of one stamp and frame id (the usual message) share a Header."""
    new = _new
    g = _GROUP
    secs, nsecs, frames = values[1::g], values[2::g], values[4::g]
    strings = _strings
    children = [strings.get(c) or _text(c) for c in values[6::g]]
    headers: Iterable[Header]
    if secs.count(secs[0]) == n and nsecs.count(nsecs[0]) == n and frames.count(frames[0]) == n:
        stamp = Time.from_ns(secs[0] * NSEC_PER_SEC + nsecs[0])
        headers = repeat(new(Header, (stamp, _text(frames[0]))), n)
    else:
        headers = [
            new(Header, (Time.from_ns(sec * NSEC_PER_SEC + nsec), _text(frame)))
            for sec, nsec, frame in zip(secs, nsecs, frames, strict=True)
        ]
    vectors = map(
        new, repeat(Vector3, n), zip(values[7::g], values[8::g], values[9::g], strict=True)
    )
    rotations = map(
        new,
        repeat(Quaternion, n),
        zip(values[10::g], values[11::g], values[12::g], values[13::g], strict=True),
    )
    transforms = map(new, repeat(Transform, n), zip(vectors, rotations, strict=True))
    return list(
        map(new, repeat(TransformStamped, n), zip(headers, children, transforms, strict=True))
    )


def _walk_ros1(buf: bytes, n: int) -> list[TransformStamped]:
    """Decode the ``n`` transforms of a ROS 1 TFMessage, one after the other.

    Transforms whose serialized header (seq, stamp, frame id) is byte-for-byte the one
    before share one :class:`~tfbus.messages.Header` value (a broadcaster stamps a whole
    message at once, as tf2_ros's ``TransformBroadcaster`` does); frame ids are decoded
    once per name (a bounded cache). Values are immutable, so sharing is invisible.

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    off = 4
    out: list[TransformStamped] = []
    append = out.append
    head = _ROS1_HEAD.unpack_from
    u32 = _U32.unpack_from
    tails = _tails
    starts = buf.startswith
    new = _new
    prev = b""  # the previous transform's serialized header
    header = None
    for _ in range(n):
        if prev and starts(prev, off):
            off += len(prev)
        else:
            _seq, sec, nsec, flen = head(buf, off)
            end = off + 16 + flen
            header = new(
                Header, (Time.from_ns(sec * NSEC_PER_SEC + nsec), _text(buf[off + 16 : end]))
            )
            prev = buf[off:end]
            off = end
        (clen,) = u32(buf, off)
        child, x, y, z, qx, qy, qz, qw = (tails.get(clen) or _tail(clen))(buf, off)
        off += clen + 60
        append(
            new(
                TransformStamped,
                (
                    header,
                    _strings.get(child) or _text(child),
                    new(Transform, (new(Vector3, (x, y, z)), new(Quaternion, (qx, qy, qz, qw)))),
                ),
            )
        )
    if off > len(buf):
        raise struct.error("message shorter than its contents")
    return out


def decode_cdr(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a CDR (ROS 2) serialized tf2_msgs/msg/TFMessage, either byte order.

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
        ValueError: a stamp out of range (negative nanoseconds overall).
    """
    buf = bytes(raw)
    if len(buf) < 8:
        raise struct.error(f"CDR message of {len(buf)} bytes is shorter than its header")
    little = buf[1] == 1
    e = "<" if little else ">"
    u32 = struct.Struct(e + "I").unpack_from
    ii = struct.Struct(e + "iII").unpack_from  # sec, nanosec, len(frame_id)
    f7 = (_F7LE if little else _F7BE).unpack_from
    (n,) = u32(buf, 4)
    off = 8  # absolute; CDR alignment is relative to byte 4
    out: list[TransformStamped] = []
    append = out.append
    for _ in range(n):
        off += -(off - 4) % 4
        sec, nsec, flen = ii(buf, off)
        off += 12
        frame = buf[off : off + flen - 1].decode()
        off += flen
        off += -(off - 4) % 4
        (clen,) = u32(buf, off)
        off += 4
        child = buf[off : off + clen - 1].decode()
        off += clen
        off += -(off - 4) % 8
        v = f7(buf, off)
        off += 56
        append(_ts(sec * NSEC_PER_SEC + nsec, frame, child, v))
    if off > len(buf):
        raise struct.error("message shorter than its contents")
    return out


def from_rosbags(msg: Any) -> list[TransformStamped]:
    """Convert a rosbags-deserialized TFMessage object to tfbus values."""
    out = []
    for t in msg.transforms:
        st = t.header.stamp
        tr = t.transform.translation
        q = t.transform.rotation
        out.append(
            _ts(
                int(st.sec) * NSEC_PER_SEC + int(st.nanosec),
                str(t.header.frame_id),
                str(t.child_frame_id),
                (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w),
            )
        )
    return out


class SchemaParseError(ValueError):
    """A message definition stored in a bag does not parse: the message names the type
    and the first line that does not (one short line, never the whole definition)."""


_SHOWN_LINE = 60  # characters of the bad line quoted in a SchemaParseError


def schema_problem(msgtype: str, msgdef: str, err: BaseException) -> str:
    """What is wrong with ``msgdef``, in one short line: ``schema 'pkg/msg/T' does not
    parse at line N: '<that line>'``.

    rosbags' parsers (``rosbags.typesys.msg`` / ``idl``) say ``Could not parse:`` then,
    one per line, the text they parsed (``repr``; for .msg text prefixed with
    ``MSG: <type>``) and the position where parsing stopped; that position's line is the
    one quoted, numbered in the stored definition. Another error is quoted shortened."""
    parts = str(err).split("\n")
    text: object = None
    if len(parts) >= 3 and parts[0].startswith("Could not parse") and parts[2].isdigit():
        with suppress(ValueError, SyntaxError):
            text = ast.literal_eval(parts[1])
    if not isinstance(text, str):
        first = " ".join(str(err).split()) or type(err).__name__
        short = first if len(first) <= 2 * _SHOWN_LINE else first[: 2 * _SHOWN_LINE] + "..."
        return f"schema {msgtype!r} does not parse: {short}"
    pos = min(int(parts[2]), len(text))
    start = text.rfind("\n", 0, pos) + 1
    end = text.find("\n", pos)
    line = text[start : end if end >= 0 else len(text)]
    number = text.count("\n", 0, start) + 1
    if text.startswith(f"MSG: {msgtype}\n") and not msgdef.startswith("MSG: "):
        number -= 1  # the header line rosbags added is not the bag's
    if len(line) > _SHOWN_LINE:
        line = line[:_SHOWN_LINE] + "..."
    return f"schema {msgtype!r} does not parse at line {number}: {line!r}"


def _typestore(msgtype: str, msgdef: str, idl: bool, ros1: bool) -> Typestore:
    """A rosbags typestore that knows ``msgtype`` from the definition stored in the bag.

    Raises:
        SchemaParseError: ``msgdef`` does not parse (:func:`schema_problem` says where).
    """
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    if not msgdef:
        store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if msgtype not in store.types:
            store.register(get_types_from_msg(TF_MSGDEF, msgtype))
        return store
    store = get_typestore(Stores.EMPTY)
    try:
        types = get_types_from_idl(msgdef) if idl else get_types_from_msg(msgdef, msgtype)
        store.register(types)
    except Exception as err:  # rosbags' TypesysError, or whatever its parser raises
        raise SchemaParseError(schema_problem(msgtype, msgdef, err)) from None
    return store


def ros1_decoder(msgtype: str, md5: str, msgdef: str) -> Decoder:
    """The decoder for a ROS 1 connection of type ``msgtype`` (rosbags' ``pkg/msg/Name``).

    Raises:
        SchemaParseError: the stored definition cannot be parsed (the type and the first
            bad line); the reader reports it as a ``BagReadError``.
    """
    if md5 == ROS1_TF_MD5:
        return decode_ros1
    store = _typestore(msgtype, msgdef, False, True)

    def ros1_generic(raw: bytes | memoryview) -> list[TransformStamped]:
        return from_rosbags(store.deserialize_ros1(raw, msgtype))

    return ros1_generic


def cdr_decoder(msgtype: str, msgdef: str, *, idl: bool, digest: str = "") -> Decoder:
    """The decoder for a ROS 2 (CDR) connection of type ``msgtype``.

    ``digest`` is the RIHS01 type hash when the bag stores one; otherwise it is computed
    from ``msgdef`` (``.msg`` text, or IDL when ``idl``).

    Raises:
        SchemaParseError: the definition cannot be parsed (the type and the first bad
            line); the reader reports it as a ``BagReadError``.
    """
    if digest == ROS2_TF_RIHS01:
        return decode_cdr
    store = _typestore(msgtype, msgdef, idl, False)
    if not digest:
        with suppress(Exception):
            digest = store.hash_rihs01(msgtype)
    if digest == ROS2_TF_RIHS01:
        return decode_cdr

    def cdr_generic(raw: bytes | memoryview) -> list[TransformStamped]:
        return from_rosbags(store.deserialize_cdr(raw, msgtype))

    return cdr_generic


class Source(NamedTuple):
    """One tf connection of a bag: its topic, its authority and how to decode it."""

    topic: str
    authority: str
    decode: Decoder


RawItem = tuple[int, Source, "bytes | memoryview", "int | None"]
"""A raw message: bag time (ns), its connection, the payload, its byte offset if known."""
