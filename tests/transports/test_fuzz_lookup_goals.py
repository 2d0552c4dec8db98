"""Fuzzing ``LookupTransform`` goals (tf2_ros ``buffer_server``) on every server of tfbus:
the ROS 1 action server (:mod:`tfbus.transports.ros1.action`, driven through its
:class:`~tfbus.transports.ros1.action.RawTopicNode` handlers, as its transport calls
them), the ROS 2 action server's lookup (:mod:`tfbus.transports.ros2.action`) and the
Zenoh buffer server's request handler (:mod:`tfbus.transports.zenoh.lookups`).

Goals carry random frame ids (huge, empty, any Unicode, control characters, lone
surrogates where a str can hold them, bytes that are not UTF-8 where only bytes can),
times (0, huge, past what the wire carries) and timeouts (negative, huge, 2**63, NaN,
None), plain and fixed-frame (``advanced``). Asserted: every goal is answered with a
result carrying tf2's error code for it (``tf2_msgs/TF2Error``: the code of the error the
buffer itself raises for that lookup, :func:`~tfbus.errors.tf2_error_code`) or refused
as malformed (counted); nothing raises out of a server; no wait outlives the goal's
bounded timeout (the buffer runs on a :class:`~tfbus.clock.ManualClock`, advanced past
``max_wait``; every test is under a wall-clock bound); a valid goal afterwards gets the
known transform. The live burst over Zenoh is in ``test_fuzz_zenoh.py``.
Deterministic (``derandomize=True``); asyncio and trio.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import anyio
import pytest
from fuzz_support import fuzz
from hypothesis import given
from hypothesis import strategies as st

from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.codecs import ros1
from tfbus.codecs.lookup_action_cdr import LookupGoal
from tfbus.errors import (
    TransformException,
    WireDecodeError,
    tf2_error_code,
)
from tfbus.messages import (
    Header,
    LookupTransformGoal,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time
from tfbus.transports.ros1.action import LookupActionServer as Ros1Server

WALL = 20.0  # seconds: the wall-clock bound of one example (never reached when it passes)
MAX_WAIT = 30.0  # the servers' max_wait (seconds of the buffer's clock)


def _ts(parent: str, child: str, sec: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time(sec), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def filled_buffer() -> tuple[Buffer, ManualClock]:
    """map -> odom static (x 1), odom -> base_link at 10 s (x 10) and 11 s (x 11)."""
    clock = ManualClock(Time(100))
    buf = Buffer(clock=clock)
    buf.set_transform_static(_ts("map", "odom", 0, 1.0), "test")
    for sec in (10, 11):
        buf.set_transform(_ts("odom", "base_link", sec, float(sec)), "test")
    return buf, clock


VALID = LookupTransformGoal("map", "base_link", Time(10, 500_000_000), 1.0, Time(0), "", False,
                            "valid-goal", Time(0))
"""A goal with a known answer: map -> base_link at 10.5 s is x = 1 + 10.5 = 11.5."""

# -- goals ---------------------------------------------------------------------------------

_KNOWN = ["map", "odom", "base_link"]
frames_on_the_wire = st.one_of(
    st.sampled_from([*_KNOWN, "", "/map", "map ", " ", "x" * 5000, "ü" * 300, "\x00",
                     "a\x00b", "\n\t\r\x1b", "\u202e", "\U0001f600"]),
    st.text(max_size=16),  # any Unicode a str can carry on UTF-8 (no surrogates)
    st.text(alphabet=st.characters(max_codepoint=0x1f), max_size=4),  # control chars
)
"""Frame ids a peer can put on a wire that carries UTF-8."""
frames_in_process = st.one_of(
    frames_on_the_wire,
    st.text(alphabet=st.characters(categories=["Cs"]), min_size=1, max_size=3),
    st.sampled_from(["ma\ud800p", "\udfff"]),
)
"""... and what only a str in this process can hold: lone surrogates."""
ros1_times = st.one_of(st.just(Time(0)), st.sampled_from([Time(10, 500_000_000), Time(11)]),
                       st.integers(0, 2**32 - 1).map(Time))
ros1_timeouts = st.one_of(st.sampled_from([0.0, -1.0, -(2.0**31), 1e-9, 2.0, 2.0**31 - 1]),
                          st.floats(-(2.0**31), 2.0**31 - 1))
"""What a ROS 1 duration (int32 seconds) carries: negative (read as 0, as tf2_ros waits no
time then) up to 68 years."""
timeouts = st.one_of(ros1_timeouts, st.sampled_from([1e300, float(2**63)]),
                     st.floats(0.0, 1e12))
"""... and what the ROS 2 server may hold (a Duration of 2**31 s or more is "forever")."""


@st.composite
def goals(draw: st.DrawFn, frames: st.SearchStrategy[str] = frames_on_the_wire,
          times: st.SearchStrategy[Time] = ros1_times,
          waits: st.SearchStrategy[float] = ros1_timeouts) -> LookupTransformGoal:
    """A goal of ``frames`` (target, source, fixed: often a known one), ``times`` and
    ``waits``, plain or fixed-frame, with a goal id."""
    frame = st.one_of(st.sampled_from(_KNOWN), frames)
    return LookupTransformGoal(
        draw(frame), draw(frame), draw(times), draw(waits), draw(times), draw(frame),
        draw(st.booleans()), draw(st.text(max_size=20).map(lambda s: "g" + s)), Time(0))


def tf2_answer(buf: Buffer, g: LookupTransformGoal) -> tuple[TransformStamped | None, int]:
    """What tf2_ros's buffer_server answers once the goal's timeout has expired: the
    lookup's own transform, or its error's ``TF2Error`` code (``checkTransforms``)."""
    try:
        if g.advanced:
            ts = buf.lookup_transform_full(g.target_frame, g.target_time, g.source_frame,
                                           g.source_time, g.fixed_frame)
        else:
            ts = buf.lookup_transform(g.target_frame, g.source_frame, g.source_time)
    except TransformException as exc:
        return None, tf2_error_code(exc)
    return ts, 0


# -- ROS 1: goal bytes and the action server ----------------------------------------------


class _Node:
    """The two sides of :class:`~tfbus.transports.ros1.action.RawTopicNode` the server
    uses, in memory: the handlers it subscribes, the payloads it sends."""

    node_name = "/fuzz"

    def __init__(self) -> None:
        self.handlers: dict[str, Callable[[bytes, str], None]] = {}
        self.sent: dict[str, list[bytes]] = {}

    def subscribe_raw(self, topic: str, msg_type: str, md5: str,
                      handler: Callable[[bytes, str], None]) -> None:
        self.handlers[topic] = handler

    def advertise_raw(self, topic: str, msg_type: str, md5: str) -> None:
        self.sent.setdefault(topic, [])

    def send_raw_nowait(self, topic: str, payload: bytes) -> None:
        self.sent[topic].append(payload)

    def connections(self, topic: str) -> tuple[int, int]:
        return (1, 1)


GOAL, CANCEL, RESULT = ("/tf2_buffer_server/goal", "/tf2_buffer_server/cancel",
                        "/tf2_buffer_server/result")


def _not_utf8(raw: bytes, frame: str) -> bytes:
    """``raw`` (a serialised goal) with the bytes of ``frame`` replaced by a lone
    surrogate's CESU/"WTF-8" bytes, ED A0 80: what a peer writing surrogates sends."""
    old = len(frame.encode()).to_bytes(4, "little") + frame.encode()
    return raw.replace(old, (3).to_bytes(4, "little") + b"\xed\xa0\x80", 1)


