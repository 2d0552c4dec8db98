"""Every codec module has one shape: the same function names with the same parameters
(``encode_tf``/``decode_tf``, ``encode_scan``/``decode_scan``, ``encode_clock``/
``decode_clock``, and the ``tf2_msgs/LookupTransform`` action's goal and result where the
wire has them), each round-tripping the same values; the LaserScan encoders write what
rosbags writes (ROS 1 and CDR), and the ROS 1 action messages are read by Debian's genpy
as tf2_ros's own."""

from __future__ import annotations

import inspect
import struct
import subprocess
from dataclasses import replace
from types import ModuleType

import numpy as np
import pytest

from tfbus.codecs import cdr, lookup_action_cdr, native, ros1
from tfbus.errors import WireDecodeError, WireEncodeError, WireLimitError
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
from tfbus.time import Time

CODECS: tuple[ModuleType, ...] = (native, ros1, cdr)
SHAPE = ("encode_tf", "decode_tf", "encode_scan", "decode_scan", "encode_clock",
         "decode_clock")
LOOKUP_SHAPE = ("encode_lookup_goal", "decode_lookup_goal", "encode_lookup_result",
                "decode_lookup_result")


def _parameters(function: object) -> list[tuple[str, object, object]]:
    """``(name, kind, default)`` of every parameter."""
    assert callable(function)
    return [(p.name, p.kind, p.default)
            for p in inspect.signature(function).parameters.values()]


def test_every_codec_module_has_the_same_functions_and_parameters() -> None:
    reference = {name: _parameters(getattr(ros1, name)) for name in (*SHAPE, *LOOKUP_SHAPE)}
    assert reference["encode_tf"] == [("message", inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                       inspect.Parameter.empty)]
    assert reference["decode_tf"][1] == ("max_transforms", inspect.Parameter.KEYWORD_ONLY,
                                         100_000)
    assert reference["decode_scan"][1] == ("max_beams", inspect.Parameter.KEYWORD_ONLY,
                                           1_000_000)
    for module in CODECS:
        for name in SHAPE:
            assert name in module.__all__, f"{module.__name__} lacks {name}"
            assert _parameters(getattr(module, name)) == reference[name], \
                f"{module.__name__}.{name}"
            assert getattr(module, name).__doc__, f"{module.__name__}.{name} has no docstring"
        present = [name for name in LOOKUP_SHAPE if hasattr(module, name)]
        assert present in ([], list(LOOKUP_SHAPE)), f"{module.__name__}: {present}"
        for name in present:
            assert name in module.__all__, f"{module.__name__} lacks {name}"
            assert _parameters(getattr(module, name)) == reference[name], \
                f"{module.__name__}.{name}"
            assert getattr(module, name).__doc__, f"{module.__name__}.{name} has no docstring"
    # the wires with the action: ROS 1 (actionlib) and ROS 2 (CDR, re-exported by cdr)
    assert all(hasattr(m, name) for m in (ros1, cdr) for name in LOOKUP_SHAPE)
    assert cdr.encode_lookup_goal is lookup_action_cdr.encode_lookup_goal


TS = (
    TransformStamped(Header(Time(1_700_000_000, 123_456_789), "odom"), "base_link",
                     Transform(Vector3(1.0, -2.5, 0.25), Quaternion(0.0, 0.0, 0.6, 0.8))),
    TransformStamped(Header(Time(7), "base_link"), "ü",
                     Transform(Vector3(0.1, 0.0, 0.2), Quaternion(0.0, 0.0, 0.0, 1.0))),
)


def _scan(n: int = 5, m: int = 3) -> LaserScan:
    ranges = np.linspace(0.25, 9.75, n, dtype=np.float32)
    if n > 2:
        ranges[1], ranges[2] = np.nan, np.inf
    return LaserScan(Header(Time(1_700_000_000, 123_456_789), "base_laser"), -2.0, 2.0,
                     0.5, 1e-4, 0.1, 0.05, 30.0, ranges,
                     np.arange(m, dtype=np.float32) * 0.5)


def _f32(x: float) -> float:
    return float(np.float32(x))


