"""The compiled decoder of tfbus's own wire (``tfbus.codecs._cwire._tf_from_native``, what
``WireCodec.decode`` tries first with the compiled core): on a TFMessage written as tfbus
writes it, the values msgspec's schema decodes (``WireCodec._decode_schema``), bit for bit
and of the same types; on anything else None, so that the schema decodes it or names what
is wrong. Encodings another msgpack writer may choose (wider array or str headers, an
integer or float 32 for a float, a signed integer for a stamp) are checked against the
schema by hand-built payloads. No I/O."""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import Any

import pytest
import refill_laws
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

msgspec = pytest.importorskip("msgspec")

from tfbus.codecs import native as wire  # noqa: E402
from tfbus.errors import WireError, WireLimitError  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import TIME_MAX_NS, Time  # noqa: E402

compiled = wire._compiled_tf
pytestmark = pytest.mark.skipif(
    compiled is None, reason="the compiled core is not built here (pure-Python install)"
)
HEAD = bytes([wire.MAGIC, wire.WIRE_VERSION])
PROPERTY = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
LIMITS = wire.WireLimits()


def _exact(decoded: Any) -> tuple[Any, ...]:
    """A Decoded as comparable values: types named, every float by its bits (NaN payloads
    and -0.0 told apart)."""
    sender, seq, message = decoded
    rows = []
    for t in message.transforms:
        tr, rot = t.transform.translation, t.transform.rotation
        floats = (*tr, *rot)
        rows.append((
            type(t), type(t.header), type(t.header.stamp), type(t.transform), type(tr),
            type(rot), tuple(type(f) for f in floats), t.header.stamp.ns,
            t.header.frame_id, t.child_frame_id, struct.pack("<7d", *floats),
        ))
    return sender, seq, type(message), type(message.transforms), rows


def _fast(payload: bytes, limits: wire.WireLimits = LIMITS) -> Any:
    """What the compiled decoder makes of ``payload`` under ``limits``."""
    assert compiled is not None
    return compiled(payload, limits.max_payload_bytes, limits.max_transforms,
                    limits.max_frame_id_length, wire.MAGIC, wire.WIRE_VERSION)


def _both(codec: wire.WireCodec, payload: bytes) -> tuple[Any, Any]:
    """(what the compiled decoder returns, what the schema decodes or the WireError type)."""
    fast = _fast(payload, codec.limits)
    try:
        schema: Any = codec._decode_schema(payload)
    except WireError as exc:
        schema = type(exc)
    return fast, schema


def _ts(parent: str, child: str) -> TransformStamped:
    return TransformStamped(Header(Time(3, 4), parent), child,
                            Transform(Vector3(1.0, 2.0, 3.0), Quaternion(0.0, 0.0, 0.6, 0.8)))


frame_ids = st.text(min_size=1, max_size=12).filter(lambda s: not s.startswith("/"))
floats = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [0.0, -0.0, math.nan, -math.nan, struct.unpack("<d", b"\x01\x00\x00\x00\x00\x00\xf8\x7f")[0]]
)
stamps = st.integers(0, TIME_MAX_NS) | st.sampled_from([0, 1, 127, 128, 2**32, TIME_MAX_NS])


@st.composite
def tf_messages(draw: st.DrawFn) -> TFMessage:
    n = draw(st.integers(0, 6))
    shared = draw(stamps)
    out = []
    for _ in range(n):
        stamp = shared if draw(st.booleans()) else draw(stamps)
        values = [draw(floats) for _ in range(7)]
        out.append(TransformStamped(
            Header(Time.from_ns(stamp), draw(frame_ids)), draw(frame_ids),
            Transform(Vector3(*values[:3]), Quaternion(*values[3:])),
        ))
    return TFMessage(tuple(out))


@PROPERTY
@given(message=tf_messages(), sender=st.integers(1, 2**63 - 1), seq=st.integers(1, 2**63 - 1))
@example(message=TFMessage(()), sender=1, seq=1)
def test_what_tfbus_writes_decodes_to_the_schema_values(
    message: TFMessage, sender: int, seq: int
) -> None:
    codec = wire.WireCodec()
    payload = codec.encode(message, sender=sender, seq=seq)
    fast, schema = _both(codec, payload)
    assert fast is not None
    assert _exact(fast) == _exact(schema)
    # decode() is the compiled path here, twice (the ids cached by position the second
    # time) and from a bytearray or a memoryview alike
    for again in (payload, payload, bytearray(payload), memoryview(payload)):
        assert _exact(codec.decode(again)) == _exact(schema)


