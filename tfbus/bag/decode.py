"""Choosing the decoder of a bag connection's serialized ``TFMessage`` payloads.

A ``TFMessage`` has had the same wire layout since ROS 1 Hydro, so when a connection's
type hash is the standard one (ROS 1 MD5 ``94810edd...``, ROS 2 RIHS01 ``e369d0f0...``)
its payloads are decoded by tfbus's codecs (:func:`tfbus.codecs.ros1.decode_tf`,
:func:`tfbus.codecs.cdr.decode_tf`), several times faster than a generic
deserializer; any other definition goes through a rosbags typestore built from the
definition stored in the bag (ROS 1 message text, ROS 2 ``.msg`` or IDL text).

The codecs raise :class:`~tfbus.errors.WireDecodeError` on a bad payload, rosbags' generic
path whatever it raises (``Exception`` subclasses); the reader turns either into
:class:`~tfbus.errors.BagReadError`.
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Sequence
from contextlib import suppress
from typing import TYPE_CHECKING, Final, NamedTuple

from tfbus.codecs import cdr, ros1
from tfbus.codecs.ros1 import TF_MD5SUM as ROS1_TF_MD5
from tfbus.codecs.ros1 import from_rosbags, tf_typestore
from tfbus.errors import SchemaParseError
from tfbus.messages import TransformStamped

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "ROS2_TF_RIHS01",
    "Decoder",
    "RawItem",
    "SchemaParseError",
    "Source",
    "cdr_decoder",
    "ros1_decoder",
]

#: ROS 2 RIHS01 type hash of tf2_msgs/msg/TFMessage.
ROS2_TF_RIHS01: Final = (
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
)

Decoder = Callable[[bytes | memoryview], Sequence[TransformStamped]]
"""Turns one serialized message into its transforms; raises on a malformed payload."""


def _decode_cdr(raw: bytes | memoryview) -> Sequence[TransformStamped]:
    """A ROS 2 (CDR) TFMessage's transforms (:func:`tfbus.codecs.cdr.decode_tf`).

    Raises:
        WireDecodeError: the payload is not a whole TFMessage.
    """
    return cdr.decode_tf(raw).transforms


def _decode_ros1(raw: bytes | memoryview) -> Sequence[TransformStamped]:
    """A ROS 1 TFMessage's transforms (:func:`tfbus.codecs.ros1.decode_tf`).

    Raises:
        WireDecodeError: the payload is not a whole TFMessage.
    """
    return ros1.decode_tf(raw).transforms


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
        return tf_typestore(ros1=ros1, msgtype=msgtype)
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
        return _decode_ros1
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
        return _decode_cdr
    store = _typestore(msgtype, msgdef, idl, False)
    if not digest:
        with suppress(Exception):
            digest = store.hash_rihs01(msgtype)
    if digest == ROS2_TF_RIHS01:
        return _decode_cdr

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
