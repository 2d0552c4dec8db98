"""The tfbus wire format: compact msgpack (msgspec) with a magic byte and a version.

A payload on the wire is::

    byte 0      MAGIC (0xB7)           anything else: not a tfbus payload (malformed)
    byte 1      WIRE_VERSION (1)       anything else: counted as a version mismatch
    bytes 2..   msgpack array [sender, seq, tag, body]

``sender`` is a random 63-bit id of the sending transport (a restarted process gets a new
one), ``seq`` counts the messages that sender published on that topic (1, 2, ...), so a
receiver can detect gaps and keep per-publisher order. ``tag`` names the message type of
``body``:

* ``"tf"`` -- a :class:`~tfbus.messages.TFMessage`; ``body`` is the array of its
  transforms, each ``[[stamp_ns, frame_id], child_frame_id, [[x, y, z], [qx, qy, qz, qw]]]``
  (the NamedTuples' field order; stamps are integer nanoseconds, lengths metres).
* a registered name (``"TransformStamped"``, ``"PointStamped"``, ``"JointState"``, ... or
  anything added with :func:`register_message_type`) -- that type, encoded field by field.
* ``"LaserScan"`` -- a :class:`~tfbus.sensor_msgs.LaserScan`; ``body`` is
  ``[stamp_ns, frame_id, angle_min, angle_max, angle_increment, time_increment, scan_time,
  range_min, range_max, ranges, intensities]`` (the fields of sensor_msgs' ``LaserScan.msg``
  in order; angles radians, times seconds, ranges metres; ``ranges`` and ``intensities``
  msgpack ``bin`` of little-endian float32s, copied bit for bit, at most
  ``WireLimits.max_scan_beams`` each).
* ``"PointCloud2"`` -- a :class:`~tfbus.sensor_msgs.PointCloud2`; ``body`` is
  ``[stamp_ns, frame_id, height, width, fields, is_bigendian, point_step, row_step, data,
  is_dense]`` (sensor_msgs' ``PointCloud2.msg`` in order), each field
  ``[name, offset, datatype, count]`` (``PointField.msg``), ``data`` msgpack ``bin``
  copied bit for bit (bounded by ``max_payload_bytes``), at most
  ``WireLimits.max_cloud_fields`` fields. The wire checks types and ranges only: whether
  the fields and sizes describe ``data`` is the receiver's to check
  (:func:`tfbus.view.clouds.cloud_points`).
* ``""`` -- a plain msgpack value (None, bool, int, float, str, bytes, list, dict).

Decoding is defensive: a payload that is too large, not msgpack, of the wrong shape or
type, has more transforms than allowed or a frame id that is too long raises a
:class:`WireError` subclass, never anything else, so a receiver can count it and go on.
This module is synchronous and has no I/O: it is unit-testable alone.

**Shape.** Besides :class:`WireCodec` (what the Zenoh transport uses: a payload of a
stream, with its sender id and sequence number), the module has the functions of every
codec module of :mod:`tfbus.codecs`, with the same parameters: :func:`encode_tf` /
:func:`decode_tf`, :func:`encode_scan` / :func:`decode_scan`, :func:`encode_clock` /
:func:`decode_clock`. They write a payload outside any stream (sender
:data:`ONE_SHOT_SENDER`, sequence number 1, as a one-shot query reply is) and read any
payload, dropping its sender and number. tfbus's wire has no ``LookupTransform`` action:
its remote lookups are Zenoh queries (:mod:`tfbus.transports.zenoh.lookups`).

Two small msgpack readers run *before* msgspec (the last section of this module, byte
layout from the msgpack specification, https://github.com/msgpack/msgpack/blob/master/spec.md,
"Formats"): :func:`read_head` reads the envelope's first three fields (``sender``, ``seq``,
``tag``) by hand, so that the body is never skipped over generically (msgspec skips an
unknown value recursively: a payload nested 1 000 deep raised ``RecursionError``);
:func:`check_depth` walks one msgpack value iteratively and refuses nesting deeper than a
bound (:class:`~tfbus.errors.WireLimitError`), so that a generic (``Any``) decode that
follows cannot recurse far. Both raise :class:`~tfbus.errors.WireDecodeError` for bytes
that are not msgpack (truncated, reserved byte ``0xc1``).
"""

from __future__ import annotations

import re
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, NamedTuple

from tfbus._extras import require

require(__name__, "msgspec")

import msgspec
import numpy as np

from tfbus import messages as _m
from tfbus.codecs import _compiled_wire
from tfbus.errors import (
    WireDecodeError,
    WireEncodeError,
    WireError,
    WireLimitError,
    WireVersionError,
)
from tfbus.messages import Clock, TFMessage, TransformStamped
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField
from tfbus.time import TIME_MAX_NS, Time