@PROPERTY
@given(data=st.data())
def test_damaged_payloads_decode_as_the_schema_does_or_are_left_to_it(
    data: st.DataObject,
) -> None:
    codec = wire.WireCodec()
    payload = bytearray(codec.encode(data.draw(tf_messages()), sender=3, seq=9))
    for _ in range(data.draw(st.integers(1, 3))):
        kind = data.draw(st.sampled_from(["flip", "cut", "extend", "set"]))
        if kind == "flip" and len(payload) > 2:
            i = data.draw(st.integers(2, len(payload) - 1))
            payload[i] ^= 1 << data.draw(st.integers(0, 7))
        elif kind == "cut":
            del payload[data.draw(st.integers(2, len(payload))):]
        elif kind == "extend":
            payload += data.draw(st.binary(min_size=1, max_size=8))
        elif len(payload) > 2:
            payload[data.draw(st.integers(2, len(payload) - 1))] = data.draw(st.integers(0, 255))
    fast, schema = _both(codec, bytes(payload))
    if fast is not None:
        assert isinstance(schema, tuple), schema
        assert _exact(fast) == _exact(schema)


def _item(stamp: bytes = b"\x05", frame: bytes = b"\xa1a", child: bytes = b"\xa1b",
          vec: bytes | None = None, rot: bytes | None = None) -> bytes:
    f64 = b"\xcb" + struct.pack(">d", 0.5)
    vec = b"\x93" + f64 * 3 if vec is None else vec
    rot = b"\x94" + f64 * 3 + b"\xcb" + struct.pack(">d", 1.0) if rot is None else rot
    return b"\x93\x92" + stamp + frame + child + b"\x92" + vec + rot


def _payload(items: bytes, count: bytes = b"\x91", tag: bytes = b"\xa2tf",
             sender: bytes = b"\x01", seq: bytes = b"\x02", head: bytes = b"\x94") -> bytes:
    return HEAD + head + sender + seq + tag + count + items


def test_the_hand_built_plain_payload_is_decoded_in_c() -> None:
    fast, schema = _both(wire.WireCodec(), _payload(_item()))
    assert fast is not None and _exact(fast) == _exact(schema)
    assert fast[2].transforms[0].transform.rotation == Quaternion(0.5, 0.5, 0.5, 1.0)


@pytest.mark.parametrize(
    "payload",
    [
        pytest.param(_payload(_item(), head=b"\xdc\x00\x04"), id="array 16 envelope"),
        pytest.param(_payload(_item(), count=b"\xdd\x00\x00\x00\x01"), id="array 32 body"),
        pytest.param(_payload(_item(), sender=b"\xcf" + (7).to_bytes(8, "big")),
                     id="uint 64 sender"),
        pytest.param(_payload(_item(), seq=b"\xd3" + (9).to_bytes(8, "big")), id="int 64 seq"),
        pytest.param(_payload(_item(stamp=b"\xd0\x05")), id="int 8 stamp"),
        pytest.param(_payload(_item(stamp=b"\xcf" + (2**63 - 1).to_bytes(8, "big"))),
                     id="largest stamp"),
        pytest.param(_payload(_item(frame=b"\xd9\x01a")), id="str 8 frame id"),
        pytest.param(_payload(_item(child=b"\xdb\x00\x00\x00\x01b")), id="str 32 child id"),
        pytest.param(_payload(_item(vec=b"\xdc\x00\x03" + (b"\xcb" + bytes(8)) * 3)),
                     id="array 16 translation"),
    ],
)
def test_other_writers_headers_decode_as_the_schema_does(payload: bytes) -> None:
    fast, schema = _both(wire.WireCodec(), payload)
    assert isinstance(schema, tuple)
    assert fast is not None and _exact(fast) == _exact(schema)


