"""The ROS 1 TFMessage decoders agree: the compiled one (objects built in C,
``tfbus.codecs._cwire._tf_from_ros1``, what ``decode_tf`` uses with the compiled core), the
struct one (``decode_ros1_struct``, the pure-Python path) and rosbags' generic
deserialiser; a short payload and a bad UTF-8 id fail alike (the codec's one error:
``WireDecodeError``)."""

from __future__ import annotations

import struct
from collections.abc import Sequence

import pytest
import refill_laws
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from tfbus.codecs import ros1 as dec
from tfbus.core import COMPILED
from tfbus.errors import WireDecodeError

pytest.importorskip("rosbags")
from tfbus.codecs.ros1 import TFCodec  # needs rosbags (checked above)

pytestmark = pytest.mark.skipif(
    dec._compiled_ros1 is None, reason="no compiled ROS 1 decoder (pure-Python core)"
)

_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
_ids = st.sampled_from(["", "base_link", "odom", "ü", "a" * 40, "bench_7"])
_CODEC = TFCodec()
"""One codec for every example: a ``TFCodec`` holds only its rosbags typestore, which
compiles its (de)serialisers on first use (half a second each time a codec is made)."""


def test_decode_ros1_uses_the_compiled_decoder() -> None:
    assert COMPILED and dec._compiled_ros1 is not None
    raw = TFCodec().encode([_ts("a", "b", 3, (1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0))])
    assert dec.decode_tf(raw) == TFMessage(tuple(dec._compiled_ros1(raw)))


def _ts(parent: str, child: str, ns: int, v: tuple[float, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(*v[:3]), Quaternion(*v[3:]))
    )


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            _ids,
            _ids,
            st.sampled_from([0, 1, 10**9 - 1, 1_700_000_000_123_456_789, (2**31 - 1) * 10**9]),
            st.tuples(*[_finite] * 7),
        ),
        max_size=30,
    ),
    st.binary(max_size=5),
)
def test_compiled_struct_and_rosbags_agree(
    items: list[tuple[str, str, int, tuple[float, ...]]], trailing: bytes
) -> None:
    codec = _CODEC
    raw = codec.encode(_ts(p, c, ns, v) for p, c, ns, v in items)
    assert dec._compiled_ros1 is not None
    got = dec._compiled_ros1(raw + trailing)
    assert got == dec.decode_ros1_struct(raw + trailing) == codec.decode_generic(raw)
    # Bit for bit (== on floats would take -0.0 for 0.0).
    assert [struct.pack("<7d", *t.transform.translation, *t.transform.rotation) for t in got] == [
        struct.pack("<7d", *v) for *_, v in items
    ]
    assert dec._compiled_ros1(memoryview(raw)) == got


def test_consecutive_equal_headers_share_one_header() -> None:
    raw = TFCodec().encode(
        [_ts("base_link", f"c{i}", 5, (0, 0, 0, 0, 0, 0, 1)) for i in range(3)]
        + [_ts("base_link", "d", 6, (0, 0, 0, 0, 0, 0, 1))]
    )
    assert dec._compiled_ros1 is not None
    out = dec._compiled_ros1(raw)
    assert out[0].header is out[1].header is out[2].header
    assert out[3].header is not out[2].header and out[3].header.stamp.ns == 6


def test_short_or_bad_payloads_fail_alike() -> None:
    raw = TFCodec().encode([_ts("base_link", "a", 1, (1, 2, 3, 0, 0, 0, 1))] * 2)
    assert dec._compiled_ros1 is not None
    for cut in range(len(raw)):
        with pytest.raises(struct.error):
            dec._compiled_ros1(raw[:cut])
        for decode in (dec.decode_ros1_struct, dec.decode_tf):
            with pytest.raises(WireDecodeError):
                decode(raw[:cut])
    huge = struct.pack("<I", 2**32 - 1) + raw[4:]  # a count no payload of this size holds
    with pytest.raises(struct.error):
        dec._compiled_ros1(huge)
    for decode in (dec.decode_ros1_struct, dec.decode_tf):
        with pytest.raises(WireDecodeError):
            decode(huge)
    bad = raw.replace(b"base_link", b"base_lin\xff")
    with pytest.raises(UnicodeDecodeError):
        dec._compiled_ros1(bad)
    for decode in (dec.decode_ros1_struct, dec.decode_tf):
        with pytest.raises(WireDecodeError, match="utf-8"):
            decode(bad)
    assert dec._compiled_ros1(struct.pack("<I", 0)) == []