async def _ros1_answers(goal_payloads: list[bytes], cancels: tuple[bytes, ...] = ()
                        ) -> tuple[list[Any], Any, Buffer]:
    """Send the goals (and cancel requests) to a ROS 1 server, then ``VALID``; advance the
    buffer's clock past ``max_wait``: (the results it sent, its statistics, the buffer)."""
    buf, clock = filled_buffer()
    node = _Node()
    with anyio.fail_after(WALL):
        async with Ros1Server(node, buf, max_wait=MAX_WAIT) as server:
            for raw in goal_payloads:
                node.handlers[GOAL](raw, "/peer")
            for raw in cancels:
                node.handlers[CANCEL](raw, "/peer")
            node.handlers[GOAL](ros1.encode_lookup_goal(VALID), "/peer")
            await clock.advance(MAX_WAIT + 1.0)
            stats = server.statistics()
    return [ros1.decode_lookup_result(r) for r in node.sent[RESULT]], stats, buf


def _check_valid_answered(results: list[Any]) -> None:
    valid = [r for r in results if r.goal_id == VALID.goal_id]
    assert len(valid) == 1 and valid[0].status == 3 and valid[0].error == 0
    assert valid[0].transform.transform.translation.x == pytest.approx(11.5)
    assert valid[0].transform.header.frame_id == "map"