@pytest.mark.parametrize("module", CODECS, ids=lambda m: m.__name__)
def test_every_codec_round_trips_the_same_values(module: ModuleType) -> None:
    assert module.decode_tf(module.encode_tf(TFMessage(TS))) == TFMessage(TS)
    assert module.decode_tf(memoryview(module.encode_tf(list(TS)))) == TFMessage(TS)
    scan = _scan()
    got = module.decode_scan(module.encode_scan(scan))
    assert got.header == scan.header
    assert (got.angle_min, got.angle_increment, got.time_increment, got.range_max) == (
        -2.0, 0.5, _f32(1e-4), 30.0)
    assert got.ranges.dtype == np.float32
    assert got.ranges.tobytes() == scan.ranges.tobytes()  # NaN and inf bit for bit
    assert got.intensities.tobytes() == scan.intensities.tobytes()
    assert module.decode_clock(module.encode_clock(Clock(Time(42, 7)))) == Clock(Time(42, 7))
    many = module.encode_tf(TS * 3)
    assert len(module.decode_tf(many, max_transforms=6).transforms) == 6
    with pytest.raises((WireDecodeError, WireLimitError), match=r"5|6"):
        module.decode_tf(many, max_transforms=5)
    with pytest.raises((WireDecodeError, WireLimitError)):
        module.decode_scan(module.encode_scan(scan), max_beams=4)
    with pytest.raises(WireEncodeError):
        module.encode_scan(Clock())
    with pytest.raises(WireEncodeError):
        module.encode_clock(scan)


def test_native_functions_write_one_shot_payloads_and_refuse_another_type() -> None:
    payload = native.encode_tf(TS)
    decoded = native.WireCodec().decode(payload)
    assert (decoded.sender, decoded.seq, decoded.message) == (native.ONE_SHOT_SENDER, 1,
                                                              TFMessage(TS))
    with pytest.raises(WireDecodeError, match="a tfbus payload of Clock, expected a TFMessage"):
        native.decode_tf(native.encode_clock(Clock(Time(1))))
    with pytest.raises(WireDecodeError, match="expected a LaserScan"):
        native.decode_scan(payload)


# -- LaserScan against rosbags ----------------------------------------------------------

def _rosbags_scan(scan: LaserScan, *, ros1_store: bool) -> tuple[object, object]:
    pytest.importorskip("rosbags")
    store = ros1.tf_typestore(ros1=ros1_store)
    t = store.types
    sec, nsec = divmod(scan.header.stamp.ns, 10**9)
    stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    header = (t["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=scan.header.frame_id)
              if ros1_store else t["std_msgs/msg/Header"](stamp=stamp,
                                                           frame_id=scan.header.frame_id))
    msg = t["sensor_msgs/msg/LaserScan"](
        header=header,
        **{name: np.float32(getattr(scan, name)) for name in (
            "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
            "range_min", "range_max")},
        ranges=scan.ranges, intensities=scan.intensities)
    return store, msg


@pytest.mark.parametrize(("n", "m"), [(0, 0), (1, 0), (5, 5), (720, 0), (3, 360)])
def test_ros1_scan_encoder_writes_what_rosbags_writes(n: int, m: int) -> None:
    scan = _scan(n, m)
    store, msg = _rosbags_scan(scan, ros1_store=True)
    expected = bytes(store.serialize_ros1(msg, "sensor_msgs/msg/LaserScan"))  # type: ignore[attr-defined]
    assert ros1.encode_scan(scan) == expected
    with pytest.raises(WireEncodeError, match="outside ROS 1 time"):
        ros1.encode_scan(replace(scan, header=Header(Time(2**32), "l")))


@pytest.mark.parametrize(("n", "m", "frame"), [(0, 0, ""), (1, 0, "l"), (5, 5, "laser"),
                                               (720, 0, "base_laser"), (3, 360, "ü_front")])
def test_cdr_scan_codec_equals_rosbags_both_ways(n: int, m: int, frame: str) -> None:
    scan = _scan(n, m)
    scan = replace(scan, header=Header(scan.header.stamp, frame))
    store, msg = _rosbags_scan(scan, ros1_store=False)
    expected = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))  # type: ignore[attr-defined]
    ours = cdr.encode_scan(scan)
    assert ours[:len(expected)] == expected and set(ours[len(expected):]) <= {0}
    assert len(ours) % 4 == 0
    big = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/LaserScan",  # type: ignore[attr-defined]
                                    little_endian=False))
    for raw in (expected, big):
        got = cdr.decode_scan(raw)
        assert got.header == scan.header
        assert got.angle_increment == _f32(scan.angle_increment)
        assert got.ranges.tobytes() == scan.ranges.tobytes()
        assert got.intensities.tobytes() == scan.intensities.tobytes()