__all__ = [
    "MAGIC",
    "MAX_SCAN_BEAMS",
    "MAX_TRANSFORMS",
    "ONE_SHOT_SENDER",
    "WIRE_VERSION",
    "Decoded",
    "WireCodec",
    "WireDecodeError",
    "WireEncodeError",
    "WireError",
    "WireLimitError",
    "WireLimits",
    "WireVersionError",
    "check_depth",
    "decode_clock",
    "decode_scan",
    "decode_tf",
    "encode_clock",
    "encode_scan",
    "encode_tf",
    "new_sender_id",
    "read_head",
    "register_message_type",
]

MAGIC: Final = 0xB7
WIRE_VERSION: Final = 1
_HEADER: Final = bytes((MAGIC, WIRE_VERSION))
_INT64_MAX: Final = 2**63 - 1
_ID: Final[Any] = Annotated[int, msgspec.Meta(ge=1, le=_INT64_MAX)]  # sender ids, seqs
_TF_TAG: Final = "tf"
_RAW_TAG: Final = ""
_SCAN_TAG: Final = "LaserScan"
_CLOUD_TAG: Final = "PointCloud2"
_U32: Final[Any] = Annotated[int, msgspec.Meta(ge=0, le=2**32 - 1)]
_F32_LE: Final = np.dtype("<f4")
_F32_MAX: Final = float(np.finfo(np.float32).max)


@dataclass(frozen=True, slots=True)
class WireLimits:
    """Bounds enforced when decoding (a sender cannot make a receiver allocate wildly).

    Attributes:
        max_payload_bytes: largest accepted payload, bytes (default 16 MiB).
        max_transforms: most transforms in one TFMessage (default 100 000).
        max_frame_id_length: longest ``frame_id`` / ``child_frame_id``, characters
            (default 256).
        max_depth: deepest nesting of msgpack arrays/maps in the body of a payload that
            is not a TFMessage (default 64), checked before decoding it (a TFMessage has
            a fixed shape and is decoded by a schema that refuses anything deeper).
        max_scan_beams: most beams (float32 values) in a LaserScan's ``ranges`` and in
            its ``intensities`` each (default 1 000 000; a 0.1 degree 360 degree laser
            has 3 600).
        max_cloud_fields: most fields (``PointField``) of a PointCloud2 (default 256).
    """

    max_payload_bytes: int = 16 * 1024 * 1024
    max_transforms: int = 100_000
    max_frame_id_length: int = 256
    max_depth: int = 64
    max_scan_beams: int = 1_000_000
    max_cloud_fields: int = 256


class Decoded(NamedTuple):
    """One decoded payload: who sent it, its per-topic sequence number, the message."""

    sender: int
    seq: int
    message: object


class CompiledTFDecoder(NamedTuple):
    """:meth:`WireCodec.tf_decoder`: the compiled decoder of a TFMessage payload and the
    arguments it takes after the payload (the codec's limits, the format's magic byte
    and version)."""

    decode: Callable[[bytes, int, int, int, int, int], tuple[int, int, TFMessage] | None]
    max_bytes: int
    max_transforms: int
    max_id: int
    magic: int
    version: int


class _OutEnvelope(msgspec.Struct, array_like=True):
    sender: int
    seq: int
    tag: str
    body: object


def new_sender_id() -> int:
    """A random positive 63-bit sender id (fits msgpack int64 on every implementation)."""
    return secrets.randbits(63) or 1


def _enc_hook(obj: object) -> object:
    if isinstance(obj, Time):
        return obj.ns
    raise NotImplementedError(f"cannot encode {type(obj).__qualname__}")


def _dec_hook(tp: type, obj: object) -> object:
    if tp is Time:
        if type(obj) is not int or not 0 <= obj <= TIME_MAX_NS:
            raise ValueError(
                f"a stamp must be an integer of nanoseconds in [0, {TIME_MAX_NS}], got {obj!r}"
            )
        t = Time.__new__(Time)
        t._ns = obj  # Time.from_ns without the re-validation: checked just above
        return t
    raise NotImplementedError(f"cannot decode {tp!r}")


# tag -> type; the names of tfbus.messages types are registered by default.
_REGISTRY: dict[str, type] = {}
_TAG_OF: dict[type, str] = {}


def register_message_type(cls: type, tag: str | None = None) -> None:
    """Let ``cls`` (a NamedTuple, dataclass or ``msgspec.Struct``) cross the wire typed.

    Both ends must register the same ``tag`` (default: the class's ``__qualname__``) for
    the same type before messages of it are exchanged; an unregistered object that is not
    a plain msgpack value cannot be sent (:class:`WireEncodeError`).

    Raises:
        ValueError: if ``tag`` is empty, ``"tf"`` or already registered for another type.
    """
    name = cls.__qualname__ if tag is None else tag
    if name in (_TF_TAG, _RAW_TAG, _SCAN_TAG, _CLOUD_TAG):
        raise ValueError(f"tag {name!r} is reserved")
    if _REGISTRY.get(name, cls) is not cls:
        raise ValueError(f"tag {name!r} is already registered for {_REGISTRY[name]!r}")
    _REGISTRY[name] = cls
    _TAG_OF[cls] = name