@fuzz(120)
@given(goal=goals(), mangle=st.sampled_from(["none", "target", "fixed"]))
def test_ros1_server_answers_every_goal_with_tf2s_code(anyio_backend: str,
                                                      goal: LookupTransformGoal,
                                                      mangle: str) -> None:
    """A random goal (or one whose frame id is not UTF-8) is answered with SUCCEEDED and
    tf2's code for it, or counted malformed; the valid goal after it gets x = 11.5."""
    goal = goal._replace(goal_id=goal.goal_id[:200])
    raw = ros1.encode_lookup_goal(goal)
    if mangle != "none":
        raw = _not_utf8(raw, goal.target_frame if mangle == "target" else goal.fixed_frame)
    results, stats, buf = anyio.run(_ros1_answers, [raw], backend=anyio_backend)
    _check_valid_answered(results)
    answers = [r for r in results if r.goal_id != VALID.goal_id]
    try:
        decoded = ros1.decode_lookup_goal(raw)
    except WireDecodeError:
        assert answers == [] and stats.malformed == 1
        return
    if decoded.goal_id == VALID.goal_id:
        return  # the same id as the valid goal: actionlib ignores the second
    assert len(answers) == 1 and answers[0].status == 3
    ts, code = tf2_answer(buf, decoded)
    assert answers[0].error == code
    if ts is not None:
        assert answers[0].transform == ts
    assert (stats.requests, stats.malformed, stats.pending) == (2, 0, 0)


def _mutants(valid: bytes) -> st.SearchStrategy[bytes]:
    """``valid`` with a bit flipped, cut short, extended, or a uint32 length (at any
    offset) replaced by an absurd one."""
    n = len(valid)
    return st.one_of(
        st.tuples(st.integers(0, n - 1), st.integers(0, 7)).map(
            lambda t: valid[:t[0]] + bytes([valid[t[0]] ^ (1 << t[1])]) + valid[t[0] + 1:]),
        st.integers(0, n - 1).map(lambda k: valid[:k]),
        st.binary(min_size=1, max_size=16).map(lambda b: valid + b),
        st.tuples(st.integers(0, n - 4), st.sampled_from(
            [b"\xff\xff\xff\xff", b"\xff\xff\xff\x7f", b"\x00\x00\x00\x80"])).map(
            lambda t: valid[:t[0]] + t[1] + valid[t[0] + 4:]),
    )


_ADVANCED = ros1.encode_lookup_goal(LookupTransformGoal(
    "base_link", "base_link", Time(11), 2.5, Time(10), "odom", True, "g-full", Time(4)))


@fuzz(120)
@given(raw=_mutants(_ADVANCED))
def test_ros1_server_survives_mutated_goal_bytes(anyio_backend: str, raw: bytes) -> None:
    """Mutants of a fixed-frame goal's bytes: each answered (tf2's code) or counted as
    malformed, and the valid goal after it answered."""
    results, stats, buf = anyio.run(_ros1_answers, [raw], backend=anyio_backend)
    _check_valid_answered(results)
    try:
        decoded = ros1.decode_lookup_goal(raw)
    except WireDecodeError:
        assert stats.malformed == 1 and len(results) == 1
        return
    if len(decoded.goal_id.encode()) > 1024 or decoded.goal_id == VALID.goal_id:
        return
    answer = [r for r in results if r.goal_id == decoded.goal_id]
    assert len(answer) == 1
    assert answer[0].error == tf2_answer(buf, decoded)[1]


