"""ROS 1's ``tf2_msgs/TFMessage``: the struct decoder, rosbags' serialiser and the one
rosbags message builder.

Every codec module of :mod:`tfbus.codecs` offers the same functions, with the same
parameters: :func:`encode_tf` / :func:`decode_tf`, :func:`encode_scan` /
:func:`decode_scan`, :func:`encode_clock` / :func:`decode_clock` and, where the wire has
the ``tf2_msgs/LookupTransform`` action, :func:`encode_lookup_goal` /
:func:`decode_lookup_goal` / :func:`encode_lookup_result` / :func:`decode_lookup_result`.

* :func:`decode_tf` -- a ROS 1 serialized TFMessage (little endian, ``std_msgs/Header``
  with ``seq``) into tfbus values, by a dedicated :mod:`struct` decoder
  (:func:`decode_ros1_struct`) or its compiled twin (:mod:`tfbus.codecs._cwire`, built
  in C with the compiled core), several times faster than a generic deserializer and
  tested equal to rosbags' ``deserialize_ros1``. Used by the ROS 1 transport (TCPROS,
  through :meth:`TFCodec.decode`) and by the bag reader for ``.bag`` connections whose
  md5 is :data:`TF_MD5SUM`.
* :class:`TFCodec` -- ROS 1 serialisation by :mod:`struct` (:meth:`TFCodec.encode`),
  tested equal to rosbags' ``serialize_ros1`` (:meth:`TFCodec.encode_generic`); rosbags'
  typestore gives the message definition and its md5 for the TCPROS connection header.
* :func:`tf_typestore`, :func:`to_rosbags`, :func:`from_rosbags` -- the rosbags typestore
  that knows ``tf2_msgs/msg/TFMessage`` and the conversion of tfbus values to and from
  rosbags message objects (the bag writer and :class:`TFCodec` build messages here only).

* :func:`encode_scan`, :func:`decode_scan` -- ``sensor_msgs/LaserScan`` (md5
  :data:`SCAN_MD5SUM`) and a :class:`~tfbus.sensor_msgs.LaserScan`, by :mod:`struct` and
  ``numpy``, bounded (:data:`MAX_SCAN_BEAMS`); tested equal to rosbags'
  ``serialize_ros1``. Used by the ROS 1 transport's scan topics.
* :func:`encode_clock`, :func:`decode_clock` -- ``rosgraph_msgs/Clock`` (md5
  :data:`CLOCK_MD5SUM`): one ``time``, two little-endian ``uint32`` (secs, nsecs).
* :func:`encode_lookup_goal`, :func:`decode_lookup_goal`, :func:`encode_lookup_result`,
  :func:`decode_lookup_result`, :func:`encode_goal_id`, :func:`decode_goal_id`,
  :func:`encode_goal_status_array` -- tf2_ros's ``tf2_msgs/LookupTransform`` action over
  actionlib (``LookupTransformActionGoal``, ``LookupTransformActionResult``, the cancel
  request ``actionlib_msgs/GoalID`` and the ``GoalStatusArray``), used by
  :mod:`tfbus.transports.ros1.action`.

**Errors.** Decoding raises :class:`~tfbus.errors.WireDecodeError` (a ``ValueError``) and
nothing else; encoding raises :class:`~tfbus.errors.WireEncodeError`.
Wire layout: ROS wiki "ROS/TCPROS" and ``roscpp_serialization``; the message is
``geometry_msgs/TransformStamped[] transforms``.
"""

from __future__ import annotations

import functools
import math
import struct
import sys
from collections.abc import Callable, Iterable, Sequence
from itertools import repeat
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from tfbus.codecs import _compiled_wire
from tfbus.errors import WireDecodeError, WireEncodeError
from tfbus.messages import (
    Clock,
    Header,
    LookupTransformGoal,
    LookupTransformResult,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.sensor_msgs import LaserScan
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "CLOCK_MD5SUM",
    "CLOCK_MSGDEF",
    "CLOCK_TYPE",
    "GOAL_ID_MD5",
    "GOAL_ID_TYPE",
    "GOAL_STATUS_ARRAY_MD5",
    "GOAL_STATUS_ARRAY_TYPE",
    "LOOKUP_FEEDBACK_MD5",
    "LOOKUP_FEEDBACK_TYPE",
    "LOOKUP_GOAL_MD5",
    "LOOKUP_GOAL_TYPE",
    "LOOKUP_RESULT_MD5",
    "LOOKUP_RESULT_TYPE",
    "MAX_SCAN_BEAMS",
    "MAX_TRANSFORMS",
    "ROSBAGS_TF_TYPE",
    "SCAN_MD5SUM",
    "SCAN_TYPE",
    "TF_MD5SUM",
    "TF_MSGDEF",
    "TF_TYPE",
    "TFCodec",
    "decode_clock",
    "decode_goal_id",
    "decode_lookup_goal",
    "decode_lookup_result",
    "decode_ros1_struct",
    "decode_scan",
    "decode_tf",
    "encode_clock",
    "encode_goal_id",
    "encode_goal_status_array",
    "encode_lookup_goal",
    "encode_lookup_result",
    "encode_scan",
    "encode_tf",
    "from_rosbags",
    "scan_definition",
    "tf_typestore",
    "to_rosbags",
]

TF_TYPE: Final = "tf2_msgs/TFMessage"
"""The ROS 1 type of ``/tf`` and ``/tf_static``."""
TF_MD5SUM: Final = "94810edda583a504dfda3829e70d7eec"
"""ROS 1 md5 of ``tf2_msgs/TFMessage``'s full definition (identical for ``tf/tfMessage``;
checked against rosbags' by :class:`TFCodec`)."""
TF_MSGDEF: Final = "geometry_msgs/TransformStamped[] transforms\n"
"""The body of tf2_msgs/TFMessage (and tf/tfMessage); its field types come from the store."""
ROSBAGS_TF_TYPE: Final = "tf2_msgs/msg/TFMessage"
"""rosbags' name of the type (``pkg/msg/Name``, ROS 1 and ROS 2 alike)."""