for _cls in (
    _m.Vector3,
    _m.Point,
    _m.Quaternion,
    _m.Transform,
    _m.Pose,
    _m.Header,
    _m.TransformStamped,
    _m.PointStamped,
    _m.PoseStamped,
    _m.Vector3Stamped,
    _m.JointState,
    _m.Clock,
):
    register_message_type(_cls)


class WireCodec:
    """Encode messages to payloads and decode payloads back, under :class:`WireLimits`.

    One codec per transport: it caches a msgspec decoder per registered type. Not
    thread-safe for concurrent use of one instance (msgspec encoders keep a buffer).
    """

    def __init__(self, limits: WireLimits | None = None) -> None:
        self.limits = limits or WireLimits()
        self._encoder = msgspec.msgpack.Encoder(enc_hook=_enc_hook)
        tf_body = _tf_schema(self.limits)
        self._tf_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder(tf_body)
        self._tf_envelope_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder(
            msgspec.defstruct(
                "_WireTFEnvelope",
                [
                    ("sender", _ID),
                    ("seq", _ID),
                    ("tag", Literal["tf"]),
                    ("body", tf_body),
                ],
                array_like=True,
                gc=False,
            )
        )
        self._raw_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder()
        self._scan_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder(
            _scan_schema(self.limits)
        )
        self._cloud_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder(
            _cloud_schema(self.limits)
        )
        self._typed: dict[str, Callable[[bytes | memoryview], object]] = {}
        self._max_bytes = self.limits.max_payload_bytes
        self._max_transforms = self.limits.max_transforms
        self._max_id = self.limits.max_frame_id_length

    # -- encoding -------------------------------------------------------------------

    def encode(self, message: object, *, sender: int, seq: int) -> bytes:
        """The payload for ``message`` from ``sender`` with sequence number ``seq``.

        With the compiled core, a TFMessage (the class itself) of the common form
        (``TransformStamped`` of the message classes, ``str`` ids, ``float`` values, a
        ``Time`` stamp) is written in C (``tfbus.codecs._cwire._tf_to_native``: the bytes
        msgspec writes, tested); anything else by msgspec.

        Raises:
            WireEncodeError: if the message type is neither a TFMessage, a registered
                type nor a plain msgpack value, or a field cannot be encoded.
        """
        if type(message) is _TFMessage and _compiled_tf_writer is not None:
            payload = _compiled_tf_writer(message[0], sender, seq, MAGIC, WIRE_VERSION)
            if payload is not None:
                return payload
        return _payload(self._encoder.encode, message, sender, seq)

    # -- decoding -------------------------------------------------------------------

    def tf_decoder(self) -> CompiledTFDecoder | None:
        """The first step of :meth:`decode` for a TFMessage, to be called per payload
        without this method's Python frame: ``decode(payload, max_bytes, max_transforms,
        max_id, magic, version)`` with this codec's limits answers ``(sender, seq,
        TFMessage)`` for a ``bytes`` payload of a TFMessage in the form tfbus writes it
        (what :meth:`decode` returns for it, equal: tested), None for any other payload,
        which :meth:`decode` then checks and decodes (raising what is wrong with it).
        None without the compiled core."""
        if _compiled_tf is None:
            return None
        return CompiledTFDecoder(_compiled_tf, self._max_bytes, self._max_transforms,
                                 self._max_id, MAGIC, WIRE_VERSION)  # fmt: skip

    def decode(self, payload: bytes | bytearray | memoryview) -> Decoded:
        """Decode one payload; nothing else than a :class:`WireError` ever escapes.

        A TFMessage body is decoded by a fixed schema (no part of it is decoded
        generically, so no nesting can make it recurse); any other body is first walked
        without decoding and refused if nested deeper than ``limits.max_depth``. With the
        compiled core, a TFMessage in the form tfbus writes it (float 64s, the envelope's
        four fields, nothing left over) is decoded in C first, with the checks of its
        size, magic byte and version (``tfbus.codecs._cwire._tf_from_native``: the
        schema's values, its limits); any other payload goes to those checks and the
        schema.

        Raises:
            WireDecodeError: bad magic byte, bad msgpack, wrong shape or field type, a
                stamp outside [0, 2**63) ns, a sender id or sequence number outside
                [1, 2**63), a finite LaserScan angle, time or range beyond float32, or any
                other failure of the decoder (nesting too deep included).
            WireVersionError: a tfbus payload of another format version.
            WireLimitError: payload too large, too many transforms, frame id too long,
                nesting too deep, a LaserScan with more than ``limits.max_scan_beams``
                beams.
        """
        data = payload
        if type(data) is not bytes and len(data) <= self._max_bytes:
            data = bytes(data)  # copied only within the limit
        if _compiled_tf is not None and type(data) is bytes:  # checked and built in C
            fast = _compiled_tf(data, self._max_bytes, self._max_transforms, self._max_id,
                                MAGIC, WIRE_VERSION)
            if fast is not None:
                return _new(Decoded, fast)
        n = len(data)
        if n > self.limits.max_payload_bytes:
            raise WireLimitError(f"payload of {n} bytes exceeds {self.limits.max_payload_bytes}")
        if n < 2 or data[0] != MAGIC:
            raise WireDecodeError("not a tfbus payload (bad magic byte)")
        if data[1] != WIRE_VERSION:
            raise WireVersionError(
                f"wire format version {data[1]}, this tfbus speaks {WIRE_VERSION}"
            )
        return self._decode_schema(bytes(data))

    def _decode_schema(self, data: bytes) -> Decoded:
        """:meth:`decode` by msgspec's schemas (its checks of the magic byte, version and
        size done): what the compiled decoder returns None for, and every payload without
        the compiled core.

        Raises: as :meth:`decode`.
        """
        view = memoryview(data)
        try:  # the fast path: a well-formed TFMessage, decoded by one typed schema
            env = self._tf_envelope_decoder.decode(view[2:])
        except Exception:  # anything else: the general path below, which says what is wrong
            pass
        else:
            return Decoded(env.sender, env.seq, _m.TFMessage(_from_wire(env.body)))
        try:
            sender, seq, tag, pos = read_head(data, 2)
            if not (0 < sender <= _INT64_MAX and 0 < seq <= _INT64_MAX):
                raise WireDecodeError(
                    f"sender {sender} / sequence number {seq} outside [1, {_INT64_MAX}]"
                )
            body = view[pos:]
            if tag == _TF_TAG:
                message: object = _m.TFMessage(_from_wire(self._tf_decoder.decode(body)))
            elif tag == _SCAN_TAG:
                message = _scan_from_wire(self._scan_decoder.decode(body))
            elif tag == _CLOUD_TAG:
                message = _cloud_from_wire(self._cloud_decoder.decode(body))
            else:
                check_depth(data, pos, self.limits.max_depth)
                if tag == _RAW_TAG:
                    message = self._raw_decoder.decode(body)
                else:
                    message = self._typed_decoder(tag)(body)
        except WireError:
            raise
        except msgspec.ValidationError as exc:
            if "of length <=" in str(exc):
                raise WireLimitError(str(exc)) from exc
            raise WireDecodeError(str(exc)) from exc
        except Exception as exc:  # msgspec.DecodeError, a dec_hook's ValueError, anything
            raise WireDecodeError(f"undecodable payload ({type(exc).__name__}: {exc})") from exc
        return Decoded(sender, seq, message)

    def _typed_decoder(self, tag: str) -> Callable[[bytes | memoryview], object]:
        dec = self._typed.get(tag)
        if dec is None:
            cls = _REGISTRY.get(tag)
            if cls is None:
                raise WireDecodeError(f"unknown message type tag {tag!r}")
            dec = msgspec.msgpack.Decoder(cls, dec_hook=_dec_hook).decode
            self._typed[tag] = dec
        return dec


