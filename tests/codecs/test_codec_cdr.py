"""The one CDR codec (:mod:`tfbus.codecs.cdr`), used by ROS 2 bags and the ROS 2 transport:
equal to rosbags' generic CDR deserialiser, reads PLAIN_CDR2 and big-endian CDR, and a
damaged payload raises ``WireDecodeError`` and nothing else (the bag reader's decoder
raised ``struct.error`` before it shared this codec). No I/O, no DDS."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus.codecs.cdr import decode_tf, encode_tf
from tfbus.errors import WireDecodeError
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time

rosbags = pytest.importorskip("rosbags")
from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, from_rosbags, tf_typestore, to_rosbags  # noqa: E402


def _ts(parent: str, child: str, ns: int, v: tuple[float, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent),
        child,
        Transform(Vector3(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6])),
    )


MSG = (
    _ts("odom", "base_link", 1_700_000_000_123_456_789, (1.0, -2.5, 0.25, 0.0, 0.0, 0.6, 0.8)),
    _ts("base_link", "laser", 7, (0.1, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0)),
    _ts("map", "ü", 2**31 * 10**9 - 1, (3.0, 4.0, 5.0, 0.5, 0.5, 0.5, 0.5)),
)


def _rosbags_cdr(transforms: tuple[TransformStamped, ...]) -> bytes:
    store = tf_typestore(ros1=False)
    msg = to_rosbags(store, transforms, ros1=False)
    return bytes(store.serialize_cdr(msg, ROSBAGS_TF_TYPE))


def test_equal_to_rosbags_both_ways() -> None:
    """rosbags writes ROS 2 bags' samples; the codec reads them as rosbags does and
    writes the same bytes (up to the final padding rosbags omits)."""
    raw = _rosbags_cdr(MSG)
    store = tf_typestore(ros1=False)
    assert decode_tf(raw) == TFMessage(MSG)
    assert tuple(from_rosbags(store.deserialize_cdr(raw, ROSBAGS_TF_TYPE))) == MSG
    ours = encode_tf(MSG)
    assert ours[: len(raw)] == raw and set(ours[len(raw):]) <= {0}
    assert decode_tf(memoryview(raw)) == TFMessage(MSG)  # a bag's view


def _plain_cdr2(transforms: tuple[TransformStamped, ...], *, big: bool) -> bytes:
    """XCDR2's plain form by hand (DDS-XTypes 1.3, 7.4.3.5: doubles aligned to 4)."""
    e = ">" if big else "<"
    out = bytearray(b"\x00\x06\x00\x00" if big else b"\x00\x07\x00\x00")
    body = bytearray(struct.pack(e + "I", len(transforms)))

    def align(n: int) -> None:
        body.extend(b"\0" * (-len(body) % n))

    for t in transforms:
        sec, nsec = divmod(t.header.stamp.ns, 10**9)
        frame = t.header.frame_id.encode() + b"\0"
        child = t.child_frame_id.encode() + b"\0"
        align(4)
        body += struct.pack(e + "iII", sec, nsec, len(frame)) + frame
        align(4)
        body += struct.pack(e + "I", len(child)) + child
        align(4)
        tr, q = t.transform.translation, t.transform.rotation
        body += struct.pack(e + "7d", tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
    return bytes(out + body)


@pytest.mark.parametrize("big", [False, True])
def test_reads_plain_cdr2(big: bool) -> None:
    assert decode_tf(_plain_cdr2(MSG, big=big)) == TFMessage(MSG)


def test_reads_big_endian_cdr() -> None:
    raw = bytearray(encode_tf(MSG[:1]))
    # re-encode the same values big-endian: XCDR1 layout, every field byte-swapped
    be = bytearray(b"\x00\x00\x00\x00") + struct.pack(">I", 1)
    t = MSG[0]
    frame, child = b"odom\0", b"base_link\0"
    sec, nsec = divmod(t.header.stamp.ns, 10**9)
    be += struct.pack(">iII", sec, nsec, len(frame)) + frame
    be += b"\0" * (-(len(be) - 4) % 4) + struct.pack(">I", len(child)) + child
    be += b"\0" * (-(len(be) - 4) % 8)
    tr, q = t.transform.translation, t.transform.rotation
    be += struct.pack(">7d", tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
    assert decode_tf(bytes(be)) == decode_tf(bytes(raw)) == TFMessage(MSG[:1])


def test_every_truncation_is_a_wire_decode_error() -> None:
    """A bag record cut anywhere: WireDecodeError (the bag reader then reports a
    BagReadError naming the message), never struct.error, IndexError or a wrong value."""
    raw = _rosbags_cdr(MSG)
    for cut in range(len(raw)):
        with pytest.raises(WireDecodeError):
            decode_tf(raw[:cut])


@pytest.mark.parametrize(
    ("patch", "match"),
    [
        (lambda b: b"\x00\x02" + b[2:], "encapsulation 0x0002"),  # PL_CDR_BE: not plain
        (lambda b: b[:8] + b"\xff\xff\xff\xff" + b[12:], "sec=-1 is before 1970"),
        (lambda b: b.replace(b"odom\x00", b"odo\xff\x00", 1), "not UTF-8"),
        (lambda b: b.replace(b"odom\x00", b"odomX", 1), "not a NUL-terminated"),
        (lambda b: b[:4] + struct.pack("<I", 10**4) + b[8:], "announces 10000"),
    ],
)
def test_damaged_samples_say_what_is_wrong(patch: object, match: str) -> None:
    raw = _rosbags_cdr(MSG)
    assert callable(patch)
    with pytest.raises(WireDecodeError, match=match):
        decode_tf(patch(raw))


@pytest.fixture(scope="module")
def msg_cdr() -> bytes:
    """rosbags' bytes of MSG, made once (a typestore compiles its serialiser on first
    use: half a second per example otherwise)."""
    return _rosbags_cdr(MSG)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.integers(0, 400), st.integers(0, 255))
def test_fuzz_only_wire_decode_errors(msg_cdr: bytes, noise: bytes, where: int, byte: int) -> None:
    raw = bytearray(msg_cdr)
    raw[where % len(raw)] = byte
    for data in (bytes(raw), noise, b"\x00\x01\x00\x00" + noise):
        try:
            out = decode_tf(data)
        except WireDecodeError:
            continue
        assert all(type(t) is TransformStamped for t in out.transforms)


def test_clock_equal_to_rosbags_both_ways() -> None:
    """``rosgraph_msgs/msg/Clock`` (the ROS 2 transport's ``/clock``, ``ros2 bag`` recordings
    made with ``--clock``): the codec writes rosbags' bytes and reads them back."""
    from rosbags.typesys import Stores, get_typestore

    from tfbus.codecs.cdr import decode_clock, encode_clock
    from tfbus.messages import Clock

    store = get_typestore(Stores.ROS2_KILTED)
    stamp = store.types["builtin_interfaces/msg/Time"](sec=1_700_000_123, nanosec=456_789_012)
    raw = bytes(store.serialize_cdr(store.types["rosgraph_msgs/msg/Clock"](clock=stamp),
                                    "rosgraph_msgs/msg/Clock"))  # fmt: skip
    clock = Clock(Time(1_700_000_123, 456_789_012))
    assert encode_clock(clock) == raw
    assert decode_clock(raw) == decode_clock(memoryview(raw)) == clock
    back = store.deserialize_cdr(encode_clock(clock), "rosgraph_msgs/msg/Clock")
    assert (back.clock.sec, back.clock.nanosec) == (1_700_000_123, 456_789_012)
    for damaged in (raw[:11], b"\x00\x09" + raw[2:], raw[:8] + struct.pack("<I", 10**9)):
        with pytest.raises(WireDecodeError):
            decode_clock(damaged)