@pytest.mark.parametrize(
    "payload",
    [
        pytest.param(_payload(_item(vec=b"\x93\x01\x02\x03")), id="integers for floats"),
        pytest.param(_payload(_item(vec=b"\x93" + (b"\xca" + struct.pack(">f", 0.5)) * 3)),
                     id="float 32s"),
        pytest.param(_payload(_item(), tag=b"\xd9\x02tf"), id="str 8 tag"),
        pytest.param(_payload(_item(stamp=b"\xff")), id="negative stamp"),
        pytest.param(_payload(_item(stamp=b"\xcf" + (2**63).to_bytes(8, "big"))),
                     id="stamp of 2**63"),
        pytest.param(_payload(_item(), sender=b"\x00"), id="sender 0"),
        pytest.param(_payload(_item(), seq=b"\xcf" + (2**63).to_bytes(8, "big")),
                     id="seq of 2**63"),
        pytest.param(_payload(_item(frame=b"\xa2\xc3\x28")), id="frame id not UTF-8"),
        pytest.param(_payload(_item(frame=b"\xc4\x01a")), id="bin frame id"),
        pytest.param(_payload(_item() + b"\x00"), id="a byte left over"),
        pytest.param(_payload(_item() * 2), id="fewer transforms counted than sent"),
        pytest.param(_payload(_item(), count=b"\x92"), id="more transforms counted than sent"),
        pytest.param(_payload(_item(), head=b"\x95") + b"\x00", id="five envelope fields"),
        pytest.param(_payload(_item(vec=b"\x92" + (b"\xcb" + bytes(8)) * 2)),
                     id="two coordinates"),
        pytest.param(_payload(_item(), tag=b"\xa2tg"), id="another tag"),
        pytest.param(_payload(_item())[:-3], id="cut short"),
    ],
)
def test_anything_else_is_left_to_the_schema(payload: bytes) -> None:
    codec = wire.WireCodec()
    fast, schema = _both(codec, payload)
    assert fast is None
    # and decode() answers what the schema answers
    if isinstance(schema, tuple):
        assert _exact(codec.decode(payload)) == _exact(schema)
    else:
        with pytest.raises(schema):
            codec.decode(payload)


def test_the_limits_are_the_codecs() -> None:
    limits = wire.WireLimits(max_transforms=2, max_frame_id_length=3)
    codec = wire.WireCodec(limits)
    at = codec.encode(TFMessage((_ts("abc", "ü12"), _ts("abc", "d"))), sender=1, seq=1)
    fast, schema = _both(codec, at)
    assert fast is not None and _exact(fast) == _exact(schema)
    for over in (
        codec.encode(TFMessage((_ts("abc", "d"),) * 3), sender=1, seq=1),
        codec.encode(TFMessage((_ts("abcd", "e"),)), sender=1, seq=1),
        codec.encode(TFMessage((_ts("a", "ü123"),)), sender=1, seq=1),
    ):
        fast, schema = _both(codec, over)
        assert fast is None and schema is WireLimitError
        with pytest.raises(WireLimitError):
            codec.decode(over)


def test_a_count_the_payload_cannot_hold_allocates_nothing() -> None:
    huge = _payload(_item(), count=b"\xdd\xff\xff\xff\xff")
    fast, schema = _both(wire.WireCodec(), huge)
    assert fast is None and isinstance(schema, type) and issubclass(schema, WireError)


def test_an_ascii_id_seen_at_the_same_position_is_the_same_str() -> None:
    codec = wire.WireCodec()
    message = TFMessage((_ts("map", "odom"), _ts("odom", "bäse")))
    first = codec.decode(codec.encode(message, sender=1, seq=1)).message.transforms
    second = codec.decode(codec.encode(message, sender=1, seq=2)).message.transforms
    assert second[0].header.frame_id is first[0].header.frame_id
    assert second[0].child_frame_id is first[0].child_frame_id
    assert second[1].child_frame_id == "bäse"  # not ASCII: decoded again, equal
    other = codec.decode(codec.encode(TFMessage((_ts("world", "odom"),)), sender=1, seq=3))
    assert other.message.transforms[0].header.frame_id == "world"



def _moving(codec: wire.WireCodec, *values: tuple[float, ...], stamp: int = 1,
            seq: int = 1) -> tuple[TransformStamped, ...]:
    """The compiled decode of a tfbus TFMessage of ``map -> c<k>`` transforms of 7 values
    each (its Decoded's transforms)."""
    message = TFMessage(tuple(
        TransformStamped(Header(Time.from_ns(stamp), "map"), f"c{k}",
                         Transform(Vector3(*v[:3]), Quaternion(*v[3:])))
        for k, v in enumerate(values)))
    payload = codec.encode(message, sender=1, seq=seq)
    decoded = _fast(payload)
    assert decoded is not None
    assert _exact(decoded) == _exact(codec._decode_schema(payload))
    transforms: tuple[TransformStamped, ...] = decoded[2].transforms
    return transforms