_CANCEL = ros1.encode_goal_id(Time(4), "g-full")


@fuzz(100)
@given(raw=_mutants(_CANCEL))
def test_ros1_server_survives_mutated_cancel_requests(anyio_backend: str, raw: bytes) -> None:
    """Mutants of an ``actionlib_msgs/GoalID`` cancel request sent after a fixed-frame
    goal: the goal is answered (SUCCEEDED) or PREEMPTED by a cancel that still names it,
    a cancel that does not decode is counted malformed, and the valid goal after them is
    answered."""
    results, stats, _buf = anyio.run(_ros1_answers, [_ADVANCED], (raw,),
                                     backend=anyio_backend)
    _check_valid_answered(results)
    full = [r for r in results if r.goal_id == "g-full"]
    assert len(full) == 1 and full[0].status in (2, 3)  # PREEMPTED or SUCCEEDED
    try:
        ros1.decode_goal_id(raw)
    except WireDecodeError:
        assert stats.malformed == 1 and full[0].status == 3
    else:
        assert stats.malformed == 0


# -- ROS 2: the action server's lookup of a decoded goal ------------------------------------

ros2_times = st.one_of(st.just(Time(0)), st.sampled_from([Time(10, 500_000_000), Time(11)]),
                       st.integers(0, 2**31 - 1).map(Time))


@fuzz(150)
@given(goal=goals(frames_in_process, ros2_times, timeouts))
def test_ros2_server_lookup_gives_tf2s_code(anyio_backend: str,
                                            goal: LookupTransformGoal) -> None:
    """The ROS 2 server's answer to a goal (any frame ids, lone surrogates included, any
    timeout it may hold: capped by ``max_wait``): tf2's code and transform, never an
    exception, and within the timeout."""
    pytest.importorskip("cyclonedds")
    from tfbus.transports.ros2.action import LookupActionServer as Ros2Server

    g = LookupGoal(bytes(16), goal.target_frame, goal.source_frame, goal.source_time,
                   max(0.0, goal.timeout), goal.target_time, goal.fixed_frame, goal.advanced)

    async def main() -> Any:
        buf, clock = filled_buffer()
        server = Ros2Server(_NoParticipant(), buf, max_wait=MAX_WAIT)
        with anyio.fail_after(WALL):
            async with anyio.create_task_group() as tg:
                box: list[Any] = []

                async def ask() -> None:
                    box.append(await server._lookup(g, min(g.timeout, MAX_WAIT)))

                tg.start_soon(ask)
                await clock.advance(MAX_WAIT + 1.0)
        return box[0], buf

    result, buf = anyio.run(main, backend=anyio_backend)
    ts, code = tf2_answer(buf, goal._replace(timeout=0.0))
    assert (result.status, result.error) == (4, code)
    if ts is not None:
        assert result.transform == ts


class _NoParticipant:
    """A ROS 2 transport stand-in: the lookup itself touches no DDS entity."""

    def participant(self) -> Any:
        raise AssertionError("the lookup must not touch DDS")

    def on_close(self, callback: Callable[[], None]) -> None:
        raise AssertionError("the lookup must not touch DDS")


# -- Zenoh: the buffer server's request handler ----------------------------------------------

_NUMBERS = st.one_of(st.integers(-2**70, 2**70), st.floats(), st.none(), st.booleans(),
                     st.sampled_from([2**63, 2**63 - 1, -1, 0, float("inf"), float("nan")]))
_VALUES = st.one_of(frames_in_process, _NUMBERS, st.lists(st.integers(), max_size=3),
                    st.binary(max_size=4))
_OPS = st.sampled_from(["lookup", "full", "can"])
zenoh_requests = st.one_of(
    # well-typed requests with hostile values
    st.fixed_dictionaries(
        {"op": _OPS, "target": frames_in_process, "source": frames_in_process,
         "fixed": frames_in_process, "time": st.integers(-5, 2**64),
         "target_time": st.integers(-5, 2**64), "source_time": st.integers(-5, 2**64),
         "timeout": st.one_of(st.none(), st.floats(), st.integers(-2**64, 2**64))},
        optional={"fail_fast": st.booleans(),
                  "policy": st.lists(st.one_of(st.sampled_from(
                      ["nearest", "clamp", "previous", "window"]), st.integers(-5, 2**64)),
                      min_size=3, max_size=3)}),
    # any field of any type, any field missing
    st.fixed_dictionaries({"op": st.one_of(_OPS, _VALUES)}, optional={
        k: _VALUES for k in ("target", "source", "time", "target_time", "source_time",
                             "fixed", "timeout", "fail_fast", "policy", "id",
                             "query_timeout")}),
)