def test_cdr_scan_decoder_refuses_damage_and_bounds() -> None:
    raw = cdr.encode_scan(_scan(5, 5))
    for cut in range(len(raw)):
        with pytest.raises(WireDecodeError):
            cdr.decode_scan(raw[:cut])
    with pytest.raises(WireDecodeError, match="ranges: 5 beams exceed 4"):
        cdr.decode_scan(raw, max_beams=4)
    at = 4 + 12 + len(b"base_laser\0") + 1 + 28  # header, frame id + pad, 7 floats
    assert struct.unpack_from("<I", raw, at) == (5,)
    huge = raw[:at] + struct.pack("<I", 2**32 - 1) + raw[at + 4:]
    with pytest.raises(WireDecodeError, match="ranges"):
        cdr.decode_scan(huge)
    with pytest.raises(WireDecodeError, match="frame_id is not UTF-8"):
        cdr.decode_scan(raw.replace(b"base_laser", b"base_lase\xff", 1))
    with pytest.raises(WireDecodeError, match="before 1970"):
        cdr.decode_scan(raw[:4] + struct.pack("<i", -1) + raw[8:])
    with pytest.raises(WireDecodeError, match="encapsulation"):
        cdr.decode_scan(b"\x00\x09" + raw[2:])
    with pytest.raises(WireEncodeError, match="NUL"):
        cdr.encode_scan(replace(_scan(), header=Header(Time(1), "a\0b")))


def test_ros1_decode_tf_refuses_more_transforms_than_allowed() -> None:
    raw = struct.pack("<I", 3) + b"\0" * 8
    with pytest.raises(WireDecodeError, match=r"3 transforms \(limit 2\)"):
        ros1.decode_tf(raw, max_transforms=2)


# -- the LookupTransform action on ROS 1 ------------------------------------------------

GOAL = LookupTransformGoal("map", "laser", Time(5, 7), 1.5, Time(6), "odom", True, "g-1",
                           Time(9, 4))
RESULT = LookupTransformResult(TS[0], 3, "extrapolation into the future", "g-1", Time(9, 4),
                               3, "done", Time(11, 2))


def test_ros1_lookup_goal_and_result_round_trip_and_refuse_damage() -> None:
    raw_goal, raw_result = ros1.encode_lookup_goal(GOAL), ros1.encode_lookup_result(RESULT)
    assert ros1.decode_lookup_goal(raw_goal) == GOAL
    assert ros1.decode_lookup_result(raw_result) == RESULT
    for raw, decode in ((raw_goal, ros1.decode_lookup_goal),
                        (raw_result, ros1.decode_lookup_result)):
        for cut in range(len(raw)):
            with pytest.raises(WireDecodeError, match="malformed tf2_msgs/LookupTransform"):
                decode(raw[:cut])
    with pytest.raises(WireEncodeError, match=r"source_time .* past ROS 1 time"):
        ros1.encode_lookup_goal(GOAL._replace(source_time=Time(2**32)))
    with pytest.raises(WireEncodeError, match="timeout"):
        ros1.encode_lookup_goal(GOAL._replace(timeout=float("nan")))
    with pytest.raises(WireEncodeError, match="uint8"):
        ros1.encode_lookup_result(RESULT._replace(error=256))
    assert ros1.decode_goal_id(ros1.encode_goal_id(Time(3, 1), "g-9")) == (Time(3, 1), "g-9")


_GENPY = """
import sys
from actionlib_msgs.msg import GoalStatusArray
from tf2_msgs.msg import LookupTransformActionResult as R
goal, result, status = (bytes.fromhex(line) for line in sys.stdin.read().split())
r = R(); r.deserialize(result)
t = r.result.transform
print(r.header.stamp.to_nsec(), r.status.goal_id.id, r.status.goal_id.stamp.to_nsec(),
      r.status.status, r.status.text, t.header.stamp.to_nsec(), t.header.frame_id,
      t.child_frame_id, t.transform.translation.y, t.transform.rotation.z,
      r.result.error.error, repr(r.result.error.error_string))
s = GoalStatusArray(); s.deserialize(status)
print(s.header.stamp.to_nsec(), [(g.goal_id.id, g.goal_id.stamp.to_nsec(), g.status, g.text)
                                 for g in s.status_list])
"""


