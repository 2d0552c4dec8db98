"""Every wire decoder under mutated input (hypothesis, derandomized, bounded).

Each property starts from a valid encoded message (tfbus's own Zenoh wire format, CDR as
rmw_zenoh and DDS carry it, ROS 1's TCPROS serialization), mutates it the way a broken or
hostile peer would (bits flipped, cut short, extended, a length field replaced by 0, 2**31,
2**32 - 1 or one past the end, a slice deleted or repeated) and decodes it. The decoder
either returns a value of its type or raises its documented error (``WireError`` and its
subclasses; ``ValueError`` for TCPROS connection headers and framing), never anything else,
and never allocates in proportion to a length it was told rather than the bytes it got
(traced peak under 8 MiB for payloads of a few hundred bytes). What decodes goes on: every
transform into a ``BufferCore`` (stored or refused with ``InvalidArgumentException``),
every ``/clock`` a ``Time`` in range. ROS 1's compiled decoder and its pure twin give the
same verdict on every input. Covered: TFMessage, ``rosgraph_msgs/Clock``, LaserScan and
the ``LookupTransform`` goal of each codec, the ROS 2 action's ``SendGoal`` request, TCPROS
connection headers and frame splitting, rmw_zenoh attachments and liveliness tokens, and
the key expressions a Zenoh peer may publish on (tfbus's bus and fleet keys).
"""

from __future__ import annotations

import itertools
import struct
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tfbus import BufferCore, Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.codecs import cdr, lookup_action_cdr, native, ros1
from tfbus.errors import InvalidArgumentException, WireError
from tfbus.messages import Clock, LookupTransformGoal, TFMessage
from tfbus.sensor_msgs import LaserScan
from tfbus.time import TIME_MAX_NS
from tfbus.transports.rmw_zenoh import wire as rmw
from tfbus.transports.ros1.tcpros import FrameSplitter, decode_header, encode_header, frame
from tfbus.transports.zenoh.fleet_keys import FleetKeySpace
from tfbus.transports.zenoh.keys import KeySpace, parse_topic_key, topic_key

FUZZ = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
PEAK_BYTES = 8 * 1024 * 1024
ABSURD = (0, 2**31, 2**32 - 1, 2**31 - 1, 1 << 24)


def _ts(parent: str, child: str, sec: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time(sec, 250), parent), child,
                            Transform(Vector3(x, -2.5, 0.125), Quaternion(0.0, 0.0, 0.6, 0.8)))


TF = TFMessage((_ts("map", "odom", 7, 1.0), _ts("odom", "base_link", 8, 2.0),
                _ts("base_link", "läser/ü", 9, 3.0)))
CLOCK = Clock(Time(1_700_000_000, 123_456_789))
SCAN = LaserScan(header=Header(Time(5, 0), "base_laser"), angle_min=-1.0, angle_max=1.0,
                 angle_increment=0.5, time_increment=0.0, scan_time=0.1, range_min=0.1,
                 range_max=10.0, ranges=np.arange(5, dtype=np.float32),
                 intensities=np.ones(5, dtype=np.float32))
GOAL = LookupTransformGoal("map", "base_link", Time(12, 5), 2.5, Time(11, 0), "odom", True,
                           "0123456789abcdef0123456789abcdef", Time(13, 0))


@st.composite
def mutated(draw: st.DrawFn, valid: bytes) -> bytes:
    """``valid`` after 1-4 mutations of a broken or hostile peer."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 4))):
        n = len(data)
        op = draw(st.sampled_from(["flip", "cut", "extend", "length", "delete", "repeat", "byte"]))
        if op == "cut":
            del data[draw(st.integers(0, n)):]
        elif op == "extend":
            data += draw(st.binary(max_size=48))
        elif not n:
            continue
        elif op == "flip":
            data[draw(st.integers(0, n - 1))] ^= 1 << draw(st.integers(0, 7))
        elif op == "byte":
            data[draw(st.integers(0, n - 1))] = draw(st.integers(0, 255))
        elif op == "length" and n >= 4:
            at = draw(st.integers(0, n - 4))
            value = draw(st.sampled_from([*ABSURD, n, n + 1, n - at]))
            data[at:at + 4] = (value % 2**32).to_bytes(4, "little")
        elif op in ("delete", "repeat"):
            a = draw(st.integers(0, n - 1))
            b = draw(st.integers(a, min(n, a + 16)))
            if op == "delete":
                del data[a:b]
            else:
                data[b:b] = data[a:b]
    return bytes(data)


@contextmanager
def bounded_memory() -> Iterator[None]:
    """Fail when the body's traced allocation peak passes :data:`PEAK_BYTES`."""
    tracemalloc.start()
    try:
        yield
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < PEAK_BYTES, f"decoding allocated {peak} bytes"