def _payload(encode: Callable[[object], bytes], message: object, sender: int,
             seq: int) -> bytes:
    """The payload of ``message`` (see :meth:`WireCodec.encode`), msgpack by ``encode``.

    Raises:
        WireEncodeError: the message cannot be encoded.
    """
    if isinstance(message, _m.TFMessage):  # also a ROS 1 connection's subclass
        tag = _TF_TAG
        body: object = message.transforms
    elif type(message) is LaserScan:
        tag = _SCAN_TAG
        body = _scan_to_wire(message)
    elif type(message) is PointCloud2:
        tag = _CLOUD_TAG
        body = _cloud_to_wire(message)
    else:
        tag = _TAG_OF.get(type(message), _RAW_TAG)
        body = message
    try:
        return _HEADER + encode(_OutEnvelope(sender, seq, tag, body))
    except (TypeError, ValueError, OverflowError, NotImplementedError) as exc:
        raise WireEncodeError(
            f"cannot encode {type(message).__qualname__} for the wire: {exc}"
        ) from exc


def _tf_schema(limits: WireLimits) -> Any:
    """The msgspec type of a TFMessage body under ``limits``: every field typed (stamps as
    int64 nanoseconds >= 0, frame ids bounded), so msgspec never decodes a part of it
    generically and refuses a wrong shape at the first byte that does not fit."""
    frame_id = Annotated[str, msgspec.Meta(max_length=limits.max_frame_id_length)]
    header = msgspec.defstruct(
        "_WireHeader",
        [("stamp", Annotated[int, msgspec.Meta(ge=0, le=TIME_MAX_NS)]), ("frame_id", frame_id)],
        array_like=True,
        gc=False,
    )
    item: Any = msgspec.defstruct(
        "_WireTransformStamped",
        [("header", header), ("child_frame_id", frame_id), ("transform", _m.Transform)],
        array_like=True,
        gc=False,
    )
    return Annotated[tuple[item, ...], msgspec.Meta(max_length=limits.max_transforms)]


