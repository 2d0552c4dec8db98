"""Fuzzing the decoders of the Zenoh wire and of ROS 2's TFMessage and LookupTransform
samples with *mutated valid payloads*: a payload each encoder wrote, then bits flipped,
cut short, extended, absurd lengths spliced over or into it, runs of it swapped or
repeated (:func:`mutated`). Unlike the random-bytes fuzzing of ``test_codec_native.py`` and
``test_codec_cdr.py``, almost every input here gets past the magic byte, the header and
the first lengths, deep into the decoders.

Asserted on every input: the decoder returns or raises its documented error
(:class:`~tfbus.errors.WireError` for :mod:`tfbus.codecs.native`,
:class:`~tfbus.errors.WireDecodeError` for :mod:`tfbus.codecs.cdr` and
:mod:`tfbus.codecs.lookup_action_cdr`) and nothing else; what it accepts is a fixed point
of encode/decode (encoding the decoded value and decoding it again gives the same bytes
and values); the native decoder's two paths (the typed fast path for a TFMessage and the
general path that reads the envelope by hand) give the same verdict and the same values;
a TFMessage sample the CDR codec accepts holds what rosbags' generic deserialiser reads.
No I/O; deterministic (``derandomize=True``).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

msgspec = pytest.importorskip("msgspec")

from fuzz_support import fuzz, mutants  # noqa: E402

from tfbus.codecs import cdr  # noqa: E402
from tfbus.codecs import lookup_action_cdr as lac  # noqa: E402
from tfbus.codecs import native as wire  # noqa: E402
from tfbus.errors import WireDecodeError, WireEncodeError, WireError  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Clock,
    Header,
    JointState,
    LookupTransformGoal,
    LookupTransformResult,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField  # noqa: E402
from tfbus.time import Time  # noqa: E402


def test_mutations_reach_past_the_header() -> None:
    """The strategy's own check: most mutants keep a valid prefix (what makes them reach
    deep into a decoder) and some differ from the original."""
    seen: list[bytes] = []

    @fuzz(100)
    @given(mutants(bytes(range(64))))
    def collect(data: bytes) -> None:
        seen.append(data)

    collect()
    assert sum(d != bytes(range(64)) for d in seen) > 80
    assert sum(d[:4] == bytes(range(4)) for d in seen) > 50


# -- tfbus's own wire (tfbus.codecs.native) ------------------------------------------------


def _ts(parent: str, child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, -2.5, 0.25), Quaternion(0.0, 0.0, 0.6, 0.8)))


_CODEC = wire.WireCodec()
_TF = TFMessage((_ts("odom", "base_link", 1_700_000_000_123_456_789, 1.0),
                 _ts("base_link", "laser", 7, 0.1), _ts("map", "ü", 2**62, 3.0)))
_SCAN = LaserScan(Header(Time.from_ns(5), "laser"), -1.5, 1.5, 0.5, 1e-4, 0.1, 0.05, 30.0,
                  np.array([0.5, np.nan, np.inf, 7.25, 1.0, 2.0, 3.0], dtype=np.float32),
                  np.arange(7, dtype=np.float32))
_CLOUD = PointCloud2(Header(Time.from_ns(9), "camera"), 1, 2,
                     [PointField("x", 0, 7, 1), PointField("y", 4, 7, 1)], False, 8, 16,
                     bytes(range(16)), True)
_NATIVE: dict[str, bytes] = {
    "tf": _CODEC.encode(_TF, sender=9, seq=4),
    "TransformStamped": _CODEC.encode(_TF.transforms[0], sender=2**63 - 1, seq=1),
    "LaserScan": _CODEC.encode(_SCAN, sender=9, seq=4),
    "PointCloud2": _CODEC.encode(_CLOUD, sender=9, seq=4),
    "Clock": _CODEC.encode(Clock(Time.from_ns(1_700_000_000_000_000_000)), sender=9, seq=4),
    "JointState": _CODEC.encode(JointState(Header(Time.from_ns(3), "base"), ["a", "b"],
                                           [0.5, 1.0], [], []), sender=9, seq=4),
    # a request to the Zenoh buffer server (tfbus.transports.zenoh.lookups)
    "lookup request": _CODEC.encode({"op": "full", "target": "map", "source": "base_link",
                                     "target_time": 0, "source_time": 5, "fixed": "odom",
                                     "timeout": 1.5, "policy": ["window", 10, 20]},
                                    sender=9, seq=1),
}


def _fixed_point(codec: wire.WireCodec, decoded: wire.Decoded) -> None:
    """Encoding what was decoded and decoding it again gives the same bytes (a
    WireEncodeError here fails the test: whatever decodes must be encodable)."""
    again = codec.encode(decoded.message, sender=decoded.sender, seq=decoded.seq)
    second = codec.decode(again)
    assert (second.sender, second.seq) == (decoded.sender, decoded.seq)
    assert codec.encode(second.message, sender=second.sender, seq=second.seq) == again


@fuzz(300)
@given(st.sampled_from(sorted(_NATIVE)).flatmap(lambda tag: mutants(_NATIVE[tag])))
def test_native_decoder_raises_only_wire_errors_on_mutants(data: bytes) -> None:
    """Mutants of a payload of every tag (TFMessage, registered types, LaserScan,
    PointCloud2, a plain map as the lookup server receives): a decoded message or a
    WireError, never anything else, and what decodes is a fixed point of encode/decode."""
    try:
        decoded = _CODEC.decode(data)
    except WireError:
        return
    _fixed_point(_CODEC, decoded)


def _general_path_tf(codec: wire.WireCodec, data: bytes) -> TFMessage:
    """The native decoder's general path for a ``"tf"`` payload: the envelope read by
    hand (:func:`~tfbus.codecs.native.read_head`), the body by the TFMessage schema (what
    :meth:`~tfbus.codecs.native.WireCodec.decode` runs when its fast path refuses)."""
    if len(data) < 2 or data[0] != wire.MAGIC or data[1] != wire.WIRE_VERSION:
        raise WireDecodeError("not a tfbus payload")
    sender, seq, tag, pos = wire.read_head(data, 2)
    if tag != "tf" or not (0 < sender < 2**63 and 0 < seq < 2**63):
        raise WireDecodeError(f"not a TFMessage envelope: {sender} {seq} {tag!r}")
    try:
        body = codec._tf_decoder.decode(memoryview(data)[pos:])
    except (msgspec.DecodeError, UnicodeDecodeError) as exc:  # msgspec: bad UTF-8 raw
        raise WireDecodeError(str(exc)) from None
    return TFMessage(wire._from_wire(body))


@fuzz(150)
@given(mutants(_NATIVE["tf"]))
def test_native_fast_and_general_paths_agree(data: bytes) -> None:
    """The typed fast path (one msgspec schema for the whole envelope) and the general
    path (envelope by hand, then the body's schema) accept and refuse the same TFMessage
    payloads, with the same transforms; ``decode_tf`` gives the codec's verdict."""
    try:
        fast = _CODEC._tf_envelope_decoder.decode(memoryview(data)[2:]) \
            if data[:2] == bytes((wire.MAGIC, wire.WIRE_VERSION)) else None
    except Exception:  # as WireCodec.decode: any refusal sends it to the general path
        fast = None
    try:
        general: TFMessage | None = _general_path_tf(_CODEC, data)
    except WireError:
        general = None
    if fast is not None:
        assert general is not None, "the fast path accepted what the general path refuses"
        assert TFMessage(wire._from_wire(fast.body)) == general
    try:
        decoded = wire.decode_tf(data)
    except WireError:
        assert general is None
    else:
        assert general is not None and decoded == general


def test_native_mutants_by_hand_are_refused() -> None:
    """One mutant of each kind, by hand: an absurd count, an absurd string length, a cut,
    a trailing byte; each refused as malformed."""
    good = _NATIVE["tf"]
    cases: list[tuple[bytes, type[WireError]]] = [
        (good[:3] + b"\xdd\xff\xff\xff\xff" + good[3:], WireDecodeError),  # absurd count
        (good.replace(b"\xa4odom", b"\xdb\xff\xff\xff\xffodom", 1), WireDecodeError),
        (good[:-5], WireDecodeError),  # cut in the last float
        (good + b"\x00", WireDecodeError),  # trailing byte
    ]
    for data, error in cases:
        with pytest.raises(error):
            _CODEC.decode(data)


# -- ROS 2 TFMessage (tfbus.codecs.cdr) -----------------------------------------------------

_TF_CDR: dict[str, bytes] = {
    "CDR_LE": cdr.encode_tf(_TF.transforms[:2]),
}
_TF_CDR["CDR_BE"] = b""  # filled below, from the LE sample's values


def _cdr_be(transforms: tuple[TransformStamped, ...]) -> bytes:
    """XCDR1 big-endian by hand (OMG DDS-XTypes 7.4.3: the same layout, other byte order)."""
    out = bytearray(b"\x00\x00\x00\x00")
    body = bytearray(struct.pack(">I", len(transforms)))

    def align(n: int) -> None:
        body.extend(b"\0" * (-len(body) % n))

    for t in transforms:
        align(4)
        sec, nsec = divmod(t.header.stamp.ns, 10**9)
        frame = t.header.frame_id.encode() + b"\0"
        body += struct.pack(">iII", sec, nsec, len(frame)) + frame
        align(4)
        child = t.child_frame_id.encode() + b"\0"
        body += struct.pack(">I", len(child)) + child
        align(8)
        body += struct.pack(">7d", *t.transform.translation, *t.transform.rotation)
    return bytes(out + body)


_TF_CDR["CDR_BE"] = _cdr_be(_TF.transforms[:2])


@pytest.fixture(scope="module")
def rosbags_tf() -> Callable[[bytes], tuple[TransformStamped, ...] | None]:
    """rosbags' generic CDR deserialiser of ``tf2_msgs/msg/TFMessage`` (the reference)."""
    pytest.importorskip("rosbags")
    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, from_rosbags, tf_typestore

    store = tf_typestore(ros1=False)

    def read(data: bytes) -> tuple[TransformStamped, ...] | None:
        """The transforms, or None where rosbags refuses bytes after the message (tfbus
        ignores them: a DDS sample may be padded)."""
        from rosbags.serde import SerdeError

        try:
            return tuple(from_rosbags(store.deserialize_cdr(data, ROSBAGS_TF_TYPE)))
        except SerdeError as exc:
            if "size mismatch" in str(exc):
                return None
            raise

    return read


def test_the_big_endian_sample_is_the_little_endian_one(
        rosbags_tf: Callable[[bytes], tuple[TransformStamped, ...] | None]) -> None:
    assert cdr.decode_tf(_TF_CDR["CDR_BE"]) == cdr.decode_tf(_TF_CDR["CDR_LE"]) \
        == TFMessage(_TF.transforms[:2])
    assert rosbags_tf(_TF_CDR["CDR_BE"]) == _TF.transforms[:2]


def _same(a: tuple[TransformStamped, ...], b: tuple[TransformStamped, ...]) -> bool:
    """Equal transforms, NaN equal to NaN (a flipped bit makes NaNs)."""
    def key(t: TransformStamped) -> tuple[Any, ...]:
        values = (*t.transform.translation, *t.transform.rotation)
        return (t.header, t.child_frame_id,
                tuple("nan" if math.isnan(v) else v for v in values))
    return [key(t) for t in a] == [key(t) for t in b]


@fuzz(150)
@given(st.sampled_from(sorted(_TF_CDR)).flatmap(lambda kind: mutants(_TF_CDR[kind])))
def test_cdr_tf_mutants_only_decode_errors_and_agree_with_rosbags(
        rosbags_tf: Callable[[bytes], tuple[TransformStamped, ...] | None], data: bytes) -> None:
    """Mutants of an XCDR1 TFMessage (little- and big-endian): a TFMessage or a
    WireDecodeError; what tfbus accepts, rosbags' deserialiser reads the same (tfbus is
    stricter: NUL-terminated UTF-8 strings, no stamp before 1970)."""
    try:
        out = cdr.decode_tf(data)
    except WireDecodeError:
        return
    reference = rosbags_tf(data)
    if reference is not None:
        assert _same(out.transforms, reference)


# -- ROS 2 LookupTransform action samples (tfbus.codecs.lookup_action_cdr) -------------------

_RID = lac.RequestId(0x0102_0304_0506_0708, 7)
_GID = bytes(range(16))
_GOAL = lac.LookupGoal(_GID, "map", "base_link", Time(5, 250), 1.5, Time(0), "odom", True)
_RESULT = lac.LookupResult(4, _ts("map", "base_link", 5_000_000_250, 1.0), 2,
                           "frame 'x' does not exist")
_INFO = lac.GoalInfo(_GID, Time(3))
_ACTION: dict[str, tuple[bytes, Callable[[bytes], Any], Callable[[Any], bytes]]] = {
    "send_goal request": (
        lac.encode_send_goal_request(_RID, _GOAL), lac.decode_send_goal_request,
        lambda v: lac.encode_send_goal_request(*v)),
    "send_goal response": (
        lac.encode_send_goal_response(_RID, True, Time(9)), lac.decode_send_goal_response,
        lambda v: lac.encode_send_goal_response(*v)),
    "get_result request": (
        lac.encode_get_result_request(_RID, _GID), lac.decode_get_result_request,
        lambda v: lac.encode_get_result_request(*v)),
    "get_result response": (
        lac.encode_get_result_response(_RID, _RESULT), lac.decode_get_result_response,
        lambda v: lac.encode_get_result_response(*v)),
    "cancel request": (
        lac.encode_cancel_goal_request(_RID, _INFO), lac.decode_cancel_goal_request,
        lambda v: lac.encode_cancel_goal_request(*v)),
    "cancel response": (
        lac.encode_cancel_goal_response(_RID, 0, [_INFO, _INFO]),
        lac.decode_cancel_goal_response, lambda v: lac.encode_cancel_goal_response(*v)),
    "status": (
        lac.encode_goal_status_array([(_INFO, 2), (_INFO, 4)]), lac.decode_goal_status_array,
        lac.encode_goal_status_array),
    "goal": (
        lac.encode_lookup_goal(LookupTransformGoal(
            "map", "base_link", Time(5), 2.0, Time(0), "", False,
            "6ba7b810-9dad-11d1-80b4-00c04fd430c8")),
        lac.decode_lookup_goal, lac.encode_lookup_goal),
    "result": (
        lac.encode_lookup_result(LookupTransformResult(_RESULT.transform, 2, "no", status=4)),
        lac.decode_lookup_result, lac.encode_lookup_result),
}


@fuzz(300)
@given(st.sampled_from(sorted(_ACTION)).flatmap(
    lambda kind: st.tuples(st.just(kind), mutants(_ACTION[kind][0]))))
def test_action_sample_mutants_only_decode_errors(case: tuple[str, bytes]) -> None:
    """Mutants of every sample of the action's services and status topic: the value or
    a WireDecodeError; what decodes is a fixed point (encoded again and decoded, the same
    value; a timeout past int32 seconds is capped to the longest Duration, as sent)."""
    kind, data = case
    _valid, decode, encode = _ACTION[kind]
    try:
        value = decode(data)
    except WireDecodeError:
        return
    try:
        again = encode(value)
    except WireEncodeError as exc:
        # The one value read but not written: a string with a NUL before its terminating
        # one (read as rosbags reads it; a NUL-terminated CDR string cannot carry it, so
        # the encoder refuses it, and a server answers such a goal ABORTED, unsendable).
        assert "NUL character" in str(exc), f"{kind}: decoded {value!r:.300}: {exc}"
        return
    # repr: equal also where a flipped bit made a NaN (NaN != NaN)
    assert repr(decode(again)) == repr(value)


def test_action_mutants_by_hand_are_refused() -> None:
    """Mutants by hand: an absurd sequence count, a string length past the end, a sample cut
    inside the goal id; each a WireDecodeError naming what is wrong."""
    status = _ACTION["status"][0]
    with pytest.raises(WireDecodeError, match="announces 4294967295 elements"):
        lac.decode_goal_status_array(status[:4] + b"\xff\xff\xff\xff" + status[8:])
    goal = _ACTION["send_goal request"][0]
    with pytest.raises(WireDecodeError, match="target_frame is not a NUL-terminated"):
        lac.decode_send_goal_request(goal[:36] + b"\xff\xff\xff\x7f" + goal[40:])
    with pytest.raises(WireDecodeError, match="goal_id runs past the end"):
        lac.decode_send_goal_request(goal[:30])


@pytest.mark.parametrize("field", ["target_frame", "source_frame", "fixed_frame"])
def test_a_lone_surrogate_frame_id_is_a_named_encode_error(field: str) -> None:
    """A frame id UTF-8 cannot carry (a lone surrogate, which Python strings may hold)
    raised UnicodeEncodeError out of the goal encoders (ROS 2 and ROS 1) and the result
    encoders; it is a WireEncodeError naming the field and the value."""
    from tfbus.codecs import ros1

    goal = LookupTransformGoal("map", "base", Time(5), 2.0, Time(0), "odom", True,
                               "6ba7b810-9dad-11d1-80b4-00c04fd430c8", Time(4))
    bad = goal._replace(**{field: "ma\ud800p"})
    with pytest.raises(WireEncodeError, match=rf"{field}.*'ma\\ud800p'"):
        lac.encode_lookup_goal(bad)
    with pytest.raises(WireEncodeError, match=rf"goal\.{field}.*'ma\\ud800p'"):
        ros1.encode_lookup_goal(bad)
    with pytest.raises(WireEncodeError, match=field):
        lac.encode_send_goal_request(_RID, _GOAL._replace(**{field: "\udfff"}))
    result = LookupTransformResult(_RESULT.transform, 1, "frame '\udc80' does not exist")
    with pytest.raises(WireEncodeError, match="error_string"):
        lac.encode_lookup_result(result)
    with pytest.raises(WireEncodeError, match="error_string"):
        ros1.encode_lookup_result(result)


@pytest.mark.parametrize("name", ["angle_min", "range_max", "time_increment"])
@pytest.mark.parametrize("value", [1e300, -3.5e38])
def test_a_scan_value_past_float32_is_a_named_decode_error(name: str, value: float) -> None:
    """A LaserScan payload whose float64 angle, time or range is finite but beyond
    float32 (``LaserScan.msg``'s type) decoded to an infinite value with numpy's overflow
    RuntimeWarning printed (found by the mutants above); it is refused naming the field.
    float32's own extremes (its largest value, infinities, NaN) still decode."""
    import warnings

    marker = 1234.5  # exactly a float32: the encoder writes it as it is
    scan = LaserScan(**{**{f: getattr(_SCAN, f) for f in (
        "header", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
        "range_min", "range_max", "ranges", "intensities")}, name: marker})
    payload = _CODEC.encode(scan, sender=9, seq=4)
    old = b"\xcb" + struct.pack(">d", marker)
    assert payload.count(old) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning either
        with pytest.raises(WireDecodeError, match=rf"LaserScan\.{name} .* outside float32"):
            _CODEC.decode(payload.replace(old, b"\xcb" + struct.pack(">d", value)))
        f32_max = float(np.finfo(np.float32).max)
        for edge in (f32_max, -f32_max, math.inf, -math.inf):
            got = _CODEC.decode(payload.replace(old, b"\xcb" + struct.pack(">d", edge)))
            assert getattr(got.message, name) == edge