SCAN_TYPE: Final = "sensor_msgs/LaserScan"
"""The ROS 1 type of a laser scan topic (``/scan``)."""
SCAN_MD5SUM: Final = "90c7ef2dc6895d81024acba2ac42f369"
"""ROS 1 md5 of ``sensor_msgs/LaserScan`` (``rosmsg md5 sensor_msgs/LaserScan``; checked
against rosbags' by :func:`scan_definition`)."""
ROSBAGS_SCAN_TYPE: Final = "sensor_msgs/msg/LaserScan"
CLOCK_TYPE: Final = "rosgraph_msgs/Clock"
"""The ROS 1 type of ``/clock`` (simulated time)."""
CLOCK_MSGDEF: Final = "time clock\n"
"""The full definition of ``rosgraph_msgs/Clock`` (``Clock.msg``, comments removed)."""
CLOCK_MD5SUM: Final = "a9c97c1d230cfc112e270351a944ee47"
"""ROS 1 md5 of ``rosgraph_msgs/Clock`` (``rosmsg md5 rosgraph_msgs/Clock`` on Debian's
ROS 1; the md5 of ``"time clock"``, genmsg's rule for a message of builtin fields)."""
MAX_SCAN_BEAMS: Final = 1_000_000
"""Most beams :func:`decode_scan` accepts in ``ranges`` and in ``intensities`` each by
default (a 0.1 degree, 360 degree laser has 3 600)."""
MAX_TRANSFORMS: Final = 100_000
"""Most transforms :func:`decode_tf` accepts in one message by default (as
:func:`tfbus.codecs.cdr.decode_tf` and :class:`tfbus.codecs.native.WireLimits`)."""

LOOKUP_GOAL_TYPE: Final = "tf2_msgs/LookupTransformActionGoal"
LOOKUP_GOAL_MD5: Final = "f2e7bcdb75c847978d0351a13e699da5"
"""md5sum of ``tf2_msgs/LookupTransformActionGoal`` (tf2_msgs 0.7.6; checked against
Debian's python3-tf2-msgs by the tests)."""
LOOKUP_RESULT_TYPE: Final = "tf2_msgs/LookupTransformActionResult"
LOOKUP_RESULT_MD5: Final = "ac26ce75a41384fa8bb4dc10f491ab90"
"""md5sum of ``tf2_msgs/LookupTransformActionResult`` (tf2_msgs 0.7.6)."""
LOOKUP_FEEDBACK_TYPE: Final = "tf2_msgs/LookupTransformActionFeedback"
LOOKUP_FEEDBACK_MD5: Final = "aae20e09065c3809e8a8e87c4c8953fd"
"""md5sum of ``tf2_msgs/LookupTransformActionFeedback`` (tf2_msgs 0.7.6)."""
GOAL_STATUS_ARRAY_TYPE: Final = "actionlib_msgs/GoalStatusArray"
GOAL_STATUS_ARRAY_MD5: Final = "8b2b82f13216d0a8ea88bd3af735e619"
"""md5sum of ``actionlib_msgs/GoalStatusArray`` (an action's ``status`` topic)."""
GOAL_ID_TYPE: Final = "actionlib_msgs/GoalID"
GOAL_ID_MD5: Final = "302881f31927c1df708a2dbab0e80ee8"
"""md5sum of ``actionlib_msgs/GoalID`` (an action's ``cancel`` topic)."""

_SEC_MAX: Final = 2**31 - 1  # rosbags serialises ROS 1 time.sec as int32 (2038-01-19)
_DECODE_ERRORS: Final = (struct.error, UnicodeDecodeError, ValueError, IndexError, OverflowError)


_U32 = struct.Struct("<I")
_ROS1_HEAD = struct.Struct("<IIII")  # seq, sec, nsec, len(frame_id)


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


def _compiled_decoder() -> Callable[[bytes | memoryview], list[TransformStamped]] | None:
    """The compiled ROS 1 TFMessage decoder (``_cwire._tf_from_ros1``, where
    :func:`tfbus.codecs._compiled_wire` finds the compiled wire decoders) on a little-endian
    host; else None (:func:`decode_ros1_struct` decodes)."""
    wire = _compiled_wire()
    if wire is None or sys.byteorder != "little":
        return None
    decode: Callable[[bytes | memoryview], list[TransformStamped]] = wire._tf_from_ros1
    return decode


_compiled_ros1: Callable[[bytes | memoryview], list[TransformStamped]] | None = (
    _compiled_decoder()
)
"""The compiled ROS 1 TFMessage decoder (objects built in C), where there is one."""


def _compiled_encoder() -> Callable[[Iterable[TransformStamped], bool], bytes | None] | None:
    """The compiled ROS 1 TFMessage writer (``_cwire._tf_to_ros1``: the bytes of
    :func:`_encode_struct` for the common form of a message, None for anything else)
    where :func:`tfbus.codecs._compiled_wire` finds the compiled wire code; else None."""
    wire = _compiled_wire()
    if wire is None:
        return None
    encode: Callable[[Iterable[TransformStamped], bool], bytes | None] = wire._tf_to_ros1
    return encode


_compiled_encode = _compiled_encoder()
"""The compiled ROS 1 TFMessage writer, where there is one."""


