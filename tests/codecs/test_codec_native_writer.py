"""The compiled writer of tfbus's own wire (``tfbus.codecs._cwire._tf_to_native``, what
``WireCodec.encode`` tries first for a TFMessage with the compiled core): on the common
form (the message classes themselves, ``str`` ids, ``float`` values, a ``Time`` stamp, an
``int`` sender and sequence number) the bytes msgspec writes for the same envelope, byte
for byte, at every boundary of msgpack's int, str and array forms; on anything else None,
so that msgspec writes it or ``WireEncodeError`` names what cannot be written. No I/O."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

msgspec = pytest.importorskip("msgspec")

from tfbus.codecs import native as wire  # noqa: E402
from tfbus.errors import WireEncodeError  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import TIME_MAX_NS, Time  # noqa: E402

writer = wire._compiled_tf_writer
pytestmark = pytest.mark.skipif(
    writer is None, reason="the compiled core is not built here (pure-Python install)"
)
PROPERTY = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
_MSGSPEC = msgspec.msgpack.Encoder(enc_hook=wire._enc_hook)


def msgspec_bytes(transforms: Any, sender: int, seq: int) -> bytes:
    """What msgspec writes for the envelope (``WireCodec.encode`` with no compiled
    writer)."""
    return wire._HEADER + _MSGSPEC.encode(wire._OutEnvelope(sender, seq, wire._TF_TAG, transforms))


def written(transforms: Any, sender: int, seq: int) -> bytes | None:
    assert writer is not None
    return writer(transforms, sender, seq, wire.MAGIC, wire.WIRE_VERSION)


def _ts(parent: str, child: str, ns: int = 5, values: tuple[Any, ...] = (
        1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8)) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(*values[:3]), Quaternion(*values[3:])))


# ids across msgpack's str forms (fixstr < 32 bytes, str 8 < 256, str 16 < 65536, str 32),
# counted in UTF-8 bytes (two- to four-byte characters included)
ids = st.text(max_size=40) | st.sampled_from(
    ["", "a" * 31, "a" * 32, "é" * 16, "a" * 255, "a" * 256, "😀" * 64]
)
floats = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [0.0, -0.0, math.nan, -math.nan, 5e-324,
     struct.unpack("<d", b"\x01\x00\x00\x00\x00\x00\xf8\x7f")[0]]
)
# unsigned ints across msgpack's forms (fixint < 128, uint 8, 16, 32, 64)
edges = [0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, 2**63 - 1]
stamps = st.integers(0, TIME_MAX_NS) | st.sampled_from(edges)
numbers = st.integers(0, 2**64 - 1) | st.sampled_from([*edges, 2**64 - 1])


@st.composite
def transform_lists(draw: st.DrawFn) -> list[TransformStamped]:
    out = []
    for _ in range(draw(st.integers(0, 5))):
        values = tuple(draw(floats) for _ in range(7))
        out.append(_ts(draw(ids), draw(ids), draw(stamps), values))
    return out


@PROPERTY
@given(transforms=transform_lists(), sender=numbers, seq=numbers, as_tuple=st.booleans())
@example(transforms=[], sender=1, seq=1, as_tuple=True)
def test_the_common_form_is_written_as_msgspec_writes_it(
    transforms: list[TransformStamped], sender: int, seq: int, as_tuple: bool
) -> None:
    items: Any = tuple(transforms) if as_tuple else transforms
    expected = msgspec_bytes(items, sender, seq)
    assert written(items, sender, seq) == expected
    if as_tuple:  # the codec's own path, and the payload decodes back to the values
        codec = wire.WireCodec()
        assert codec.encode(TFMessage(items), sender=sender, seq=seq) == expected
        if 0 < sender < 2**63 and 0 < seq < 2**63:  # what the wire carries
            roomy = wire.WireCodec(wire.WireLimits(max_frame_id_length=1 << 20))
            back = roomy._decode_schema(expected)
            assert (back.sender, back.seq) == (sender, seq)
            assert [struct.pack("<7d", *t.transform.translation, *t.transform.rotation)
                    for t in back.message.transforms] == [
                struct.pack("<7d", *t.transform.translation, *t.transform.rotation)
                for t in items]


@pytest.mark.parametrize("length", [65535, 65536])
def test_the_longest_str_forms(length: int) -> None:
    """str 16 up to 65535 bytes, str 32 from there (the property test's ids stay
    shorter)."""
    items = (_ts("a" * length, "é" * length),)
    assert written(items, 3, 4) == msgspec_bytes(items, 3, 4)


@pytest.mark.parametrize("n", [15, 16, 65535, 65536])
def test_array_lengths_across_msgpack_forms(n: int) -> None:
    """fixarray below 16, array 16 below 65536, array 32 from there."""
    items = tuple(_ts("map", "a", 7) for _ in range(n))
    assert written(items, 3, 4) == msgspec_bytes(items, 3, 4)


def test_anything_else_is_handed_back_to_msgspec() -> None:
    """What the C writer does not write is None from it; ``WireCodec.encode`` then has
    msgspec write it (the same bytes as before there was a C writer), or raises
    ``WireEncodeError`` naming what cannot be written."""
    import numpy as np

    good = _ts("map", "a")
    assert written([good], 1, 1) == msgspec_bytes([good], 1, 1)

    class _Sub(TransformStamped):
        pass

    class _Later(Time):
        pass

    class _SubMessage(TFMessage):
        pass

    later = _Later.__new__(_Later)
    later._ns = 9
    odd = []  # Time objects holding what Time never makes: msgspec writes them as held
    for held in (1.5, -1, 2**63, 2**64):
        stamp = Time.__new__(Time)
        stamp._ns = held
        odd.append([TransformStamped(Header(stamp, "map"), "e", good.transform)])
    others: list[Any] = [
        [good, _ts("map", "b", 5, (0, 0, 0, 0, 0, 0, 1))],  # int values
        [_ts("map", "c", 5, (np.float64(0.5), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))],
        [_Sub(*good)],
        [TransformStamped(Header(later, "map"), "d", good.transform)],
        *odd,
        iter([good]),
        {"a": good}.values(),
    ]
    codec = wire.WireCodec()
    for items in others:
        assert written(items, 1, 1) is None, items
    for items in others[:-2]:  # as msgspec writes them, or refuses (a numpy float)
        message = TFMessage(tuple(items))
        try:
            expected: bytes | type[Exception] = msgspec_bytes(tuple(items), 1, 1)
        except (TypeError, ValueError, OverflowError, NotImplementedError):  # _payload's
            expected = WireEncodeError
        try:
            got: bytes | type[Exception] = codec.encode(message, sender=1, seq=1)
        except WireEncodeError as exc:
            got = type(exc)
        assert got == expected, items
    sub = _SubMessage((good,))  # a subclass (a ROS 1 connection's): msgspec writes it
    assert codec.encode(sub, sender=1, seq=1) == msgspec_bytes((good,), 1, 1)
    for sender, seq in ((True, 1), (1, -1), (-1, 1), (2**64, 1), (1, 2**64), (1.0, 1)):
        assert written([good], sender, seq) is None, (sender, seq)
    with pytest.raises(WireEncodeError):
        codec.encode(TFMessage((good,)), sender=2**64, seq=1)
    surrogate = [_ts("map", "\udc80")]
    assert written(surrogate, 1, 1) is None
    with pytest.raises(WireEncodeError, match="cannot encode TFMessage"):
        codec.encode(TFMessage(tuple(surrogate)), sender=1, seq=1)