def _decode(decode: Callable[[bytes], Any], data: bytes, kind: type,
            errors: tuple[type[BaseException], ...] = (WireError,)) -> Any:
    """``decode(data)``: a ``kind`` or one of ``errors`` (then None); nothing else."""
    with bounded_memory():
        try:
            out = decode(data)
        except errors:
            return None
    assert isinstance(out, kind), type(out)
    return out


def _stored(message: TFMessage) -> None:
    """Every transform of a decoded message goes into a buffer or is refused by name."""
    core = BufferCore()
    for t in message.transforms:
        assert isinstance(t.header.frame_id, str) and isinstance(t.child_frame_id, str)
        with suppress(InvalidArgumentException):
            core.set_transform(t, "fuzz")


def _native_tf(data: bytes) -> TFMessage:
    return native.decode_tf(data)


ENCODED_TF = {"native": native.encode_tf(TF), "cdr": cdr.encode_tf(TF),
              "ros1": ros1.encode_tf(TF)}
TF_DECODERS: dict[str, Callable[[bytes], TFMessage]] = {
    "native": native.decode_tf, "cdr": cdr.decode_tf, "ros1": ros1.decode_tf}


@pytest.mark.parametrize("codec", sorted(TF_DECODERS))
def test_valid_messages_round_trip(codec: str) -> None:
    assert TF_DECODERS[codec](ENCODED_TF[codec]) == TF


@pytest.mark.parametrize("codec", sorted(TF_DECODERS))
@FUZZ
@given(data=st.data())
def test_mutated_tf_messages_decode_or_raise_wire_errors(codec: str, data: st.DataObject) -> None:
    raw = data.draw(mutated(ENCODED_TF[codec]))
    out = _decode(TF_DECODERS[codec], raw, TFMessage)
    if out is not None:
        _stored(out)


@FUZZ
@given(raw=mutated(ENCODED_TF["ros1"]))
@example(raw=(2**31).to_bytes(4, "little") + ENCODED_TF["ros1"][4:])
@example(raw=ENCODED_TF["ros1"][:-1])
def test_ros1_compiled_decoder_and_its_twin_agree(raw: bytes) -> None:
    compiled = ros1._compiled_decoder()
    if compiled is None:
        pytest.skip("the compiled core is not built here (pure-Python install)")
    outcomes = []
    for decode in (compiled, ros1.decode_ros1_struct):
        try:
            outcomes.append(("ok", decode(raw)))
        except (WireError, ValueError, struct.error) as exc:  # each twin's own failures:
            outcomes.append(("error", type(exc).__name__))  # struct's (compiled), WireError
    assert outcomes[0][0] == outcomes[1][0], outcomes
    if outcomes[0][0] == "ok":
        assert outcomes[0][1] == outcomes[1][1]


CLOCK_CODECS = {"native": (native.encode_clock, native.decode_clock),
                "cdr": (cdr.encode_clock, cdr.decode_clock),
                "ros1": (ros1.encode_clock, ros1.decode_clock)}


@pytest.mark.parametrize("codec", sorted(CLOCK_CODECS))
@FUZZ
@given(data=st.data())
def test_mutated_clock_samples_decode_to_a_time_in_range(codec: str,
                                                          data: st.DataObject) -> None:
    encode, decode = CLOCK_CODECS[codec]
    raw = data.draw(mutated(encode(CLOCK)))
    out = _decode(decode, raw, Clock)
    if out is not None:
        assert isinstance(out.clock, Time) and 0 <= out.clock.ns <= TIME_MAX_NS


SCAN_CODECS = {"native": (native.encode_scan, native.decode_scan),
               "cdr": (cdr.encode_scan, cdr.decode_scan),
               "ros1": (ros1.encode_scan, ros1.decode_scan)}


@pytest.mark.parametrize("codec", sorted(SCAN_CODECS))
@settings(FUZZ, max_examples=80)
@given(data=st.data())
def test_mutated_laser_scans_decode_or_raise_wire_errors(codec: str,
                                                         data: st.DataObject) -> None:
    encode, decode = SCAN_CODECS[codec]
    out = _decode(decode, data.draw(mutated(encode(SCAN))), LaserScan)
    if out is not None:
        assert len(out.ranges) <= 2**16