def test_repeated_values_are_the_earlier_transforms_and_changed_bytes_are_new() -> None:
    """As the ROS 1 decoder: a transform whose 7 values are byte for byte those at the
    same position of the last message is that message's Transform; one with only the
    translation (or the rotation) equal shares that part; other bytes (-0.0 after 0.0
    included) give a new value."""
    codec = wire.WireCodec()
    one = (1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0)
    two = (4.0, 5.0, 6.0, 0.0, 0.0, 0.6, 0.8)
    first = _moving(codec, one, two, one)
    again = _moving(codec, one, two, one, stamp=2, seq=2)
    assert [a.transform is f.transform for a, f in zip(again, first, strict=True)] == [True] * 3
    assert again[0].header.stamp.ns == 2  # the stamps are read anew
    moved = _moving(codec, (1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8),
                    (7.0, 5.0, 6.0, 0.0, 0.0, 0.6, 0.8), two, seq=3)
    assert moved[0].transform.translation is again[0].transform.translation
    assert moved[0].transform.rotation == Quaternion(0.0, 0.0, 0.6, 0.8)
    assert moved[1].transform.rotation is again[1].transform.rotation
    assert moved[1].transform.translation == Vector3(7.0, 5.0, 6.0)
    assert moved[2].transform == Transform(Vector3(*two[:3]), Quaternion(*two[3:]))
    signed = _moving(codec, (-0.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8), seq=4)
    assert struct.pack("<d", signed[0].transform.translation.x) == struct.pack("<d", -0.0)


def test_the_two_wires_keep_their_own_positions() -> None:
    """A process may follow tfbus's wire and ROS 1 at once: each wire's position 0 gives
    its own last values, whatever the other decoded in between."""
    from tfbus.codecs import ros1

    codec, tf_codec = wire.WireCodec(), ros1.TFCodec()
    here = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    there = TransformStamped(Header(Time(1, 0), "map"), "c0",
                             Transform(Vector3(9.0, 0.0, 0.0), Quaternion()))
    native_first = _moving(codec, here)
    ros1_first = ros1.decode_tf(tf_codec.encode([there])).transforms
    native_again = _moving(codec, here, seq=2)
    ros1_again = ros1.decode_tf(tf_codec.encode([there])).transforms
    assert native_again[0].transform is native_first[0].transform
    assert ros1_again[0].transform == there.transform
    if ros1._compiled_ros1 is not None:
        assert ros1_again[0].transform is ros1_first[0].transform


def _reuses() -> bool:
    from tfbus.codecs import _cwire

    return bool(_cwire._REUSES)


def _decode(values: Sequence[tuple[float, ...]], stamp: int) -> tuple[TransformStamped, ...]:
    """:func:`_moving` as :mod:`refill_laws` calls it (stamp ``stamp`` ns)."""
    return _moving(wire.WireCodec(), *values, stamp=stamp, seq=stamp)


def test_a_message_nobody_holds_is_refilled_and_what_is_held_never_changes() -> None:
    """As the ROS 1 decoder: the objects of the message decoded two messages earlier that
    nothing references any more are refilled in place with the new values; a message, a
    transform, a Transform, a Vector3, a Quaternion or a float a user still holds keeps
    its values, and a new object takes its place."""
    refill_laws.check_refilled_and_held(_decode, _reuses())


@PROPERTY
@given(refill_laws.steps((0.0, -0.0, 1.0, 2.5, math.nan)))
def test_refilling_never_changes_what_is_held_and_decodes_as_the_schema(
    steps: list[refill_laws.Step],
) -> None:
    """Messages of 0-4 transforms whose values repeat or change at random; after each
    decode some of what it gave is kept (the transforms, a transform, a Transform, a
    Vector3, a Quaternion or a float) and the rest dropped. Every decode equals the
    schema's, bit for bit (:func:`_moving`), and nothing kept ever changes."""
    refill_laws.check_nothing_held_changes(_decode, steps)


def test_what_the_checks_refuse_is_left_to_them() -> None:
    """A payload over the size limit, too short, or of another magic byte or version is
    None from the compiled decoder, and ``decode`` names it as before."""
    from tfbus.errors import WireDecodeError, WireVersionError

    good = _payload(_item())
    small = wire.WireCodec(wire.WireLimits(max_payload_bytes=len(good) - 1))
    cases: list[tuple[wire.WireCodec, bytes, type[WireError]]] = [
        (small, good, WireLimitError),
        (wire.WireCodec(), good[:1], WireDecodeError),
        (wire.WireCodec(), b"\x00" + good[1:], WireDecodeError),
        (wire.WireCodec(), good[:1] + bytes([wire.WIRE_VERSION + 1]) + good[2:], WireVersionError),
    ]
    for codec, payload, error in cases:
        assert _fast(payload, codec.limits) is None
        with pytest.raises(error):
            codec.decode(payload)
        with pytest.raises(error):
            codec.decode(memoryview(payload))
    at_limit = wire.WireCodec(wire.WireLimits(max_payload_bytes=len(good)))
    assert at_limit.decode(good).message == wire.WireCodec().decode(good).message