def test_repeated_frame_ids_are_the_earlier_strs_and_a_changed_id_is_new() -> None:
    """A publisher repeats its frame ids: the same ASCII id at the same position is the
    str decoded before (no new object); a different id, also of the same length, or a
    non-ASCII one, is decoded anew."""
    codec = TFCodec()
    v = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    first = dec._compiled_ros1(codec.encode([_ts("map", "bench_1", 1, v), _ts("map", "ü", 1, v)]))
    again = dec._compiled_ros1(codec.encode([_ts("map", "bench_1", 2, v), _ts("map", "ü", 2, v)]))
    assert again[0].child_frame_id is first[0].child_frame_id
    assert again[0].header.frame_id is first[0].header.frame_id
    assert again[1].child_frame_id == "ü"
    changed = dec._compiled_ros1(codec.encode([_ts("odo", "bench_2", 3, v)]))
    assert [changed[0].header.frame_id, changed[0].child_frame_id] == ["odo", "bench_2"]
    back = dec._compiled_ros1(codec.encode([_ts("map", "bench_1", 4, v)]))
    assert back[0].child_frame_id == "bench_1" and back[0].header.frame_id == "map"


def _raw_tf(*values: tuple[float, ...] | bytes, stamp: int = 1) -> bytes:
    """A ROS 1 TFMessage of ``map -> c<k>`` transforms; each entry is 7 doubles or their
    56 bytes (to set NaN payloads exactly)."""
    out = [struct.pack("<I", len(values))]
    for k, v in enumerate(values):
        child = f"c{k}".encode()
        out.append(struct.pack("<IIII", 0, stamp, 0, 3) + b"map")
        out.append(struct.pack("<I", len(child)) + child)
        out.append(v if isinstance(v, bytes) else struct.pack("<7d", *v))
    return b"".join(out)