_SCAN_FLOATS: Final = (
    "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
    "range_min", "range_max",
)  # fmt: skip


def _scan_schema(limits: WireLimits) -> Any:
    """The msgspec type of a LaserScan body under ``limits`` (every field typed, arrays
    as ``bin`` of at most ``4 * limits.max_scan_beams`` bytes)."""
    beams = Annotated[bytes, msgspec.Meta(max_length=4 * limits.max_scan_beams)]
    return msgspec.defstruct(
        "_WireLaserScan",
        [
            ("stamp", Annotated[int, msgspec.Meta(ge=0, le=TIME_MAX_NS)]),
            ("frame_id", Annotated[str, msgspec.Meta(max_length=limits.max_frame_id_length)]),
            *((name, float) for name in _SCAN_FLOATS),
            ("ranges", beams),
            ("intensities", beams),
        ],
        array_like=True,
        gc=False,
    )


def _scan_to_wire(scan: LaserScan) -> tuple[object, ...]:
    """A LaserScan as its wire body (see the module's docstring)."""
    return (
        scan.header.stamp.ns,
        scan.header.frame_id,
        *(float(getattr(scan, name)) for name in _SCAN_FLOATS),
        np.ascontiguousarray(scan.ranges, dtype=_F32_LE).tobytes(),
        np.ascontiguousarray(scan.intensities, dtype=_F32_LE).tobytes(),
    )


def _beams(data: bytes, name: str) -> Any:
    if len(data) % 4:
        raise WireDecodeError(
            f"LaserScan.{name} of {len(data)} bytes is not a whole number of float32s"
        )
    return np.frombuffer(data, dtype=_F32_LE).astype(np.float32)  # a writable copy


def _scan_from_wire(body: Any) -> LaserScan:
    """The wire schema's LaserScan body as a :class:`~tfbus.sensor_msgs.LaserScan` (bounds
    and types already checked by the schema).

    Raises:
        WireDecodeError: a finite angle, time or range beyond float32's range (the type of
            ``LaserScan.msg``'s fields; tfbus writes float32 values, and casting a larger
            one made it infinite with a numpy overflow warning), naming the field.
    """
    for name in _SCAN_FLOATS:
        value = getattr(body, name)
        if abs(value) > _F32_MAX and value - value == 0.0:  # finite, past float32
            raise WireDecodeError(f"LaserScan.{name} {value!r} is outside float32's range")
    stamp = Time.__new__(Time)
    stamp._ns = body.stamp
    return LaserScan(
        _m.Header(stamp, body.frame_id),
        body.angle_min,
        body.angle_max,
        body.angle_increment,
        body.time_increment,
        body.scan_time,
        body.range_min,
        body.range_max,
        _beams(body.ranges, "ranges"),
        _beams(body.intensities, "intensities"),
    )


def _cloud_schema(limits: WireLimits) -> Any:
    """The msgspec type of a PointCloud2 body under ``limits`` (every field typed; counts
    and offsets uint32, datatypes uint8, as in ``PointField.msg``)."""
    name = Annotated[str, msgspec.Meta(max_length=limits.max_frame_id_length)]
    point_field = msgspec.defstruct(
        "_WirePointField",
        [("name", name), ("offset", _U32),
         ("datatype", Annotated[int, msgspec.Meta(ge=0, le=255)]), ("count", _U32)],
        array_like=True,
        gc=False,
    )
    return msgspec.defstruct(
        "_WirePointCloud2",
        [
            ("stamp", Annotated[int, msgspec.Meta(ge=0, le=TIME_MAX_NS)]),
            ("frame_id", name),
            ("height", _U32),
            ("width", _U32),
            ("fields", Annotated[list[point_field],  # type: ignore[valid-type]
                                 msgspec.Meta(max_length=limits.max_cloud_fields)]),
            ("is_bigendian", bool),
            ("point_step", _U32),
            ("row_step", _U32),
            ("data", bytes),
            ("is_dense", bool),
        ],
        array_like=True,
        gc=False,
    )


def _cloud_to_wire(cloud: PointCloud2) -> tuple[object, ...]:
    """A PointCloud2 as its wire body (see the module's docstring)."""
    return (
        cloud.header.stamp.ns,
        cloud.header.frame_id,
        int(cloud.height),
        int(cloud.width),
        [(f.name, int(f.offset), int(f.datatype), int(f.count)) for f in cloud.fields],
        bool(cloud.is_bigendian),
        int(cloud.point_step),
        int(cloud.row_step),
        bytes(cloud.data),
        bool(cloud.is_dense),
    )