GOAL_CODECS = {"ros1": (ros1.encode_lookup_goal, ros1.decode_lookup_goal),
               "cdr": (lookup_action_cdr.encode_lookup_goal, lookup_action_cdr.decode_lookup_goal)}


@pytest.mark.parametrize("codec", sorted(GOAL_CODECS))
@FUZZ
@given(data=st.data())
def test_mutated_lookup_goals_decode_or_raise_wire_errors(codec: str,
                                                          data: st.DataObject) -> None:
    encode, decode = GOAL_CODECS[codec]
    out = _decode(decode, data.draw(mutated(encode(GOAL))), LookupTransformGoal)
    if out is not None:
        for name in ("target_frame", "source_frame", "fixed_frame", "goal_id"):
            assert isinstance(getattr(out, name), str)
        for name in ("source_time", "target_time", "goal_stamp"):
            assert 0 <= getattr(out, name).ns <= TIME_MAX_NS
        assert out.timeout >= 0


FRAME_IDS = st.sampled_from(["", "/", "map", "x" * 5000, "\x00", "\x1b[2J", "ü/ß", "\ud800",
                             " base", "a/b/c"]) | st.text(max_size=20)
TIMES = st.sampled_from([0, 1, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**63 - 1]) | st.integers(
    0, 2**63 - 1)
TIMEOUTS = st.sampled_from([0.0, -1.0, 1e-9, 2.0**31, 2.0**63, float("inf"), float("nan"),
                            -0.0, 1e300])


@pytest.mark.parametrize("codec", sorted(GOAL_CODECS))
@FUZZ
@given(target=FRAME_IDS, source=FRAME_IDS, fixed=FRAME_IDS, stamp=TIMES, timeout=TIMEOUTS,
       advanced=st.booleans())
def test_goals_with_any_fields_round_trip_or_are_refused_by_name(
    codec: str, target: str, source: str, fixed: str, stamp: int, timeout: float,
    advanced: bool,
) -> None:
    encode, decode = GOAL_CODECS[codec]
    t = Time.from_ns(min(stamp, TIME_MAX_NS))
    goal = LookupTransformGoal(target, source, t, timeout, t, fixed, advanced, GOAL.goal_id, t)
    try:
        raw = encode(goal)
    except (WireError, ValueError) as exc:  # refused at the sender, naming what
        assert any(name in str(exc) for name in (
            "frame", "time", "timeout", "stamp", "goal", "sec", "UTF", "utf", "NUL")), exc
        return
    back = _decode(decode, raw, LookupTransformGoal)
    assert back is not None, "a goal the codec encoded did not decode"
    assert (back.target_frame, back.source_frame, back.advanced) == (target, source, advanced)
    if advanced:
        assert back.fixed_frame == fixed


def _send_goal_request() -> bytes:
    goal = lookup_action_cdr.LookupGoal(
        goal_id=bytes(range(16)), target_frame="map", source_frame="base_link",
        source_time=Time(3, 0), timeout=1.0, target_time=Time(0), fixed_frame="",
        advanced=False)
    return lookup_action_cdr.encode_send_goal_request(
        lookup_action_cdr.RequestId(0x0123456789ABCDEF, 7), goal)


@FUZZ
@given(raw=mutated(_send_goal_request()))
def test_mutated_send_goal_requests_decode_or_raise_wire_errors(raw: bytes) -> None:
    _decode(lookup_action_cdr.decode_send_goal_request, raw, tuple)


HEADER = encode_header({"callerid": "/talker", "topic": "/tf", "md5sum": ros1.TF_MD5SUM,
                        "type": "tf2_msgs/TFMessage", "latching": "0", "tcp_nodelay": "1"})


@FUZZ
@given(raw=mutated(HEADER[4:]))
@example(raw=b"\xff\xff\xff\xffcallerid=/x")
@example(raw=b"\x03\x00\x00\x00abc")
def test_mutated_connection_headers_parse_or_raise_value_error(raw: bytes) -> None:
    out = _decode(decode_header, raw, dict, (ValueError,))
    if out is not None:
        assert all(isinstance(k, str) and isinstance(v, str) for k, v in out.items())


STREAM = HEADER + b"".join(frame(ros1.encode_tf(TFMessage(TF.transforms[:k]))) for k in (1, 3, 2))