@fuzz(150)
@given(request=zenoh_requests)
def test_zenoh_server_answers_every_request(anyio_backend: str,
                                            request: dict[str, Any]) -> None:
    """The Zenoh server's handler on a decoded request: an answer (a transform, a
    ``{"can": bool}``) or a TransformException (sent as ``{"error": ...}``), never
    another exception, within ``max_wait`` of the buffer's clock; a request naming a
    bad field gets InvalidArgumentException naming it; a well-formed lookup answers
    what the buffer answers."""
    pytest.importorskip("zenoh")
    from tfbus.bus import Bus
    from tfbus.errors import InvalidArgumentException
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.lookups import BufferServer

    async def main() -> tuple[Any, Buffer]:
        buf, clock = filled_buffer()
        bus = Bus(transport=ZenohTransport(listen="tcp/127.0.0.1:0"))  # never opened
        server = BufferServer(buf, bus, max_wait=MAX_WAIT)
        box: list[Any] = []
        with anyio.fail_after(WALL):
            async with anyio.create_task_group() as tg:

                async def ask() -> None:
                    try:
                        box.append(await server._run(request, MAX_WAIT))
                    except TransformException as exc:
                        box.append(exc)

                tg.start_soon(ask)
                await clock.advance(MAX_WAIT + 1.0)
        return box[0], buf

    answer, buf = anyio.run(main, backend=anyio_backend)
    if isinstance(answer, InvalidArgumentException) and "request field" in str(answer):
        name = str(answer).split("'")[1]
        assert name in request or name in ("target", "source", "time", "fixed",
                                           "target_time", "source_time")
        return
    if request.get("op") == "lookup" and "policy" not in request and \
            not request.get("fail_fast"):
        try:
            expected: Any = buf.lookup_transform(request["target"], request["source"],
                                                 Time.from_ns(request["time"]))
        except TransformException as exc:
            expected = exc
        if isinstance(expected, TransformException):
            assert type(answer) is type(expected) and str(answer) == str(expected)
        else:
            assert answer == expected


@pytest.mark.parametrize("timeout", [None, 2**63, float("inf"), 1e300, -1.0, float("nan")])
def test_zenoh_server_bounds_or_refuses_every_timeout(anyio_backend: str,
                                                      timeout: float | None) -> None:
    """A lookup that cannot be answered and a timeout of None, 2**63 s, inf or 1e300 s
    waits ``max_wait`` of the buffer's clock, then gets the lookup's own error
    (LookupException: tf2's message); a negative or NaN timeout is refused naming it."""
    pytest.importorskip("zenoh")
    from tfbus.bus import Bus
    from tfbus.errors import InvalidArgumentException, LookupException
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.lookups import BufferServer

    request = {"op": "lookup", "target": "map", "source": "nowhere", "time": 0,
               "timeout": timeout}

    async def main() -> tuple[BaseException, Time]:
        buf, clock = filled_buffer()
        server = BufferServer(buf, Bus(transport=ZenohTransport(listen="tcp/127.0.0.1:0")),
                              max_wait=MAX_WAIT)
        box: list[tuple[BaseException, Time]] = []

        async def ask() -> None:
            try:
                await server._run(request, MAX_WAIT)
            except TransformException as exc:
                box.append((exc, clock.now()))

        with anyio.fail_after(WALL):
            async with anyio.create_task_group() as tg:
                tg.start_soon(ask)
                await clock.advance(MAX_WAIT + 1.0)
        return box[0]

    exc, ended = anyio.run(main, backend=anyio_backend)
    if timeout is not None and (math.isnan(timeout) or timeout < 0):
        assert type(exc) is InvalidArgumentException
        assert "request field 'timeout' has an invalid value" in str(exc)
        assert ended == Time(100)  # refused at once
    else:
        assert type(exc) is LookupException and '"nowhere"' in str(exc)
        assert ended == Time(100 + int(MAX_WAIT))  # waited max_wait, not the timeout


