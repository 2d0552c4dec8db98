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
* a registered name (``"TransformStamped"``, ``"PointStamped"``, ... or anything added with
  :func:`register_message_type`) -- that type, encoded field by field.
* ``""`` -- a plain msgpack value (None, bool, int, float, str, bytes, list, dict).

Decoding is defensive: a payload that is too large, not msgpack, of the wrong shape or
type, has more transforms than allowed or a frame id that is too long raises a
:class:`WireError` subclass, never anything else, so a receiver can count it and go on.
This module is synchronous and has no I/O (layer 0 style): it is unit-testable alone.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Final, NamedTuple

import msgspec

from tfbus import messages as _m
from tfbus.errors import (
    WireDecodeError,
    WireEncodeError,
    WireError,
    WireLimitError,
    WireVersionError,
)
from tfbus.time import Time

__all__ = [
    "MAGIC",
    "WIRE_VERSION",
    "Decoded",
    "WireCodec",
    "WireDecodeError",
    "WireEncodeError",
    "WireError",
    "WireLimitError",
    "WireLimits",
    "WireVersionError",
    "new_sender_id",
    "register_message_type",
]

MAGIC: Final = 0xB7
WIRE_VERSION: Final = 1
_HEADER: Final = bytes((MAGIC, WIRE_VERSION))
_TF_TAG: Final = "tf"
_RAW_TAG: Final = ""


@dataclass(frozen=True, slots=True)
class WireLimits:
    """Bounds enforced when decoding (a sender cannot make a receiver allocate wildly).

    Attributes:
        max_payload_bytes: largest accepted payload, bytes (default 16 MiB).
        max_transforms: most transforms in one TFMessage (default 100 000).
        max_frame_id_length: longest ``frame_id`` / ``child_frame_id``, characters
            (default 256).
    """

    max_payload_bytes: int = 16 * 1024 * 1024
    max_transforms: int = 100_000
    max_frame_id_length: int = 256


class Decoded(NamedTuple):
    """One decoded payload: who sent it, its per-topic sequence number, the message."""

    sender: int
    seq: int
    message: object


class _Envelope(msgspec.Struct, array_like=True, frozen=True):
    sender: int
    seq: int
    tag: str
    body: msgspec.Raw


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
        if type(obj) is not int or obj < 0:
            raise ValueError("a stamp must be a non-negative integer of nanoseconds")
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
    if name in (_TF_TAG, _RAW_TAG):
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
        self._env_decoder = msgspec.msgpack.Decoder(_Envelope)
        tf_type: Any = Annotated[
            tuple[_m.TransformStamped, ...],
            msgspec.Meta(max_length=self.limits.max_transforms),
        ]
        self._tf_decoder: msgspec.msgpack.Decoder[tuple[_m.TransformStamped, ...]] = (
            msgspec.msgpack.Decoder(tf_type, dec_hook=_dec_hook)
        )
        self._raw_decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder()
        self._typed: dict[str, Callable[[bytes | memoryview], object]] = {}

    # -- encoding -------------------------------------------------------------------

    def encode(self, message: object, *, sender: int, seq: int) -> bytes:
        """The payload for ``message`` from ``sender`` with sequence number ``seq``.

        Raises:
            WireEncodeError: if the message type is neither a TFMessage, a registered
                type nor a plain msgpack value, or a field cannot be encoded.
        """
        if type(message) is _m.TFMessage:
            tag = _TF_TAG
            body: object = message.transforms
        else:
            tag = _TAG_OF.get(type(message), _RAW_TAG)
            body = message
        try:
            return _HEADER + self._encoder.encode(_OutEnvelope(sender, seq, tag, body))
        except (TypeError, ValueError, OverflowError, NotImplementedError) as exc:
            raise WireEncodeError(
                f"cannot encode {type(message).__qualname__} for the wire: {exc}"
            ) from exc

    # -- decoding -------------------------------------------------------------------

    def decode(self, payload: bytes | bytearray | memoryview) -> Decoded:
        """Decode one payload.

        Raises:
            WireDecodeError: bad magic byte, bad msgpack, wrong shape or field type.
            WireVersionError: a tfbus payload of another format version.
            WireLimitError: payload too large, too many transforms, frame id too long.
        """
        n = len(payload)
        if n > self.limits.max_payload_bytes:
            raise WireLimitError(f"payload of {n} bytes exceeds {self.limits.max_payload_bytes}")
        if n < 2 or payload[0] != MAGIC:
            raise WireDecodeError("not a tfbus payload (bad magic byte)")
        if payload[1] != WIRE_VERSION:
            raise WireVersionError(
                f"wire format version {payload[1]}, this tfbus speaks {WIRE_VERSION}"
            )
        view = memoryview(payload)[2:]
        try:
            env = self._env_decoder.decode(view)
            tag = env.tag
            if tag == _TF_TAG:
                transforms = self._tf_decoder.decode(env.body)
                limit = self.limits.max_frame_id_length
                # A frame id longer than `limit` needs more than `limit` payload bytes.
                if n > limit:
                    for t in transforms:
                        if len(t.header.frame_id) > limit or len(t.child_frame_id) > limit:
                            raise WireLimitError(f"a frame id is longer than {limit} characters")
                message: object = _m.TFMessage(transforms)
            elif tag == _RAW_TAG:
                message = self._raw_decoder.decode(env.body)
            else:
                message = self._typed_decoder(tag)(env.body)
        except msgspec.ValidationError as exc:
            if "of length <=" in str(exc):
                raise WireLimitError(str(exc)) from exc
            raise WireDecodeError(str(exc)) from exc
        except (msgspec.DecodeError, TypeError, ValueError) as exc:
            if isinstance(exc, WireError):
                raise
            raise WireDecodeError(str(exc)) from exc
        return Decoded(env.sender, env.seq, message)

    def _typed_decoder(self, tag: str) -> Callable[[bytes | memoryview], object]:
        dec = self._typed.get(tag)
        if dec is None:
            cls = _REGISTRY.get(tag)
            if cls is None:
                raise WireDecodeError(f"unknown message type tag {tag!r}")
            dec = msgspec.msgpack.Decoder(cls, dec_hook=_dec_hook).decode
            self._typed[tag] = dec
        return dec