def _decode_ros1_compiled_or_struct(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a ROS 1 serialized TFMessage (little endian, Header with ``seq``).

    With the compiled core (on a little-endian host) the transforms are built in C
    (``tfbus.codecs._cwire._tf_from_ros1``, ~3x faster at 50 transforms); otherwise by
    :func:`decode_ros1_struct`. Equal values either way (tested).

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    if _compiled_ros1 is not None:
        return _compiled_ros1(raw)
    return _decode_struct(raw)


def _decode_struct(raw: bytes | memoryview) -> list[TransformStamped]:
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


def decode_tf(data: bytes | memoryview, *, max_transforms: int = MAX_TRANSFORMS) -> TFMessage:
    """Decode a ROS 1 serialized TFMessage (little endian, Header with ``seq``).

    With the compiled core (on a little-endian host) the transforms are built in C
    (``tfbus.codecs._cwire._tf_from_ros1``, ~3x faster at 50 transforms); otherwise by
    :func:`decode_ros1_struct`. Equal values either way (tested). Bytes after the message
    are ignored (a TCPROS frame or bag record holds exactly one message).

    Raises:
        WireDecodeError: the payload is shorter than its contents, a frame id is not
            UTF-8, or it announces more than ``max_transforms`` transforms (the message
            says which).
    """
    if len(data) >= 4:
        (count,) = _U32.unpack_from(data, 0)
        if count > max_transforms:
            raise WireDecodeError(
                f"{TF_TYPE} holds {count} transforms (limit {max_transforms})"
            )
    return TFMessage(tuple(_decode_transforms(data)))


def _decode_transforms(raw: bytes | memoryview) -> list[TransformStamped]:
    """The transforms of a ROS 1 TFMessage, as a list (what :func:`decode_tf` wraps and
    the ROS 1 transport delivers in a per-publisher ``TFMessage``).

    Raises:
        WireDecodeError: the payload is shorter than its contents or a frame id is not
            UTF-8.
    """
    try:
        return _decode_ros1_compiled_or_struct(raw)
    except _DECODE_ERRORS as exc:
        raise WireDecodeError(str(exc) or type(exc).__name__) from None


def decode_ros1_struct(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a ROS 1 serialized TFMessage with :mod:`struct` (the pure-Python path).

    A publisher sends the same frames message after message, so the same layout (count,
    size and the length of every frame id): after a message of 12 to 4096 transforms was
    decoded one transform at a time, its layout is kept as a single :class:`struct.Struct`
    (16384 transforms over all layouts at most); a later message of the same count and
    size is unpacked by it in one call, used only if every length field it read equals
    the layout's (otherwise the transform-at-a-time decoder runs), and its values are
    built column by column. Both paths give equal values.

    Raises:
        WireDecodeError: the payload is shorter than its contents or a frame id is not
            UTF-8.
    """
    try:
        return _decode_struct(raw)
    except _DECODE_ERRORS as exc:
        raise WireDecodeError(str(exc) or type(exc).__name__) from None


def tf_typestore(*, ros1: bool, msgtype: str = ROSBAGS_TF_TYPE) -> Typestore:
    """A rosbags typestore (``ROS1_NOETIC`` or ``ROS2_HUMBLE``) that knows ``msgtype``
    (default ``tf2_msgs/msg/TFMessage``; ROS1_NOETIC lacks tf2_msgs, and a bag may name
    the type ``tf/msg/tfMessage``: registered from :data:`TF_MSGDEF` when missing).

    Raises:
        ImportError: rosbags is not installed (``pip install 'tfbus[ros1]'``).
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if msgtype not in store.types:
        store.register(get_types_from_msg(TF_MSGDEF, msgtype))
    return store


def to_rosbags(store: Typestore, transforms: Iterable[TransformStamped], *, ros1: bool) -> Any:
    """The rosbags ``tf2_msgs/msg/TFMessage`` object of ``transforms`` in ``store``
    (:func:`tf_typestore`), ready for ``serialize_ros1`` (``ros1``: the header has a
    ``seq``, written 0 as tf2_ros does) or ``serialize_cdr``.

    Raises:
        AttributeError, TypeError, ValueError: an element is not a ``TransformStamped``
            of float-convertible values.
    """
    t = store.types
    time_ = t["builtin_interfaces/msg/Time"]
    header_ = t["std_msgs/msg/Header"]
    stamped_ = t["geometry_msgs/msg/TransformStamped"]
    transform_ = t["geometry_msgs/msg/Transform"]
    vector_ = t["geometry_msgs/msg/Vector3"]
    quat_ = t["geometry_msgs/msg/Quaternion"]
    items = []
    for ts in transforms:
        sec, nsec = divmod(ts.header.stamp.ns, NSEC_PER_SEC)
        stamp = time_(sec=sec, nanosec=nsec)
        frame_id = ts.header.frame_id
        head = (
            header_(seq=0, stamp=stamp, frame_id=frame_id)
            if ros1
            else header_(stamp=stamp, frame_id=frame_id)
        )
        tr, q = ts.transform.translation, ts.transform.rotation
        items.append(
            stamped_(
                header=head,
                child_frame_id=ts.child_frame_id,
                transform=transform_(
                    translation=vector_(x=float(tr.x), y=float(tr.y), z=float(tr.z)),
                    rotation=quat_(x=float(q.x), y=float(q.y), z=float(q.z), w=float(q.w)),
                ),
            )
        )
    return t[ROSBAGS_TF_TYPE](transforms=items)


def from_rosbags(msg: Any) -> list[TransformStamped]:
    """Convert a rosbags-deserialized TFMessage object (ROS 1 or ROS 2) to tfbus values."""
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


class TFCodec:
    """ROS 1 (de)serialisation of ``tf2_msgs/TFMessage``: :func:`_encode_struct` writes,
    :func:`decode_tf`'s decoder reads (valid because a TCPROS connection's md5sum is checked to be
    :data:`TF_MD5SUM`); :meth:`encode_generic` and :meth:`decode_generic` are rosbags'
    writer and reader, the references.

    Raises:
        ImportError: rosbags is not installed (``pip install 'tfbus[ros1]'``).
    """

    def __init__(self) -> None:
        try:
            store = tf_typestore(ros1=True)
        except ImportError as exc:
            raise ImportError(
                "the ROS 1 transport needs rosbags: pip install 'tfbus[ros1]'"
            ) from exc
        self._store = store
        definition, md5 = store.generate_msgdef(ROSBAGS_TF_TYPE, ros_version=1)
        if md5 != TF_MD5SUM:  # pragma: no cover - a rosbags regression, not an input error
            raise RuntimeError(f"rosbags gives md5 {md5} for {TF_TYPE}, expected {TF_MD5SUM}")
        self.definition: str = definition
        """The full message definition for the TCPROS ``message_definition`` field."""

    def encode(self, transforms: Iterable[TransformStamped]) -> bytes:
        """Serialise transforms as one ROS 1 ``TFMessage`` (each header's ``seq`` 0, as
        tf2_ros writes it), in C with the compiled core for the common form of a message
        (``tfbus.codecs._cwire._tf_to_ros1``), else with :mod:`struct`
        (:func:`_encode_struct`): the bytes of rosbags' ``serialize_ros1``
        (:meth:`encode_generic`, the reference both are tested against), as roscpp's
        ``serialize`` writes each field in turn.

        Raises:
            WireEncodeError: a stamp before 1970 or from 2038-01-19 on (rosbags writes
                ROS 1's ``time.sec`` as int32; ROS 1 itself reads uint32), or a field of
                the wrong type, naming the frame (a ``ValueError``).
        """
        if _compiled_encode is not None:  # the common form, written in C
            data = _compiled_encode(transforms, False)
            if data is not None:
                return data
        return _encode_struct(transforms)

    def encode_framed(self, transforms: Iterable[TransformStamped]) -> bytes:
        """:meth:`encode`'s bytes with their TCPROS length prefix (``uint32``, little
        endian: ``roscpp``'s ``serializeMessage``, what a publisher writes to each
        subscriber), made in the same join rather than copied after it.

        Raises:
            WireEncodeError: as :meth:`encode`.
        """
        if _compiled_encode is not None:  # the common form, written in C
            data = _compiled_encode(transforms, True)
            if data is not None:
                return data
        return _encode_struct(transforms, True)

    def encode_generic(self, transforms: Iterable[TransformStamped]) -> bytes:
        """Serialise transforms as one ROS 1 ``TFMessage`` with rosbags' typestore
        (``serialize_ros1``): the reference of :meth:`encode`.

        Raises:
            WireEncodeError: as :meth:`encode`.
        """
        items = list(transforms)
        for ts in items:
            _check_ros1_stamp(ts.header.stamp.ns, ts.child_frame_id)
        try:
            msg = to_rosbags(self._store, items, ros1=True)
            return bytes(self._store.serialize_ros1(msg, ROSBAGS_TF_TYPE))
        except (struct.error, UnicodeEncodeError, TypeError, AttributeError, ValueError) as exc:
            raise WireEncodeError(f"cannot serialise a TFMessage for ROS 1: {exc}") from exc

    def decode(self, raw: bytes | memoryview) -> list[TransformStamped]:
        """Deserialise one ROS 1 ``TFMessage`` (:func:`decode_tf`'s decoder, the
        transforms as a list): 3-5x faster than
        rosbags' generic deserialiser (:meth:`decode_generic`, the reference it is tested
        against), which keeps a 50-transform message's latency near roscpp's.

        Raises:
            WireDecodeError: the bytes are not a whole ``TFMessage`` (short, bad UTF-8).
        """
        return _decode_transforms(raw)

    def decode_generic(self, raw: bytes) -> list[TransformStamped]:
        """Deserialise one ROS 1 ``TFMessage`` with rosbags' generic deserialiser.

        Raises:
            WireDecodeError: the bytes are not a whole ``TFMessage``.
        """
        try:
            return from_rosbags(self._store.deserialize_ros1(raw, ROSBAGS_TF_TYPE))
        except Exception as exc:  # rosbags raises struct.error, UnicodeDecodeError, ...
            raise WireDecodeError(
                f"malformed {TF_TYPE}: {type(exc).__name__}: {exc}"
            ) from None


def _check_ros1_stamp(ns: int, child_frame_id: object) -> None:
    """Refuse a stamp outside ``0 .. 2**31-1`` s (what rosbags writes as ROS 1 time).

    Raises:
        WireEncodeError: the stamp is out of that range, naming the frame.
    """
    if not 0 <= ns // NSEC_PER_SEC <= _SEC_MAX:
        raise WireEncodeError(
            f"header.stamp {ns} ns of {child_frame_id!r} is outside ROS 1's time "
            "as sent (0 .. 2**31-1 s)"
        )


_TF_HEADER = struct.Struct("<4I")  # seq, stamp.secs, stamp.nsecs, len(frame_id)
_TF_POSE = struct.Struct("<7d")  # translation x y z, rotation x y z w


_ONE_HEAD = struct.Struct("<5I")  # count 1, seq 0, stamp.secs, stamp.nsecs, len(frame_id)
_ONE_FRAMED = struct.Struct("<6I")  # the TCPROS length, then _ONE_HEAD's fields
_ONE_FIXED: Final = _ONE_HEAD.size + _TF_POSE.size  # a one-transform message but its ids
_PAIR_BYTES_MAX: Final = 4096  # frame pairs whose encoded ids are kept (then cleared)
# (frame_id, child_frame_id) -> (len(frame_id as UTF-8), frame_id + len(child) + child,
# the message's length)
_pair_bytes: dict[tuple[str, str], tuple[int, bytes, int]] = {}


def _encode_struct(transforms: Iterable[TransformStamped], framed: bool = False) -> bytes:
    """One ROS 1 ``TFMessage`` (``framed``: with its TCPROS ``uint32`` length first):
    ``uint32`` count, then per transform ``std_msgs/Header``
    (``seq`` 0, ``time`` as two ``uint32``, ``frame_id``), ``child_frame_id`` (strings
    as ``uint32`` length + UTF-8) and seven ``float64`` (``roscpp_serialization``,
    little endian).

    A list or tuple of one transform (a broadcaster's tick) is written with the ids'
    bytes (``frame_id``, ``child_frame_id``'s length and bytes) encoded once per frame
    pair and kept (up to ``_PAIR_BYTES_MAX`` pairs, then cleared): one ``struct`` call
    for the count and header, one for the pose, three parts joined; anything it cannot
    write falls through to the loop, which writes it or names what is wrong.

    With the compiled core, :meth:`TFCodec.encode` and :meth:`TFCodec.encode_framed` write
    a message of the common form (a list or tuple of the message classes themselves,
    ``float`` values, UTF-8 ids, a stamp ROS 1 can carry) in C
    (``tfbus.codecs._cwire._tf_to_ros1``: the same bytes, tested) and call this for the
    rest.

    Raises:
        WireEncodeError: as :meth:`TFCodec.encode`.
    """
    if (type(transforms) is list or type(transforms) is tuple) and len(transforms) == 1:
        try:
            one = transforms[0]
            header = one.header
            frame_id = header.frame_id
            child = one.child_frame_id
            pair = (frame_id, child)
            ids = _pair_bytes.get(pair)
            if ids is None and type(frame_id) is str and type(child) is str:
                frame_bytes = frame_id.encode()
                child_bytes = child.encode()
                if len(_pair_bytes) >= _PAIR_BYTES_MAX:
                    _pair_bytes.clear()
                ids_bytes = frame_bytes + _U32.pack(len(child_bytes)) + child_bytes
                ids = _pair_bytes[pair] = (
                    len(frame_bytes), ids_bytes, _ONE_FIXED + len(ids_bytes)
                )
            sec, nsec = divmod(header.stamp.ns, NSEC_PER_SEC)
            if ids is not None and 0 <= sec <= _SEC_MAX:
                tr, q = one.transform.translation, one.transform.rotation
                return b"".join((
                    _ONE_FRAMED.pack(ids[2], 1, 0, sec, nsec, ids[0]) if framed
                    else _ONE_HEAD.pack(1, 0, sec, nsec, ids[0]),
                    ids[1],
                    # struct's "d" converts as float() does; what it refuses (a str)
                    # goes to the loop below, which applies float() itself
                    _TF_POSE.pack(tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w),
                ))  # fmt: skip
        except (struct.error, UnicodeEncodeError, TypeError, AttributeError, ValueError):
            pass  # the loop below raises the error that names the field
    parts: list[bytes] = [b""]
    append = parts.append
    header_pack, pose_pack, u32_pack = _TF_HEADER.pack, _TF_POSE.pack, _U32.pack
    n = 0
    ts: Any = None
    try:
        for ts in transforms:
            header = ts.header
            ns = header.stamp.ns
            sec, nsec = divmod(ns, NSEC_PER_SEC)
            if not 0 <= sec <= _SEC_MAX:
                _check_ros1_stamp(ns, ts.child_frame_id)
            frame_id = header.frame_id.encode()
            child = ts.child_frame_id.encode()
            tr, q = ts.transform.translation, ts.transform.rotation
            append(header_pack(0, sec, nsec, len(frame_id)))
            append(frame_id)
            append(u32_pack(len(child)))
            append(child)
            append(pose_pack(float(tr.x), float(tr.y), float(tr.z),
                             float(q.x), float(q.y), float(q.z), float(q.w)))  # fmt: skip
            n += 1
    except (struct.error, UnicodeEncodeError, TypeError, AttributeError, ValueError) as exc:
        if isinstance(exc, WireEncodeError):
            raise
        child_frame_id = getattr(ts, "child_frame_id", None)
        raise WireEncodeError(
            f"cannot serialise a TFMessage for ROS 1: transforms[{n}] "
            f"(child_frame_id {child_frame_id!r:.80}): {exc}"
        ) from exc
    parts[0] = u32_pack(n)
    if framed:
        body = b"".join(parts)
        return u32_pack(len(body)) + body
    return b"".join(parts)


@functools.cache
def _tf_codec() -> TFCodec:
    """The one :class:`TFCodec` of :func:`encode_tf` (rosbags' typestore, built once)."""
    return TFCodec()


def encode_tf(message: TFMessage | Sequence[TransformStamped]) -> bytes:
    """Serialise a TFMessage (or its transforms) as ROS 1 ``tf2_msgs/TFMessage`` (each
    header's ``seq`` 0, as tf2_ros writes it) (:meth:`TFCodec.encode`: :mod:`struct`,
    tested equal to rosbags' ``serialize_ros1``).

    Raises:
        WireEncodeError: a stamp before 1970 or from 2038-01-19 on, or a field of the
            wrong type, naming the frame.
        ImportError: rosbags is not installed (``pip install 'tfbus[ros1]'``).
    """
    transforms = message.transforms if isinstance(message, TFMessage) else message
    return _tf_codec().encode(transforms)


# -- sensor_msgs/LaserScan ----------------------------------------------------------------

_SCAN_FLOATS = struct.Struct("<7fI")  # angle_min ... range_max, then len(ranges)
_F32_LE: Final = "<f4"


def encode_scan(message: LaserScan) -> bytes:
    """A :class:`~tfbus.sensor_msgs.LaserScan` as ROS 1 serializes ``sensor_msgs/LaserScan``
    (the layout :func:`decode_scan` reads; ``header.seq`` 0): the arrays as little-endian
    float32s, bit for bit. Tested equal to rosbags' ``serialize_ros1``.

    Raises:
        WireEncodeError: ``message`` is not a LaserScan, its stamp is outside ROS 1's time
            (0 .. 2**32-1 s), its ``frame_id`` is not a ``str``, or a field does not
            convert to float32 (the message names the field).
    """
    if not isinstance(message, LaserScan):
        raise WireEncodeError(f"{SCAN_TYPE}: expected a LaserScan, got {message!r:.100}")
    header = message.header
    sec, nsec = divmod(header.stamp.ns, NSEC_PER_SEC)
    if not 0 <= sec < 2**32:
        raise WireEncodeError(f"{SCAN_TYPE}.header.stamp {sec} s is outside ROS 1 time")
    if not isinstance(header.frame_id, str):
        raise WireEncodeError(f"{SCAN_TYPE}.header.frame_id must be a str, "
                              f"got {header.frame_id!r:.100}")
    frame = header.frame_id.encode()
    try:
        arrays = [np.ascontiguousarray(getattr(message, name), dtype=_F32_LE).reshape(-1)
                  for name in ("ranges", "intensities")]
        floats = struct.pack("<7f", *(float(getattr(message, name)) for name in _SCAN_FIELDS))
    except (TypeError, ValueError, OverflowError, struct.error) as exc:
        raise WireEncodeError(f"{SCAN_TYPE}: a field does not convert to float32: {exc}") from None
    return b"".join((
        _ROS1_HEAD.pack(0, sec, nsec, len(frame)), frame, floats,
        _U32.pack(arrays[0].size), arrays[0].tobytes(),
        _U32.pack(arrays[1].size), arrays[1].tobytes(),
    ))


_SCAN_FIELDS: Final = (
    "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
    "range_min", "range_max",
)  # fmt: skip


def decode_scan(data: bytes | memoryview, *, max_beams: int = MAX_SCAN_BEAMS) -> LaserScan:
    """A ROS 1 serialized ``sensor_msgs/LaserScan`` (``LaserScan.msg``: ``Header header``,
    seven ``float32`` -- angles in radians, times in seconds, ranges in metres -- then
    ``float32[] ranges`` and ``float32[] intensities``, each a ``uint32`` count and that
    many little-endian floats; ROS wiki "msg", "Serialization") as a
    :class:`~tfbus.sensor_msgs.LaserScan`. The arrays are copied bit for bit (NaN and
    infinities kept); the header's ``seq`` is dropped, as tfbus's Header has none.

    Raises:
        WireDecodeError: truncated data, trailing bytes, a ``frame_id`` that is not UTF-8,
            a stamp out of range, or an array of more than ``max_beams`` beams (checked
            before anything is allocated).
    """
    buf = bytes(data)
    try:
        _seq, sec, nsec, flen = _ROS1_HEAD.unpack_from(buf, 0)
        pos = 16 + flen
        if pos > len(buf):
            raise WireDecodeError(f"LaserScan truncated in header.frame_id ({flen} bytes)")
        try:
            frame_id = buf[16:pos].decode()
        except UnicodeDecodeError:
            raise WireDecodeError("LaserScan header.frame_id is not UTF-8") from None
        a_min, a_max, a_inc, t_inc, scan_time, r_min, r_max, n = _SCAN_FLOATS.unpack_from(
            buf, pos
        )
        pos += _SCAN_FLOATS.size
        arrays = []
        for name in ("ranges", "intensities"):
            if name == "intensities":
                (n,) = _U32.unpack_from(buf, pos)
                pos += 4
            if n > max_beams:
                raise WireDecodeError(f"LaserScan.{name}: {n} beams exceed {max_beams}")
            end = pos + 4 * n
            if end > len(buf):
                raise WireDecodeError(f"LaserScan truncated in {name} ({n} beams)")
            arrays.append(np.frombuffer(buf, _F32_LE, n, pos).astype(np.float32))
            pos = end
        if pos != len(buf):
            raise WireDecodeError(f"LaserScan with {len(buf) - pos} trailing bytes")
        stamp = Time.from_ns(sec * NSEC_PER_SEC + nsec)
        return LaserScan(
            Header(stamp, frame_id), a_min, a_max, a_inc, t_inc, scan_time, r_min, r_max,
            arrays[0], arrays[1],
        )  # fmt: skip
    except WireDecodeError:
        raise
    except _DECODE_ERRORS as exc:
        raise WireDecodeError(
            f"malformed {SCAN_TYPE}: {str(exc) or type(exc).__name__}"
        ) from None


def scan_definition() -> str:
    """The full ROS 1 message definition of ``sensor_msgs/LaserScan`` (with
    ``std_msgs/Header``), for a TCPROS connection header; made by rosbags' typestore.

    Raises:
        ImportError: rosbags is not installed (``pip install 'tfbus[ros1]'``).
        RuntimeError: rosbags gives another md5 than :data:`SCAN_MD5SUM`.
    """
    definition, md5 = tf_typestore(ros1=True).generate_msgdef(ROSBAGS_SCAN_TYPE, ros_version=1)
    if md5 != SCAN_MD5SUM:  # pragma: no cover - a rosbags regression, not an input error
        raise RuntimeError(f"rosbags gives md5 {md5} for {SCAN_TYPE}, expected {SCAN_MD5SUM}")
    return str(definition)


# -- rosgraph_msgs/Clock ------------------------------------------------------------------

_TIME = struct.Struct("<II")  # ROS 1 time: uint32 secs, uint32 nsecs


def encode_clock(message: Clock) -> bytes:
    """A :class:`~tfbus.messages.Clock` as ROS 1 serializes ``rosgraph_msgs/Clock``: 8
    bytes, ``uint32`` seconds then ``uint32`` nanoseconds, little endian (ROS wiki "msg",
    "Serialization"; ROS 1 ``time`` is unsigned, seconds below 2**32).

    Raises:
        WireEncodeError: ``message`` is not a Clock holding a :class:`~tfbus.time.Time`,
            or its seconds do not fit a ``uint32`` (after year 2106).
    """
    stamp = message.clock if isinstance(message, Clock) else None
    if not isinstance(stamp, Time):
        raise WireEncodeError(f"{CLOCK_TYPE}.clock must be a Time, got {stamp!r}")
    sec, nsec = divmod(stamp.ns, NSEC_PER_SEC)
    if sec >= 2**32:
        raise WireEncodeError(f"{CLOCK_TYPE}.clock {sec} s does not fit a ROS 1 uint32 time")
    return _TIME.pack(sec, nsec)


def decode_clock(data: bytes | memoryview) -> Clock:
    """A ROS 1 serialized ``rosgraph_msgs/Clock`` (see :func:`encode_clock`) as a
    :class:`~tfbus.messages.Clock`.

    Raises:
        WireDecodeError: not exactly 8 bytes, or ``nsecs`` of a billion or more (the
            ROS 1 time normal form).
    """
    if len(data) != 8:
        raise WireDecodeError(f"malformed {CLOCK_TYPE}: {len(data)} bytes, expected 8")
    sec, nsec = _unpack_time(data)
    if nsec >= NSEC_PER_SEC:
        raise WireDecodeError(f"malformed {CLOCK_TYPE}: clock.nsecs {nsec} >= 1e9")
    # Time.from_ns and Clock(...) without their Python calls: a uint32 sec and a nsec
    # below 1e9 are always within Time's range (a /clock at 1 kHz decodes in a thread
    # of its own: tfbus.transports.ros1.transport.Ros1Transport._clock_frame)
    stamp = _new_time(Time)
    stamp._ns = sec * NSEC_PER_SEC + nsec
    return _new_tuple(Clock, (stamp,))


_unpack_time = _TIME.unpack
_new_time = Time.__new__
_new_tuple = tuple.__new__


# -- tf2_msgs/LookupTransform over actionlib ----------------------------------------------
# LookupTransformActionGoal: Header header, actionlib_msgs/GoalID goal_id (time stamp,
# string id), LookupTransformGoal goal (string target_frame, string source_frame, time
# source_time, duration timeout, time target_time, string fixed_frame, bool advanced).
# LookupTransformActionResult: Header header, actionlib_msgs/GoalStatus status (GoalID
# goal_id, uint8 status, string text), LookupTransformResult result
# (geometry_msgs/TransformStamped transform, tf2_msgs/TF2Error error: uint8 error,
# string error_string). tf2_msgs 0.7.6 ``LookupTransform.action``, actionlib_msgs 1.12.

_U8 = struct.Struct("<B")
_DURATION = struct.Struct("<ii")  # ROS 1 duration: int32 secs, int32 nsecs
_POSE = struct.Struct("<7d")
_ACTION_ERRORS: Final = (struct.error, UnicodeDecodeError, ValueError, OverflowError)


def _string(text: str, field: str) -> bytes:
    """A ROS 1 string (``uint32`` length, UTF-8 bytes).

    Raises:
        WireEncodeError: ``text`` is not a str or cannot be UTF-8 (a lone surrogate),
            naming ``field`` and the value.
    """
    try:
        raw = text.encode()
    except (AttributeError, UnicodeEncodeError):
        raise WireEncodeError(f"{field} must be a str of Unicode characters (UTF-8 "
                              f"encodable), got {text!r:.100}") from None
    return _U32.pack(len(raw)) + raw


def _time(t: Time, field: str) -> bytes:
    sec, nsec = divmod(t.ns, NSEC_PER_SEC)
    if sec > 0xFFFF_FFFF:
        raise WireEncodeError(
            f"{field} {sec}.{nsec:09d} s is past ROS 1 time (uint32 seconds)"
        )
    return _TIME.pack(sec, nsec)


def _header(stamp: Time, field: str) -> bytes:
    """A ``std_msgs/Header`` with ``seq`` 0 and no frame id (actionlib's messages)."""
    return _U32.pack(0) + _time(stamp, field) + _string("", "header.frame_id")


class _Reader:
    """Reads ROS 1 fields one after the other (struct, strings bounded by the data)."""

    def __init__(self, raw: bytes) -> None:
        self.raw, self.off = raw, 0

    def take(self, st: struct.Struct) -> tuple[Any, ...]:
        out = st.unpack_from(self.raw, self.off)
        self.off += st.size
        return out

    def string(self) -> str:
        (n,) = self.take(_U32)
        if n > len(self.raw) - self.off:
            raise ValueError(f"a string of {n} bytes runs past the end of the message")
        text = self.raw[self.off : self.off + n].decode()
        self.off += n
        return text

    def time(self) -> Time:
        sec, nsec = self.take(_TIME)
        return Time.from_ns(sec * NSEC_PER_SEC + nsec)

    def header(self) -> Header:
        self.take(_U32)  # seq
        stamp = self.time()
        return Header(stamp, self.string())


def encode_lookup_goal(message: LookupTransformGoal) -> bytes:
    """A :class:`~tfbus.messages.LookupTransformGoal` as ROS 1
    ``tf2_msgs/LookupTransformActionGoal`` (:data:`LOOKUP_GOAL_MD5`): the header (``seq``
    0) and the ``GoalID`` stamped ``goal_stamp``, ``timeout`` as a ROS 1 duration (whole
    seconds and nanoseconds).

    Raises:
        WireEncodeError: a time at or after 2**32 s (past ROS 1 time, uint32 seconds),
            naming the field, a timeout that is not a finite number, or a goal id or
            frame id that is not a str UTF-8 can carry (a lone surrogate), named.
    """
    g = message
    if not isinstance(g.timeout, (int, float)) or not math.isfinite(g.timeout):
        raise WireEncodeError(f"{LOOKUP_GOAL_TYPE}: goal.timeout must be a finite number "
                              f"of seconds, got {g.timeout!r:.100}")
    seconds = math.floor(g.timeout)
    try:
        duration = _DURATION.pack(seconds, round((g.timeout - seconds) * 1e9))
    except struct.error:
        raise WireEncodeError(f"{LOOKUP_GOAL_TYPE}: goal.timeout {g.timeout} s does not "
                              "fit a ROS 1 duration (int32 seconds)") from None
    return b"".join((
        _header(g.goal_stamp, "goal_stamp"),
        _time(g.goal_stamp, "goal_stamp"), _string(g.goal_id, "goal_id"),
        _string(g.target_frame, "goal.target_frame"),
        _string(g.source_frame, "goal.source_frame"),
        _time(g.source_time, "source_time"), duration,
        _time(g.target_time, "target_time"), _string(g.fixed_frame, "goal.fixed_frame"),
        _U8.pack(1 if g.advanced else 0),
    ))


def decode_lookup_goal(data: bytes | memoryview) -> LookupTransformGoal:
    """A ROS 1 ``tf2_msgs/LookupTransformActionGoal`` as a
    :class:`~tfbus.messages.LookupTransformGoal` (``goal_stamp`` from the ``GoalID``; a
    negative timeout read as 0, as tf2_ros's server waits no time then).

    Raises:
        WireDecodeError: the bytes are not such a message (short, a string past the end,
            not UTF-8).
    """
    try:
        r = _Reader(bytes(data))
        r.header()
        stamp = r.time()
        goal_id = r.string()
        target, source = r.string(), r.string()
        source_time = r.time()
        sec, nsec = r.take(_DURATION)
        target_time = r.time()
        fixed = r.string()
        (advanced,) = r.take(_U8)
    except _ACTION_ERRORS as exc:
        raise WireDecodeError(f"malformed {LOOKUP_GOAL_TYPE}: {exc}") from None
    return LookupTransformGoal(target, source, source_time, max(0.0, sec + nsec / 1e9),
                               target_time, fixed, bool(advanced), goal_id, stamp)


def _goal_status(goal_id: str, stamp: Time, status: int, text: str) -> bytes:
    """An ``actionlib_msgs/GoalStatus``."""
    return (_time(stamp, "goal_stamp") + _string(goal_id, "goal_id") + _U8.pack(status)
            + _string(text, "status.text"))


def encode_lookup_result(message: LookupTransformResult) -> bytes:
    """A :class:`~tfbus.messages.LookupTransformResult` as ROS 1
    ``tf2_msgs/LookupTransformActionResult`` (:data:`LOOKUP_RESULT_MD5`): the header
    (``seq`` 0, stamped ``stamp``), the ``GoalStatus`` of the goal answered, the transform
    (its header's ``seq`` 0) and the ``TF2Error``.

    Raises:
        WireEncodeError: a stamp at or after 2**32 s (past ROS 1 time), naming the field,
            a status or error code outside uint8, or a string (frame id, goal id, status
            text, error string) UTF-8 cannot carry (a lone surrogate), named.
    """
    m = message
    t = m.transform.transform
    try:
        codes = _U8.pack(m.status), _U8.pack(m.error)
    except struct.error:
        raise WireEncodeError(f"{LOOKUP_RESULT_TYPE}: status {m.status!r} or error "
                              f"{m.error!r} is not a uint8") from None
    return b"".join((
        _header(m.stamp, "stamp"),
        _time(m.goal_stamp, "goal_stamp"), _string(m.goal_id, "goal_id"), codes[0],
        _string(m.status_text, "status.text"),
        _U32.pack(0), _time(m.transform.header.stamp, "transform.header.stamp"),
        _string(m.transform.header.frame_id, "result.transform.header.frame_id"),
        _string(m.transform.child_frame_id, "result.transform.child_frame_id"),
        _POSE.pack(*t.translation, *t.rotation),
        codes[1], _string(m.error_string, "result.error.error_string"),
    ))


def decode_lookup_result(data: bytes | memoryview) -> LookupTransformResult:
    """A ROS 1 ``tf2_msgs/LookupTransformActionResult`` as a
    :class:`~tfbus.messages.LookupTransformResult`.

    Raises:
        WireDecodeError: the bytes are not such a message.
    """
    try:
        r = _Reader(bytes(data))
        sent = r.header().stamp
        goal_stamp = r.time()
        goal_id = r.string()
        (status,) = r.take(_U8)
        text = r.string()
        header = r.header()
        child = r.string()
        x, y, z, qx, qy, qz, qw = r.take(_POSE)
        (code,) = r.take(_U8)
        error_string = r.string()
    except _ACTION_ERRORS as exc:
        raise WireDecodeError(f"malformed {LOOKUP_RESULT_TYPE}: {exc}") from None
    ts = TransformStamped(header, child, Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)))
    return LookupTransformResult(ts, code, error_string, goal_id, goal_stamp, status, text,
                                 sent)