# -- regression: the minimal input the fuzzing found -------------------------------------------


@pytest.mark.parametrize(("target", "source"), [("map ", ""), ("nowhere", "/odom")])
def test_unknown_target_with_an_invalid_source_is_tf2s_lookup_error(
        anyio_backend: str, target: str, source: str) -> None:
    """tf2's ``lookupTransform`` checks the target frame (it does not exist:
    LookupException, code 1) before the source (empty, or a leading ``/``:
    InvalidArgumentException, code 4), and tf2_ros's buffer_server answers with it. The
    servers answered 4: the awaited lookup checks every argument first."""
    goal = LookupTransformGoal(target, source, Time(0), 0.0, Time(0), "", False, "g", Time(0))
    message = f'"{target}" passed to lookupTransform argument target_frame does not exist. '
    results, stats, _ = anyio.run(_ros1_answers, [ros1.encode_lookup_goal(goal)],
                                  backend=anyio_backend)
    answer = [r for r in results if r.goal_id == "g"]
    assert (answer[0].status, answer[0].error, answer[0].error_string) == (3, 1, message)
    assert (stats.requests, stats.errors, stats.answered) == (2, 1, 1)

    pytest.importorskip("cyclonedds")
    from tfbus.transports.ros2.action import LookupActionServer as Ros2Server

    async def ros2() -> Any:
        buf, _clock = filled_buffer()
        return await Ros2Server(_NoParticipant(), buf)._lookup(
            LookupGoal(bytes(16), target, source, Time(0), 0.0, Time(0), "", False), 0.0)

    result = anyio.run(ros2, backend=anyio_backend)
    assert (result.status, result.error, result.error_string) == (4, 1, message)

    pytest.importorskip("zenoh")
    from tfbus.bus import Bus
    from tfbus.errors import LookupException
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.lookups import BufferServer

    async def zenoh() -> None:
        buf, _clock = filled_buffer()
        server = BufferServer(buf, Bus(transport=ZenohTransport(listen="tcp/127.0.0.1:0")))
        request = {"op": "lookup", "target": target, "source": source, "time": 0,
                   "timeout": 5.0}
        with pytest.raises(LookupException) as raised:
            await server._run(request, MAX_WAIT)
        assert str(raised.value) == message

    anyio.run(zenoh, backend=anyio_backend)


@pytest.mark.parametrize("argument", ["target_frame", "source_frame", "fixed_frame"])
def test_zenoh_client_names_a_frame_id_it_cannot_send(anyio_backend: str,
                                                      argument: str) -> None:
    """A lone surrogate in a frame id (a str can hold one, UTF-8 cannot carry it) made
    the Zenoh client's lookup raise msgspec's "can't encode character" as a
    WireEncodeError naming no argument; it names the argument and the value (and the
    goal encoders of ROS 1 and ROS 2 do likewise: ``tests/codecs/test_fuzz_wire.py``)."""
    pytest.importorskip("zenoh")
    from tfbus.bus import Bus
    from tfbus.errors import WireEncodeError
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.lookups import BufferClient

    frames = {"target_frame": "map", "source_frame": "base", "fixed_frame": "odom",
              argument: "ma\ud800p"}

    async def main() -> None:
        client = BufferClient(Bus(transport=ZenohTransport(listen="tcp/127.0.0.1:0")))
        with pytest.raises(WireEncodeError, match=rf"^{argument} 'ma\\ud800p' cannot be sent"):
            await client.lookup_transform_full(frames["target_frame"], Time(0),
                                               frames["source_frame"], Time(0),
                                               frames["fixed_frame"], 1.0)
        if argument != "fixed_frame":
            with pytest.raises(WireEncodeError, match=rf"^{argument} 'ma\\ud800p'"):
                await client.lookup_transform(frames["target_frame"],
                                              frames["source_frame"], Time(0), 1.0)

    anyio.run(main, backend=anyio_backend)