def _cloud_from_wire(body: Any) -> PointCloud2:
    """The wire schema's PointCloud2 body as a :class:`~tfbus.sensor_msgs.PointCloud2`
    (types and ranges already checked by the schema)."""
    stamp = Time.__new__(Time)
    stamp._ns = body.stamp
    return PointCloud2(
        _m.Header(stamp, body.frame_id), body.height, body.width,
        [PointField(f.name, f.offset, f.datatype, f.count) for f in body.fields],
        body.is_bigendian, body.point_step, body.row_step, body.data, body.is_dense,
    )  # fmt: skip


_new = tuple.__new__
_TFMessage = _m.TFMessage
_TransformStamped = _m.TransformStamped
_Header = _m.Header


def _compiled_decoder() -> (
    Callable[[bytes, int, int, int, int, int], tuple[int, int, TFMessage] | None] | None
):
    """The compiled decoder of a TFMessage payload in the form tfbus writes it
    (``_cwire._tf_from_native``, where :func:`tfbus.codecs._compiled_wire` finds the
    compiled wire decoders); else None (msgspec's schema decodes every payload)."""
    wire = _compiled_wire()
    if wire is None:
        return None
    decode: Callable[[bytes, int, int, int, int, int], tuple[int, int, TFMessage] | None]
    decode = wire._tf_from_native
    return decode


_compiled_tf = _compiled_decoder()
"""The compiled TFMessage decoder (``None`` for anything but a TFMessage as tfbus writes
it, equal values otherwise: tested), where there is one."""


def _compiled_writer() -> Callable[[object, object, object, int, int], bytes | None] | None:
    """The compiled writer of a TFMessage payload of the common form
    (``_cwire._tf_to_native(transforms, sender, seq, MAGIC, WIRE_VERSION)``: the bytes
    msgspec writes, or None for anything else), where :func:`tfbus.codecs._compiled_wire`
    finds the compiled wire module; else None (msgspec writes every payload)."""
    wire = _compiled_wire()
    if wire is None:
        return None
    write: Callable[[object, object, object, int, int], bytes | None] = wire._tf_to_native
    return write


_compiled_tf_writer = _compiled_writer()
"""The compiled TFMessage writer (the bytes msgspec writes, or None: tested), where there
is one."""


def _compiled_clock_stamp() -> Callable[[bytes, int, int], int] | None:
    """The compiled reader of the stamp of a ``Clock`` payload in the form tfbus writes it
    (``_cwire._clock_stamp_native(payload, MAGIC, WIRE_VERSION)``: the stamp in int ns,
    or -1 for anything it does not read), where :func:`tfbus.codecs._compiled_wire` finds
    the compiled wire decoders; else None."""
    wire = _compiled_wire()
    if wire is None:
        return None
    read: Callable[[bytes, int, int], int] = wire._clock_stamp_native
    return read


def _from_wire(items: Any) -> tuple[_m.TransformStamped, ...]:
    """The wire schema's items as TransformStamped NamedTuples (the values are already
    checked: :class:`~tfbus.time.Time` is built without re-validating)."""
    out: list[_m.TransformStamped] = []
    append = out.append
    for item in items:
        header = item.header
        stamp = Time.__new__(Time)
        stamp._ns = header.stamp
        append(
            _new(
                _TransformStamped,
                (_new(_Header, (stamp, header.frame_id)), item.child_frame_id, item.transform),
            )
        )
    return tuple(out)


# -- the functions of every codec module ------------------------------------------------

MAX_TRANSFORMS: Final = WireLimits().max_transforms
"""Most transforms :func:`decode_tf` accepts by default (:class:`WireLimits`)."""
MAX_SCAN_BEAMS: Final = WireLimits().max_scan_beams
"""Most beams :func:`decode_scan` accepts in each array by default (:class:`WireLimits`)."""
ONE_SHOT_SENDER: Final = 1
"""The sender id of the payloads :func:`encode_tf`, :func:`encode_scan` and
:func:`encode_clock` write (a message outside any stream; its sequence number is 1)."""

_DECODERS_KEPT: Final = 8
_decoders: dict[WireLimits, WireCodec] = {}
"""Decoding codecs by limits (a few kept, built once each; msgspec's decoders keep no
state between calls, its encoders do: :func:`_one_shot` encodes with msgspec's stateless
``encode`` instead)."""


def _decoded(data: bytes | memoryview, limits: WireLimits, kind: type, name: str) -> Any:
    codec = _decoders.get(limits)
    if codec is None:
        if len(_decoders) >= _DECODERS_KEPT:
            _decoders.clear()
        codec = _decoders[limits] = WireCodec(limits)
    message = codec.decode(data).message
    if not isinstance(message, kind):
        raise WireDecodeError(f"a tfbus payload of {type(message).__name__}, expected {name}")
    return message


def _one_shot(message: object) -> bytes:
    """The payload of ``message`` from :data:`ONE_SHOT_SENDER`, sequence number 1."""
    return _payload(_encode, message, ONE_SHOT_SENDER, 1)