def encode_goal_id(stamp: Time, goal_id: str) -> bytes:
    """An ``actionlib_msgs/GoalID`` (:data:`GOAL_ID_MD5`; a cancel request: actionlib's
    client cancels its goal with ``GoalID(stamp=0, id=goal_id)``).

    Raises:
        WireEncodeError: a stamp at or after 2**32 s, or a goal id UTF-8 cannot carry.
    """
    return _time(stamp, "stamp") + _string(goal_id, "goal_id")


def decode_goal_id(data: bytes | memoryview) -> tuple[Time, str]:
    """``(stamp, id)`` of an ``actionlib_msgs/GoalID`` (a cancel request).

    Raises:
        WireDecodeError: the bytes are not such a message.
    """
    try:
        r = _Reader(bytes(data))
        stamp = r.time()
        goal_id = r.string()
    except _ACTION_ERRORS as exc:
        raise WireDecodeError(f"malformed {GOAL_ID_TYPE}: {exc}") from None
    return stamp, goal_id


def encode_goal_status_array(stamp: Time,
                             statuses: Iterable[tuple[str, Time, int, str]]) -> bytes:
    """An ``actionlib_msgs/GoalStatusArray`` (:data:`GOAL_STATUS_ARRAY_MD5`) stamped
    ``stamp``, of ``(goal id, goal stamp, status, text)`` entries (actionlib's
    ``GoalStatus`` codes: 1 ACTIVE, 3 SUCCEEDED, ...).

    Raises:
        WireEncodeError: a stamp at or after 2**32 s, or a status outside uint8.
    """
    try:
        parts = [_goal_status(goal_id, goal_stamp, status, text)
                 for goal_id, goal_stamp, status, text in statuses]
    except struct.error:
        raise WireEncodeError(f"{GOAL_STATUS_ARRAY_TYPE}: a status is not a uint8") from None
    return _header(stamp, "stamp") + _U32.pack(len(parts)) + b"".join(parts)