@FUZZ
@given(cuts=st.lists(st.integers(0, len(STREAM)), max_size=12))
def test_frames_split_alike_however_the_stream_is_cut(cuts: list[int]) -> None:
    got: list[bytes] = []
    splitter = FrameSplitter(lambda p: got.append(bytes(p)), first_limit=4096, limit=4096)
    bounds = [0, *sorted(cuts), len(STREAM)]
    for a, b in itertools.pairwise(bounds):
        splitter.feed(memoryview(STREAM)[a:b])
    assert got[0] == HEADER[4:]
    assert [ros1.decode_tf(p) for p in got[1:]] == [
        TFMessage(TF.transforms[:k]) for k in (1, 3, 2)]


@FUZZ
@given(raw=mutated(STREAM), cut=st.integers(1, 64))
def test_mutated_streams_give_frames_or_one_value_error(raw: bytes, cut: int) -> None:
    got: list[bytes] = []
    splitter = FrameSplitter(lambda p: got.append(bytes(p)), first_limit=4096, limit=4096)
    with bounded_memory():
        try:
            for at in range(0, len(raw), cut):
                splitter.feed(raw[at:at + cut])
        except ValueError as exc:
            assert "exceeds the limit" in str(exc)
    assert sum(len(p) + 4 for p in got) <= len(raw)
    for payload in got[1:]:
        _decode(ros1.decode_tf, payload, TFMessage)


ATTACHMENT = rmw.Attachment(sequence_number=42, source_timestamp=1_700_000_000_000_000_000,
                            gid=bytes(range(16)))


@pytest.mark.parametrize("form", [rmw.ATTACHMENT_POSITIONAL, rmw.ATTACHMENT_LABELLED])
@FUZZ
@given(data=st.data())
def test_mutated_attachments_decode_or_raise_wire_errors(form: str, data: st.DataObject) -> None:
    valid = rmw.encode_attachment(ATTACHMENT, form)
    assert rmw.decode_attachment(valid) == ATTACHMENT
    out = _decode(rmw.decode_attachment, data.draw(mutated(valid)), rmw.Attachment)
    if out is not None:
        assert len(out.gid) == rmw.GID_SIZE
        assert -(2**63) <= out.sequence_number < 2**63
        assert -(2**63) <= out.source_timestamp < 2**63


TOKENS = [
    rmw.node_token(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "robot_state_publisher"),
    rmw.endpoint_token(7, "aac3178e146ba6f1fc6e6a4085e77f21", 3, 12, "MP", "/ns", "talker",
                       "/tf", rmw.QosProfile()),
]


@pytest.mark.parametrize("token", TOKENS, ids=["node", "endpoint"])
@FUZZ
@given(data=st.data())
def test_mutated_liveliness_tokens_parse_or_raise_wire_errors(token: str,
                                                              data: st.DataObject) -> None:
    rmw.parse_token(token)  # the valid one parses
    raw = data.draw(mutated(token.encode()))
    key = raw.decode("utf-8", "replace")
    out = _decode(rmw.parse_token, key, rmw.EndpointToken)
    if out is not None:
        assert out.domain_id >= 0


KEY_PARTS = st.sampled_from(["tfbus", "tf", "tf_static", "@alive", "@latch", "robot7", "%",
                             "%41", "t%66", "%zz", "*", "**", "$*", "", "ü", "a b", "@", "x" * 300,
                             "0123abcd", "%C3%A9", "%c3%a9"]) | st.text(max_size=8)
KEYS = st.lists(KEY_PARTS, min_size=1, max_size=7).map("/".join)


@FUZZ
@given(key=KEYS, reply=st.booleans())
@example(key="tfbus/r%31/tf", reply=False)
@example(key="tfbus/robot7/@latch/node/tf", reply=True)
def test_any_key_a_peer_publishes_on_maps_to_one_topic_or_none(key: str, reply: bool) -> None:
    """Keys a Zenoh peer may publish or declare liveliness on: a topic only for the one
    canonical spelling of it (so access rules on keys cannot be bypassed), else None."""
    topic = parse_topic_key(key)
    if topic is not None:
        assert topic_key(topic) == key
    for space in (KeySpace(), KeySpace(namespace="robot7"), FleetKeySpace()):
        found = space.topic_of(key, reply)
        assert found is None or (isinstance(found, str) and found.startswith("/"))
        if found is not None and not reply:
            assert space.data(found) == key
        alive = space.parse_alive(key)
        assert alive is None or isinstance(alive.node_id, str)