def test_ros1_action_messages_are_read_by_debians_genpy() -> None:
    status = ros1.encode_goal_status_array(Time(12), [("g-1", Time(9, 4), 1, ""),
                                                      ("g-2", Time(8), 8, "recalled")])
    lines = "\n".join(raw.hex() for raw in (ros1.encode_lookup_goal(GOAL),
                                            ros1.encode_lookup_result(RESULT), status))
    try:
        done = subprocess.run(["/usr/bin/python3", "-c", _GENPY], input=lines, text=True,
                              capture_output=True, timeout=60, check=False)
    except OSError as err:
        pytest.skip(f"no Debian python3: {err}")
    if done.returncode != 0:
        pytest.skip(f"python3-tf2-msgs is not installed: {done.stderr.strip()[-200:]}")
    assert done.stdout.splitlines() == [
        "11000000002 g-1 9000000004 3 done 1700000000123456789 odom base_link -2.5 0.6 3 "
        "'extrapolation into the future'",
        "12000000000 [('g-1', 9000000004, 1, ''), ('g-2', 8000000000, 8, 'recalled')]",
    ]


# -- the LookupTransform action on ROS 2 (CDR) ----------------------------------------------

UUID_TEXT = "6ba7b810-9dad-11d1-80b4-00c04fd430c8"  # RFC 4122 appendix C's DNS namespace
CDR_GOAL = LookupTransformGoal("map", "laser", Time(5, 7), 1.5, Time(6), "odom", True,
                               UUID_TEXT)
CDR_RESULT = LookupTransformResult(TS[0], 3, "extrapolation into the future", status=4)


def test_cdr_lookup_goal_and_result_round_trip_and_refuse_damage() -> None:
    raw_goal, raw_result = cdr.encode_lookup_goal(CDR_GOAL), cdr.encode_lookup_result(CDR_RESULT)
    assert cdr.decode_lookup_goal(raw_goal) == CDR_GOAL
    assert cdr.decode_lookup_result(raw_result) == CDR_RESULT
    # the goal id as 32 hex digits is the same UUID; fields the message lacks are dropped
    undashed = CDR_GOAL._replace(goal_id=UUID_TEXT.replace("-", ""), goal_stamp=Time(9))
    assert cdr.encode_lookup_goal(undashed) == raw_goal
    assert cdr.encode_lookup_result(CDR_RESULT._replace(goal_id="g", stamp=Time(3))) \
        == raw_result
    assert raw_goal[:4] == b"\x00\x01\x00\x00" and raw_goal[4:20] == bytes.fromhex(
        UUID_TEXT.replace("-", ""))
    for raw, decode in ((raw_goal, cdr.decode_lookup_goal),
                        (raw_result, cdr.decode_lookup_result)):
        for cut in range(len(raw) - 3):  # the last bytes may be padding
            with pytest.raises(WireDecodeError):
                decode(raw[:cut])
    with pytest.raises(WireEncodeError, match="goal_id must be a UUID"):
        cdr.encode_lookup_goal(CDR_GOAL._replace(goal_id="g-1"))
    with pytest.raises(WireEncodeError, match="source_time"):
        cdr.encode_lookup_goal(CDR_GOAL._replace(source_time=Time(2**31)))
    with pytest.raises(WireEncodeError, match="timeout"):
        cdr.encode_lookup_goal(CDR_GOAL._replace(timeout=float("nan")))
    with pytest.raises(WireEncodeError, match="NUL"):
        cdr.encode_lookup_result(CDR_RESULT._replace(error_string="a\0b"))


