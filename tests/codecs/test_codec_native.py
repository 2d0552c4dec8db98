"""tfbus's own wire (:mod:`tfbus.codecs.native`, the msgpack payload the Zenoh transport
carries): round trips, limits, malformed and hostile payloads, fuzzing. Only
``WireError`` subclasses ever come out of the decoder. No I/O."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

msgspec = pytest.importorskip("msgspec")

from tfbus.codecs import native as wire  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Point,
    PointStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time  # noqa: E402

HEAD = bytes([wire.MAGIC, wire.WIRE_VERSION])


def ts(child: str, ns: int, x: float = 0.0, parent: str = "world") -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


# -- wire format ------------------------------------------------------------------------


def test_wire_round_trip_tf_typed_and_raw() -> None:
    codec = wire.WireCodec()
    msg = TFMessage((ts("a", 1_700_000_000_123_456_789, 1.5), ts("b", 7)))
    out = codec.decode(codec.encode(msg, sender=42, seq=3))
    assert out == wire.Decoded(42, 3, msg)
    assert type(out.message) is TFMessage
    assert type(out.message.transforms[0].header.stamp) is Time
    point = PointStamped(Header(Time(2), "map"), Point(1.0, 2.0, 3.0))
    assert codec.decode(codec.encode(point, sender=1, seq=1)).message == point
    assert codec.decode(codec.encode({"k": [1, "x"]}, sender=1, seq=1)).message == {"k": [1, "x"]}
    with pytest.raises(wire.WireEncodeError):
        codec.encode(object(), sender=1, seq=1)


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        (b"", wire.WireDecodeError),
        (b"garbage bytes", wire.WireDecodeError),
        (bytes([wire.MAGIC, wire.WIRE_VERSION + 1]) + b"\x90", wire.WireVersionError),
        (bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\xc1", wire.WireDecodeError),
        (
            bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\x94\x01\x01\xa2tf\x91\x01",
            wire.WireDecodeError,
        ),
        (bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\x94\x01\x01\xa3zzz\x90", wire.WireDecodeError),
    ],
)
def test_wire_rejects_malformed(payload: bytes, error: type[Exception]) -> None:
    with pytest.raises(error):
        wire.WireCodec().decode(payload)


def test_wire_limits_and_negative_stamp() -> None:
    codec = wire.WireCodec(wire.WireLimits(max_transforms=2, max_frame_id_length=8))
    ok = codec.encode(TFMessage((ts("a", 1), ts("b", 2))), sender=1, seq=1)
    assert len(codec.decode(ok).message.transforms) == 2  # type: ignore[attr-defined]
    with pytest.raises(wire.WireLimitError):
        codec.decode(codec.encode(TFMessage((ts("a", 1),) * 3), sender=1, seq=1))
    with pytest.raises(wire.WireLimitError):
        codec.decode(codec.encode(TFMessage((ts("x" * 9, 1),)), sender=1, seq=1))
    small = wire.WireCodec(wire.WireLimits(max_payload_bytes=10))
    with pytest.raises(wire.WireLimitError):
        small.decode(ok)
    bad_stamp = ok.replace(b"\x01\xa5world", b"\xff\xa5world", 1)
    with pytest.raises(wire.WireDecodeError):
        codec.decode(bad_stamp)


# -- hostile payloads: deep nesting, huge stamps, forged sequence numbers ------------------


def _envelope(tag: bytes, body: bytes, sender: bytes = b"\x05", seq: bytes = b"\x01") -> bytes:
    return HEAD + b"\x94" + sender + seq + tag + body


@pytest.mark.parametrize(
    ("tag", "error"),
    [
        (b"\xa2tf", wire.WireDecodeError),  # the typed TFMessage schema refuses it at once
        (b"\xa0", wire.WireLimitError),  # plain msgpack: the nesting bound
        (b"\xacPointStamped", wire.WireLimitError),
    ],
)
def test_deep_nesting_is_a_decode_error_not_recursion(tag: bytes, error: type) -> None:
    """A ~1 KB msgpack payload nested 1 000 deep raised RecursionError
    out of the decoder; nesting is bounded before decoding."""
    payload = _envelope(tag, b"\x91" * 1000 + b"\xc0")
    assert len(payload) < 1100
    with pytest.raises(error):
        wire.WireCodec().decode(payload)
    # nested where a stamp is expected (decoded generically before the fix)
    stamp_bomb = _envelope(b"\xa2tf", b"\x91\x93\x92" + b"\x91" * 1000 + b"\xc0")
    with pytest.raises(wire.WireError):
        wire.WireCodec().decode(stamp_bomb)


def test_nesting_below_the_bound_still_decodes() -> None:
    """The bound leaves ordinary nested values alone."""
    codec = wire.WireCodec()
    value: Any = 1
    for _ in range(wire.WireLimits().max_depth - 1):
        value = [value]
    assert codec.decode(codec.encode(value, sender=1, seq=1)).message == value


def test_stamps_beyond_int64_are_rejected_at_decode() -> None:
    """Stamps >= 2**63 ns passed the decoder (and crashed --bus CLI
    commands later with OverflowError); they are malformed at decode time."""
    codec = wire.WireCodec()
    ok = codec.encode(TFMessage((ts("a", 7),)), sender=1, seq=1)
    assert b"\x07\xa5world" in ok
    for stamp in (b"\xcf\x80\x00\x00\x00\x00\x00\x00\x00", b"\xcf" + b"\xff" * 8):
        with pytest.raises(wire.WireDecodeError):
            codec.decode(ok.replace(b"\x07\xa5world", stamp + b"\xa5world", 1))
    top = ok.replace(b"\x07\xa5world", b"\xcf\x7f" + b"\xff" * 7 + b"\xa5world", 1)
    assert codec.decode(top).message.transforms[0].header.stamp.ns == 2**63 - 1  # type: ignore[attr-defined]
    point = codec.encode(PointStamped(Header(Time(2), "map"), Point()), sender=1, seq=1)
    stamp2 = Time(2).ns.to_bytes(4, "big")
    assert b"\xce" + stamp2 in point
    with pytest.raises(wire.WireDecodeError):
        codec.decode(point.replace(b"\xce" + stamp2, b"\xcf" + b"\xff" * 8, 1))


@pytest.mark.parametrize(
    ("sender", "seq"),
    [
        (b"\x00", b"\x01"),
        (b"\x05", b"\x00"),
        (b"\x05", b"\xff"),
        (b"\x05", b"\xd3" + b"\x80" + b"\x00" * 7),
        (b"\x05", b"\xcf" + b"\xff" * 8),
        (b"\xcf" + b"\xff" * 8, b"\x01"),
    ],
)
def test_negative_or_oversized_sequence_numbers_are_malformed(sender: bytes, seq: bytes) -> None:
    """Sender ids and sequence numbers are 1..2**63-1 (negative ones fed
    the `lost` counter); anything else is a decode error."""
    codec = wire.WireCodec()
    body = codec.encode(TFMessage((ts("a", 1),)), sender=5, seq=1)[8:]
    with pytest.raises(wire.WireDecodeError):
        codec.decode(_envelope(b"\xa2tf", body, sender=sender, seq=seq))
    assert codec.decode(_envelope(b"\xa2tf", body)).seq == 1


# -- fuzzing the wire decoder ------------------------------------------------------------

_msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**64), 2**64)
    | st.floats()
    | st.text(max_size=8)
    | st.binary(max_size=8),
    lambda children: (
        st.lists(children, max_size=4)
        | st.dictionaries(st.text(max_size=4) | st.integers(-5, 5), children, max_size=4)
    ),
    max_leaves=30,
)


def _packb(value: Any) -> bytes:
    try:
        return msgspec.msgpack.encode(value)
    except OverflowError:  # an int beyond msgpack's 64 bits
        return b"\xc0"


def _decode_or_wire_error(codec: wire.WireCodec, payload: bytes) -> None:
    try:
        decoded = codec.decode(payload)
    except wire.WireError:
        return
    assert 1 <= decoded.sender < 2**63 and 1 <= decoded.seq < 2**63
    if isinstance(decoded.message, TFMessage):
        for t in decoded.message.transforms:
            assert type(t) is TransformStamped and 0 <= t.header.stamp.ns < 2**63


_GOOD = wire.WireCodec().encode(
    TFMessage((ts("a", 1_700_000_000_000_000_000, 1.0), ts("b", 5))), sender=9, seq=4
)


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    data=st.one_of(
        st.binary(max_size=64),  # random bytes
        st.binary(max_size=64).map(lambda b: HEAD + b),  # random bytes after a valid header
        # structured: a well-formed envelope around any msgpack value, any tag
        st.tuples(
            st.integers(-(2**63), 2**64 - 1),
            st.integers(-(2**63), 2**64 - 1),
            st.sampled_from(["tf", "", "PointStamped", "TransformStamped", "nope"]),
            _msgpack_values,
        ).map(lambda t: HEAD + b"\x94" + _packb(t[0]) + _packb(t[1]) + _packb(t[2]) + _packb(t[3])),
        # mutations of a valid TFMessage payload: byte flips and truncations
        st.tuples(st.integers(0, len(_GOOD) - 1), st.integers(0, 255), st.booleans()).map(
            lambda t: (_GOOD[: t[0]] + bytes([t[1]]) + _GOOD[t[0] + 1 :]) if t[2] else _GOOD[: t[0]]
        ),
        # nesting bombs of every container byte
        st.tuples(
            st.sampled_from([b"\x91", b"\x81\x00", b"\xdc\x00\x01", b"\xdd\x00\x00\x00\x01"]),
            st.integers(1, 3000),
            st.sampled_from([b"\xa2tf", b"\xa0", b"\xa7Vector3"]),
        ).map(lambda t: HEAD + b"\x94\x01\x01" + t[2] + t[0] * t[1] + b"\xc0"),
    )
)
def test_fuzz_wire_decoder_raises_only_wire_errors(data: bytes) -> None:
    """Fuzzing: random and structured bytes give a decoded message or a
    WireError (the counted decode error), never anything else."""
    _decode_or_wire_error(wire.WireCodec(), data)


@settings(max_examples=200, deadline=None)
@given(_msgpack_values)
def test_depth_walk_agrees_with_msgpack(value: Any) -> None:
    """The pre-decode walk (the nesting bound) ends exactly where the value ends."""
    from tfbus.codecs.native import check_depth

    data = _packb(value)
    assert check_depth(data + b"\x01", 0, 1000) == len(data)


# -- sensor_msgs/LaserScan (scans between processes) -------------------------------------


def _scan(n: int = 5) -> Any:
    import numpy as np

    from tfbus.sensor_msgs import LaserScan

    ranges = np.array([0.5, float("nan"), float("inf"), 1e-3, 7.25][:n], dtype=np.float32)
    # a NaN with a payload: only a bit-for-bit copy keeps it
    ranges = np.concatenate([ranges, np.array([0x7FC01234], dtype=np.uint32).view(np.float32)])
    return LaserScan(header=Header(Time.from_ns(1_700_000_000_123_456_789), "base_laser"),
                     angle_min=-1.5, angle_max=1.5, angle_increment=0.1, time_increment=1e-4,
                     scan_time=0.1, range_min=0.05, range_max=30.0, ranges=ranges,
                     intensities=np.arange(len(ranges), dtype=np.float32) * 0.5)


def test_wire_laser_scan_round_trip_bit_for_bit() -> None:
    import numpy as np

    from tfbus.sensor_msgs import LaserScan

    codec = wire.WireCodec()
    scan = _scan()
    out = codec.decode(codec.encode(scan, sender=9, seq=4))
    assert (out.sender, out.seq) == (9, 4)
    got = out.message
    assert type(got) is LaserScan
    assert got.header == scan.header and type(got.header.stamp) is Time
    for name in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
                 "range_min", "range_max"):
        assert getattr(got, name) == getattr(scan, name), name
    for name in ("ranges", "intensities"):
        a, b = getattr(got, name), getattr(scan, name)
        assert a.dtype == np.float32 and a.shape == b.shape
        assert a.tobytes() == b.tobytes(), name
        a[0] = 1.0  # a writable copy of its own, not a view of the payload
    empty = codec.decode(codec.encode(LaserScan(), sender=1, seq=1)).message
    assert type(empty) is LaserScan and len(empty.ranges) == 0 and len(empty.intensities) == 0


def test_wire_laser_scan_limits_and_damage() -> None:
    codec = wire.WireCodec(wire.WireLimits(max_scan_beams=6, max_frame_id_length=10))
    ok = codec.encode(_scan(), sender=1, seq=1)  # 6 beams: at the bound
    assert len(codec.decode(ok).message.ranges) == 6  # type: ignore[attr-defined]
    with pytest.raises(wire.WireLimitError, match="length <= 24"):
        codec.decode(wire.WireCodec().encode(
            type(_scan())(ranges=[1.0] * 7), sender=1, seq=1))
    with pytest.raises(wire.WireLimitError):
        codec.decode(wire.WireCodec().encode(
            type(_scan())(header=Header(Time(1), "x" * 11)), sender=1, seq=1))
    # ranges of 23 bytes: not a whole number of float32s
    odd = ok.replace(b"\xc4\x18", b"\xc4\x17", 1)
    odd = odd[: odd.index(b"\xc4\x17") + 2 + 23] + odd[odd.index(b"\xc4\x17") + 2 + 24:]
    with pytest.raises(wire.WireDecodeError, match="ranges"):
        codec.decode(odd)
    for cut in (3, 10, len(ok) // 2, len(ok) - 1):
        with pytest.raises(wire.WireDecodeError):
            codec.decode(ok[:cut])
    wrong_type = ok.replace(b"\xaabase_laser", b"\x2a" + b"\xc0" * 10, 1)  # frame_id an int
    with pytest.raises(wire.WireDecodeError):
        codec.decode(wrong_type)
    with pytest.raises(ValueError, match="reserved"):
        wire.register_message_type(dict, "LaserScan")