def test_repeated_values_are_the_earlier_transforms_and_changed_bytes_are_new() -> None:
    """A publisher repeats most values (joint origins, identity rotations): a transform
    whose 56 bytes equal those at the same position of the last message is that message's
    Transform; one with only the translation (or the rotation) equal shares that part;
    any other bytes give a new value, equal to what the struct decoder reads, so 0.0 and
    -0.0 or two NaN payloads are told apart."""
    one = (1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0)
    two = (4.0, 5.0, 6.0, 0.0, 0.0, 0.6, 0.8)
    first = dec._compiled_ros1(_raw_tf(one, two, one))
    again = dec._compiled_ros1(_raw_tf(one, two, one, stamp=2))
    assert [a.transform is f.transform for a, f in zip(again, first, strict=True)] == [True] * 3
    assert again[0].header.stamp.ns == 2_000_000_000  # the stamps are read anew
    # position 0: rotation changed; position 1: translation changed; 2: both
    moved = dec._compiled_ros1(_raw_tf((1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8),
                                       (7.0, 5.0, 6.0, 0.0, 0.0, 0.6, 0.8), two))
    assert moved[0].transform.translation is again[0].transform.translation
    assert moved[0].transform.rotation == Quaternion(0.0, 0.0, 0.6, 0.8)
    assert moved[1].transform.rotation is again[1].transform.rotation
    assert moved[1].transform.translation == Vector3(7.0, 5.0, 6.0)
    assert moved[2].transform == Transform(Vector3(4.0, 5.0, 6.0),
                                           Quaternion(0.0, 0.0, 0.6, 0.8))
    # byte for byte: -0.0 after 0.0 and another NaN payload are new values
    nan_a = struct.pack("<d", float("nan"))
    nan_b = struct.pack("<Q", 0x7FF8_0000_0000_0001)
    raw = [struct.pack("<6d", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) + nan_a,
           struct.pack("<7d", *one)]
    base = dec._compiled_ros1(_raw_tf(*raw))
    signed = dec._compiled_ros1(_raw_tf(struct.pack("<6d", -0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                                        + nan_b, raw[1]))
    assert struct.pack("<d", signed[0].transform.translation.x) == struct.pack("<d", -0.0)
    assert struct.pack("<d", signed[0].transform.rotation.w) == nan_b
    assert signed[1].transform is base[1].transform
    twin = dec.decode_ros1_struct(_raw_tf(struct.pack("<6d", -0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                                          + nan_b, raw[1]))
    assert [struct.pack("<7d", *t.transform.translation, *t.transform.rotation)
            for t in signed] == [struct.pack("<7d", *t.transform.translation,
                                             *t.transform.rotation) for t in twin]


def _decode(values: Sequence[tuple[float, ...]], stamp: int) -> list[TransformStamped]:
    """The compiled decode of a ROS 1 TFMessage of ``map -> c<k>`` transforms stamped
    ``stamp`` s (:mod:`refill_laws`), equal to the struct decoder's bit for bit."""
    f = dec._compiled_ros1
    assert f is not None
    raw = _raw_tf(*values, stamp=stamp)
    out = f(raw)
    twin = dec.decode_ros1_struct(raw)
    assert out == twin and refill_laws.bits(out) == refill_laws.bits(twin)
    return out


def _reuses() -> bool:
    from tfbus.codecs import _cwire

    return bool(_cwire._REUSES)


def test_a_message_nobody_holds_is_refilled_and_what_is_held_never_changes() -> None:
    """Values that change every message (a robot moving every joint) cannot be shared,
    but the objects of the message decoded two messages earlier that nothing references
    any more are refilled in place: the same TransformStamped, Transform, Vector3 and
    Quaternion, with the new bytes. A message, a transform, a rotation or a float a user
    still holds keeps its values, and a new object takes its place."""
    refill_laws.check_refilled_and_held(_decode, _reuses())


@settings(max_examples=200, deadline=None)
@given(refill_laws.steps((0.0, -0.0, 1.0, 2.5)))
def test_refilling_never_changes_what_is_held_and_decodes_as_the_twin(
    steps: list[refill_laws.Step],
) -> None:
    """Messages of 0-4 transforms whose values repeat or change at random; after each
    decode the caller keeps some of what it got (a message, a transform, a Transform, a
    Vector3, a Quaternion or a float) and drops the rest. Every decode equals the struct
    decoder's, bit for bit, and nothing kept ever changes."""
    refill_laws.check_nothing_held_changes(_decode, steps)


# -- sensor_msgs/LaserScan (a real ROS 1 laser in tfbus view) ----------------------------


def _rosbags_scan(n: int, m: int) -> tuple[bytes, object]:
    """A ROS 1 LaserScan serialised by rosbags (the reference), and the message."""
    import numpy as np

    store = dec.tf_typestore(ros1=True)
    t = store.types
    ranges = np.linspace(0.25, 9.75, n, dtype=np.float32)
    if n > 2:
        ranges[1] = np.nan
        ranges[2] = np.inf
    msg = t["sensor_msgs/msg/LaserScan"](
        header=t["std_msgs/msg/Header"](seq=7, stamp=t["builtin_interfaces/msg/Time"](
            sec=1_700_000_000, nanosec=123_456_789), frame_id="base_laser"),
        angle_min=np.float32(-2.0), angle_max=np.float32(2.0),
        angle_increment=np.float32(4.0 / max(n - 1, 1)), time_increment=np.float32(1e-4),
        scan_time=np.float32(0.1), range_min=np.float32(0.05), range_max=np.float32(30.0),
        ranges=ranges, intensities=np.arange(m, dtype=np.float32) * 0.5)
    return bytes(store.serialize_ros1(msg, "sensor_msgs/msg/LaserScan")), msg


def test_laser_scan_md5_and_definition_are_rosbags_and_debians() -> None:
    # ``rosmsg md5 sensor_msgs/LaserScan`` on Debian's ros-sensor-msgs: 90c7ef2d...
    assert dec.SCAN_MD5SUM == "90c7ef2dc6895d81024acba2ac42f369"
    assert dec.SCAN_TYPE == "sensor_msgs/LaserScan"
    definition = dec.scan_definition()
    assert definition.startswith("std_msgs/Header header\nfloat32 angle_min\n")
    assert "MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id" in definition


@pytest.mark.parametrize(("n", "m"), [(0, 0), (1, 0), (5, 5), (720, 0), (360, 360)])
def test_laser_scan_decoder_equals_rosbags(n: int, m: int) -> None:
    import numpy as np

    from tfbus.sensor_msgs import LaserScan

    raw, msg = _rosbags_scan(n, m)
    got = dec.decode_scan(raw)
    assert type(got) is LaserScan
    assert got.header == Header(Time.from_ns(1_700_000_000_123_456_789), "base_laser")
    for name in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
                 "range_min", "range_max"):
        assert getattr(got, name) == float(getattr(msg, name)), name
    assert got.ranges.dtype == np.float32 and got.intensities.dtype == np.float32
    assert got.ranges.tobytes() == msg.ranges.tobytes()  # type: ignore[attr-defined]
    assert got.intensities.tobytes() == msg.intensities.tobytes()  # type: ignore[attr-defined]
    got.ranges[:] = 0.0  # its own writable copy
    assert dec.decode_scan(memoryview(raw)).ranges.tobytes() == \
        msg.ranges.tobytes()  # type: ignore[attr-defined]


def test_laser_scan_decoder_refuses_damage_and_bounds() -> None:
    raw, _ = _rosbags_scan(5, 5)
    for cut in range(len(raw)):  # every truncation, one clear error
        with pytest.raises(WireDecodeError):
            dec.decode_scan(raw[:cut])
    with pytest.raises(WireDecodeError, match="trailing"):
        dec.decode_scan(raw + b"\x00")
    with pytest.raises(WireDecodeError, match="ranges: 5 beams exceed 4"):
        dec.decode_scan(raw, max_beams=4)
    # ranges count claiming 2**32-1 beams: refused before any allocation
    at = 16 + len("base_laser") + 28
    huge = raw[:at] + struct.pack("<I", 2**32 - 1) + raw[at + 4:]
    with pytest.raises(WireDecodeError, match="ranges"):
        dec.decode_scan(huge)
    bad_utf8 = raw.replace(b"base_laser", b"base_lase\xff", 1)
    with pytest.raises(WireDecodeError, match="frame_id"):
        dec.decode_scan(bad_utf8)