def test_cdr_lookup_messages_are_the_action_samples_without_the_request_identity() -> None:
    """rmw_cyclonedds_cpp's samples (:mod:`tfbus.codecs.lookup_action_cdr`) are the same
    bytes with the 16-byte request identity after the encapsulation header."""
    rid = lookup_action_cdr.RequestId(0x0102030405060708, 42)
    identity = struct.pack("<Qq", rid.guid, rid.seq)
    goal = lookup_action_cdr.LookupGoal(bytes.fromhex(UUID_TEXT.replace("-", "")), "map",
                                        "laser", Time(5, 7), 1.5, Time(6), "odom", True)
    sample = lookup_action_cdr.encode_send_goal_request(rid, goal)
    raw = cdr.encode_lookup_goal(CDR_GOAL)
    assert sample == raw[:4] + identity + raw[4:]
    result = lookup_action_cdr.LookupResult(4, TS[0], 3, "extrapolation into the future")
    sample = lookup_action_cdr.encode_get_result_response(rid, result)
    raw = cdr.encode_lookup_result(CDR_RESULT)
    assert sample == raw[:4] + identity + raw[4:]


_ACTION_MSGS = {
    "tf2_msgs/msg/LookupTransformGoal": """string target_frame
string source_frame
builtin_interfaces/Time source_time
builtin_interfaces/Duration timeout
builtin_interfaces/Time target_time
string fixed_frame
bool advanced""",
    "tf2_msgs/msg/LookupTransformSendGoalRequest": """unique_identifier_msgs/UUID goal_id
tf2_msgs/LookupTransformGoal goal""",
    "tf2_msgs/msg/LookupTransformResult": """geometry_msgs/TransformStamped transform
tf2_msgs/TF2Error error""",
    "tf2_msgs/msg/LookupTransformGetResultResponse": """int8 status
tf2_msgs/LookupTransformResult result""",
}


def test_cdr_lookup_messages_equal_rosbags_serialize_cdr() -> None:
    """rosbags' generic CDR serialiser, given ``LookupTransform.action``'s fields
    (tf2_msgs, rosidl's ``SendGoal_Request`` / ``GetResult_Response`` layout), writes the
    same bytes, and its bytes decode to the same values."""
    pytest.importorskip("rosbags")
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    for name, text in _ACTION_MSGS.items():
        store.register(get_types_from_msg(text, name))
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"]
    goal = t["tf2_msgs/msg/LookupTransformGoal"](
        target_frame="map", source_frame="laser", source_time=stamp(sec=5, nanosec=7),
        timeout=t["builtin_interfaces/msg/Duration"](sec=1, nanosec=500_000_000),
        target_time=stamp(sec=6, nanosec=0), fixed_frame="odom", advanced=True)
    uuid = t["unique_identifier_msgs/msg/UUID"](
        uuid=np.frombuffer(bytes.fromhex(UUID_TEXT.replace("-", "")), dtype=np.uint8))
    request = t["tf2_msgs/msg/LookupTransformSendGoalRequest"](goal_id=uuid, goal=goal)
    expected = bytes(store.serialize_cdr(  # type: ignore[attr-defined]
        request, "tf2_msgs/msg/LookupTransformSendGoalRequest"))
    ours = cdr.encode_lookup_goal(CDR_GOAL)
    assert ours[:len(expected)] == expected and set(ours[len(expected):]) <= {0}
    assert cdr.decode_lookup_goal(expected) == CDR_GOAL

    ts = TS[0]
    tr = ts.transform
    msg_ts = t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=stamp(sec=1_700_000_000, nanosec=123_456_789),
                                        frame_id="odom"),
        child_frame_id="base_link",
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=tr.translation.x, y=tr.translation.y,
                                                       z=tr.translation.z),
            rotation=t["geometry_msgs/msg/Quaternion"](x=tr.rotation.x, y=tr.rotation.y,
                                                       z=tr.rotation.z, w=tr.rotation.w)))
    result = t["tf2_msgs/msg/LookupTransformResult"](
        transform=msg_ts,
        error=t["tf2_msgs/msg/TF2Error"](error=3, error_string="extrapolation into the future"))
    response = t["tf2_msgs/msg/LookupTransformGetResultResponse"](status=4, result=result)
    expected = bytes(store.serialize_cdr(  # type: ignore[attr-defined]
        response, "tf2_msgs/msg/LookupTransformGetResultResponse"))
    ours = cdr.encode_lookup_result(CDR_RESULT)
    assert ours[:len(expected)] == expected and set(ours[len(expected):]) <= {0}
    assert cdr.decode_lookup_result(expected) == CDR_RESULT