def _encode(value: object) -> bytes:
    return msgspec.msgpack.encode(value, enc_hook=_enc_hook)


def encode_tf(message: TFMessage | Sequence[TransformStamped]) -> bytes:
    """A TFMessage (or its transforms) as a tfbus wire payload (tag ``"tf"``, sender
    :data:`ONE_SHOT_SENDER`, sequence number 1).

    Raises:
        WireEncodeError: an element is not a TransformStamped of encodable fields.
    """
    if not isinstance(message, TFMessage):
        message = TFMessage(tuple(message))
    return _one_shot(message)


def decode_tf(data: bytes | memoryview, *, max_transforms: int = MAX_TRANSFORMS) -> TFMessage:
    """The TFMessage of a tfbus wire payload (its sender and number dropped).

    Raises:
        WireDecodeError: not a tfbus payload of a TFMessage (the message says why).
        WireVersionError: a payload of another format version.
        WireLimitError: more than ``max_transforms`` transforms, or another
            :class:`WireLimits` bound exceeded.
    """
    message: TFMessage = _decoded(
        data, WireLimits(max_transforms=max_transforms), TFMessage, "a TFMessage"
    )
    return message


def encode_scan(message: LaserScan) -> bytes:
    """A :class:`~tfbus.sensor_msgs.LaserScan` as a tfbus wire payload (tag
    ``"LaserScan"``, the arrays as float32s bit for bit).

    Raises:
        WireEncodeError: ``message`` is not a LaserScan, or a field cannot be encoded.
    """
    if type(message) is not LaserScan:
        raise WireEncodeError(f"expected a LaserScan, got {message!r:.100}")
    return _one_shot(message)


def decode_scan(data: bytes | memoryview, *, max_beams: int = MAX_SCAN_BEAMS) -> LaserScan:
    """The :class:`~tfbus.sensor_msgs.LaserScan` of a tfbus wire payload.

    Raises:
        WireDecodeError: not a tfbus payload of a LaserScan.
        WireVersionError: a payload of another format version.
        WireLimitError: an array of more than ``max_beams`` beams, or another
            :class:`WireLimits` bound exceeded.
    """
    scan: LaserScan = _decoded(
        data, WireLimits(max_scan_beams=max_beams), LaserScan, "a LaserScan"
    )
    return scan


def encode_clock(message: Clock) -> bytes:
    """A :class:`~tfbus.messages.Clock` as a tfbus wire payload (tag ``"Clock"``, the
    stamp in integer nanoseconds).

    Raises:
        WireEncodeError: ``message`` is not a Clock holding a :class:`~tfbus.time.Time`.
    """
    if not isinstance(message, Clock) or not isinstance(message.clock, Time):
        raise WireEncodeError(f"expected a Clock holding a Time, got {message!r:.100}")
    return _one_shot(message)


def decode_clock(data: bytes | memoryview) -> Clock:
    """The :class:`~tfbus.messages.Clock` of a tfbus wire payload.

    Raises:
        WireDecodeError: not a tfbus payload of a Clock.
        WireVersionError: a payload of another format version.
        WireLimitError: the payload exceeds a :class:`WireLimits` bound.
    """
    clock: Clock = _decoded(data, WireLimits(), Clock, "a Clock")
    return clock


# -- msgpack readers run before msgspec (the msgpack specification, "Formats") ----------

# type byte -> number of bytes of the whole item when it has a fixed size
_FIXED: Final[dict[int, int]] = {
    0xC0: 1, 0xC2: 1, 0xC3: 1,  # nil, false, true
    0xCA: 5, 0xCB: 9,  # float32, float64
    0xCC: 2, 0xCD: 3, 0xCE: 5, 0xCF: 9,  # uint8..64
    0xD0: 2, 0xD1: 3, 0xD2: 5, 0xD3: 9,  # int8..64
    0xD4: 3, 0xD5: 4, 0xD6: 6, 0xD7: 10, 0xD8: 18,  # fixext 1..16 (+ type byte)
}  # fmt: skip
# type byte -> (size of its big-endian length field, bytes after the payload's length)
_SIZED: Final[dict[int, tuple[int, int]]] = {
    0xC4: (1, 0), 0xC5: (2, 0), 0xC6: (4, 0),  # bin 8/16/32
    0xC7: (1, 1), 0xC8: (2, 1), 0xC9: (4, 1),  # ext 8/16/32 (+ type byte)
    0xD9: (1, 0), 0xDA: (2, 0), 0xDB: (4, 0),  # str 8/16/32
}  # fmt: skip
# type byte -> (size of its count field, items per counted entry)
_CONTAINERS: Final[dict[int, tuple[int, int]]] = {
    0xDC: (2, 1), 0xDD: (4, 1),  # array 16/32
    0xDE: (2, 2), 0xDF: (4, 2),  # map 16/32: key and value
}  # fmt: skip


# A run of one-byte items (fixints, nil, false, true): skipped in one regex step.
_ONE_BYTE_RUN: Final = re.compile(rb"[\x00-\x7f\xc0\xc2\xc3\xe0-\xff]+")


def _truncated() -> WireDecodeError:
    return WireDecodeError("truncated msgpack data")


def _read_int(data: bytes, pos: int) -> tuple[int, int]:
    """An integer at ``pos``: (value, position after it)."""
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if b <= 0x7F:
        return b, pos + 1
    if b >= 0xE0:
        return b - 0x100, pos + 1
    if 0xCC <= b <= 0xD3:
        size = 1 << ((b - 0xCC) & 3)
        end = pos + 1 + size
        if end > len(data):
            raise _truncated()
        return int.from_bytes(data[pos + 1 : end], "big", signed=b >= 0xD0), end
    raise WireDecodeError(f"expected a msgpack integer at byte {pos}, found 0x{b:02x}")


def _read_str(data: bytes, pos: int) -> tuple[str, int]:
    """A string at ``pos``: (value, position after it)."""
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if 0xA0 <= b <= 0xBF:
        start, length = pos + 1, b & 0x1F
    elif b in (0xD9, 0xDA, 0xDB):
        size = 1 << (b - 0xD9)
        start = pos + 1 + size
        length = int.from_bytes(data[pos + 1 : start], "big")
    else:
        raise WireDecodeError(f"expected a msgpack string at byte {pos}, found 0x{b:02x}")
    end = start + length
    if end > len(data):
        raise _truncated()
    try:
        return data[start:end].decode("utf-8"), end
    except UnicodeDecodeError as exc:
        raise WireDecodeError(f"invalid UTF-8 in a string at byte {pos}") from exc


def read_head(data: bytes, pos: int) -> tuple[int, int, str, int]:
    """Read ``[sender, seq, tag, ...`` at ``pos``: ``(sender, seq, tag, body_position)``.

    The envelope must be a msgpack array of exactly 4 items; the body is its last item
    and runs to the end of ``data``.

    Raises:
        WireDecodeError: not an array of 4, or a field of the wrong msgpack type.
    """
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if b == 0x94:
        pos += 1
    elif b in (0xDC, 0xDD):
        size = 2 if b == 0xDC else 4
        if int.from_bytes(data[pos + 1 : pos + 1 + size], "big") != 4:
            raise WireDecodeError("the envelope must be an array of 4 items")
        pos += 1 + size
    else:
        raise WireDecodeError("the envelope must be an array of 4 items")
    sender, pos = _read_int(data, pos)
    seq, pos = _read_int(data, pos)
    tag, pos = _read_str(data, pos)
    return sender, seq, tag, pos


def check_depth(data: bytes, pos: int, max_depth: int) -> int:
    """Walk the msgpack value at ``pos`` without building it; return the position after it.

    Containers (arrays, maps) nested more than ``max_depth`` deep are refused before any
    decoder recurses into them. Iterative: the walk itself never recurses. Cost: one
    step per item, bounded by ``len(data)`` (every item takes at least one byte).

    Raises:
        WireLimitError: nesting deeper than ``max_depth``.
        WireDecodeError: truncated data or the reserved byte ``0xc1``.
    """
    n = len(data)
    stack: list[int] = []  # items still to read in each enclosing container
    left = 1  # items still to read at the current level
    while True:
        while left == 0:
            if not stack:
                return pos
            left = stack.pop()
        if pos >= n:
            raise _truncated()
        b = data[pos]
        if b <= 0x7F or b >= 0xE0 or b in (0xC0, 0xC2, 0xC3):  # one-byte items: a run
            match = _ONE_BYTE_RUN.match(data, pos)
            assert match is not None
            taken = min(match.end() - pos, left)
            pos += taken
            left -= taken
            continue
        left -= 1
        count = 0
        if b <= 0x8F:  # fixmap
            count = (b & 0x0F) * 2
            pos += 1
        elif b <= 0x9F:  # fixarray
            count = b & 0x0F
            pos += 1
        elif b <= 0xBF:  # fixstr
            pos += 1 + (b & 0x1F)
            continue
        elif b in _FIXED:
            pos += _FIXED[b]
            continue
        elif b in _SIZED:
            size, extra = _SIZED[b]
            start = pos + 1 + size
            if start > n:
                raise _truncated()
            pos = start + extra + int.from_bytes(data[pos + 1 : start], "big")
            continue
        elif b in _CONTAINERS:
            size, per = _CONTAINERS[b]
            start = pos + 1 + size
            if start > n:
                raise _truncated()
            count = per * int.from_bytes(data[pos + 1 : start], "big")
            pos = start
        else:  # 0xc1: never used
            raise WireDecodeError(f"invalid msgpack byte 0x{b:02x} at byte {pos}")
        if count:
            stack.append(left)
            left = count
            if len(stack) > max_depth:
                raise WireLimitError(
                    f"msgpack values nested deeper than {max_depth} levels at byte {pos}"
                )
