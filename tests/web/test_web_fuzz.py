"""Fuzzing ``tfbus web``'s rosbridge handling: random and mutated client messages.

Many examples go through :class:`~tfbus.web.rosbridge.Session` in-process (what the
server calls for each complete text message of a client): random JSON values, valid ops
of roslibjs / roslibpy with a field deleted, retyped or added, huge strings and numbers,
deep nesting, lone surrogates (``"\\ud800"`` escapes), text cut short. Whatever comes in,
the session answers (nothing raised), every reply can be sent (JSON without NaN, UTF-8),
every transform it publishes can go on a bus (UTF-8 frame ids) and into a
:class:`~tfbus.BufferCore`, and its ticks run. One live test sends a burst of garbage to a
real ``tfbus web`` process on one connection while a second client keeps receiving /tf.

Hypothesis runs derandomized (the same examples on every run) and bounded
(``max_examples``), so the suite stays deterministic and short.
"""

from __future__ import annotations

import copy
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import anyio
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from web_support import BOUND, RawClient

from tfbus import BufferCore, Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.web.rosbridge import MAX_ID, MIN_RATE, Session, transform_to_json

S = 1_000_000_000
ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}

FUZZ = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _ts(x: float, child: str = "base_link", stamp: int = S) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(stamp), "world"), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def _goal() -> dict[str, Any]:
    return {"source_frames": ["base_link", "/odom"], "target_frame": "/world",
            "angular_thres": 0.1, "trans_thres": 0.01, "rate": 10.0}


VALID: list[dict[str, Any]] = [
    {"op": "subscribe", "topic": "/tf", "type": "tf2_msgs/TFMessage"},
    {"op": "subscribe", "topic": "/tf_static", "type": "tf2_msgs/msg/TFMessage", "id": "s1"},
    {"op": "unsubscribe", "topic": "/tf"},
    {"op": "advertise", "topic": "/tf", "type": "tf2_msgs/TFMessage"},
    {"op": "unadvertise", "topic": "/tf"},
    {"op": "publish", "topic": "/tf", "msg": {"transforms": [transform_to_json(_ts(1.0))]}},
    {"op": "publish", "topic": "/tf_static",
     "msg": {"transforms": [transform_to_json(_ts(2.0, "odom"), ros2=True)]}},
    {"op": "subscribe", "topic": "/tf2_web_republisher/feedback"},
    {"op": "publish", "topic": "/tf2_web_republisher/goal",
     "msg": {"goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": "g1"}, "goal": _goal()}},
    {"op": "publish", "topic": "/tf2_web_republisher/cancel", "msg": {"id": "g1"}},
    {"op": "call_service", "service": "/republish_tfs", "id": "c1",
     "args": {**_goal(), "timeout": {"secs": 2, "nsecs": 0}}},
    {"op": "call_service", "service": "/rosapi/topics", "id": "c2"},
    {"op": "send_action_goal", "action": "/tf2_web_republisher", "id": "a1",
     "action_type": "tf2_web_republisher_msgs/action/TFSubscription", "args": _goal()},
    {"op": "cancel_action_goal", "action": "/tf2_web_republisher", "id": "a1"},
    {"op": "set_level", "level": "info"},
]

NUMBER_EDGES: list[Any] = [
    # an integer beyond a double, tiny and huge numbers, int64 and uint32 ends
    10**400, -(10**400), 1e-300, -0.0, 5e-324, 1e-12, 1.7976931348623157e308, 2**63, 2**32,
    -1, 0, 1, 0.5, float("inf"), float("nan"),
]
STRING_EDGES: list[Any] = [
    # lone surrogates, NUL, names served and not, too long
    "\ud800", "a\udfff", "\x00", "", "/", "/tf", "/world", "base_link",
    "x" * (MAX_ID + 1), "tf2_msgs/msg/TFMessage",
]
EDGES: list[Any] = [*NUMBER_EDGES, *STRING_EDGES, True, None, [], {}]
_leaf = (st.none() | st.booleans()
         | st.integers(-(2**64), 2**64)
         | st.floats(allow_nan=True, allow_infinity=True)
         | st.text(max_size=12)
         | st.sampled_from(EDGES).map(copy.deepcopy))  # [] and {} are mutated later
JSON = st.recursive(_leaf, lambda c: st.lists(c, max_size=4)
                    | st.dictionaries(st.text(max_size=10), c, max_size=4), max_leaves=12)


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path (keys / indexes) into a JSON value, the root included."""
    out = [prefix]
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out += _paths(v, (*prefix, i))
    return out


def _at(value: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        value = value[key]
    return value


@st.composite
def mutated(draw: st.DrawFn) -> Any:
    """A valid op with one to three of: a field deleted, its value replaced by any JSON
    value or by an edge value (:data:`EDGES`), a field added."""
    message = json.loads(json.dumps(draw(st.sampled_from(VALID))))
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["delete", "replace", "edge", "edge", "add"]))
        # mostly past the op (a wrong op is refused before anything else is read)
        paths = [p for p in _paths(message) if p[:1] != ("op",)] or [()]
        leaves = [p for p in paths if p and not isinstance(_at(message, p), (dict, list))]
        path = draw(st.sampled_from(leaves if how == "edge" and leaves else paths))
        if not path:
            if how in ("replace", "edge"):
                message = draw(JSON)
            elif how == "add" and isinstance(message, dict):
                message[draw(st.text(max_size=8))] = draw(JSON)
            continue
        parent = message
        for key in path[:-1]:
            parent = parent[key]
        if how == "delete":
            del parent[path[-1]]
        elif how == "replace":
            parent[path[-1]] = draw(JSON)
        elif how == "edge":  # an edge value of the field's type, or another type
            value = parent[path[-1]]
            same = NUMBER_EDGES if isinstance(value, (int, float)) else \
                STRING_EDGES if isinstance(value, str) else EDGES
            parent[path[-1]] = draw((st.sampled_from(same) | st.sampled_from(EDGES)).map(
                copy.deepcopy))
        elif isinstance(parent[path[-1]], dict):
            parent[path[-1]][draw(st.text(max_size=8))] = draw(JSON)
    return message


def _dumps(value: Any) -> str:
    """JSON text of any drawn value (NaN and infinities as Python's json writes them)."""
    return json.dumps(value)


TEXT = st.one_of(
    mutated().map(_dumps),
    mutated().map(_dumps),
    mutated().map(_dumps),
    JSON.map(_dumps),
    st.text(max_size=40),
    # cut short
    st.tuples(st.sampled_from(VALID).map(_dumps), st.integers(0, 400)).map(
        lambda t: t[0][: t[1]]),
    # deep nesting, huge numbers and strings
    st.integers(1, 200_000).map(lambda n: "[" * n + "]" * n),
    st.integers(1, 5000).map(lambda n: '{"op":"subscribe","topic":' + "[" * n + '"/tf"'
                              + "]" * n + "}"),
    st.integers(300, 6000).map(lambda n: '{"op":"set_level","level":' + "9" * n + "}"),
    st.sampled_from(["1e999", "-1e999", "NaN", '{"op":"publish","topic":"/tf","msg":'
                     '{"transforms":[' + ",".join(['{"header":{}}'] * 3) + "]}}"]),
    st.integers(1, 5).map(lambda n: json.dumps(
        {"op": "subscribe", "topic": "/t" + "x" * (10**n), "id": "y" * (10**n)})),
)


class World:
    """A BufferCore with world -> base_link and world -> odom, and a session on it."""

    def __init__(self) -> None:
        self.core = BufferCore(cache_time=100.0)
        assert self.core.set_transform(_ts(1.0), "test")
        assert self.core.set_transform(_ts(3.0, "odom"), "test")
        self.session = Session(lambda t, s: self.core.lookup_transform(t, s, Time(0)))
        self.sink = BufferCore(cache_time=100.0)


def _check_sendable(messages: list[dict[str, Any]]) -> None:
    for m in messages:
        # what Client.push does before sending a text frame
        json.dumps(m, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _feed(w: World, text: str, now_ns: int) -> None:
    session = w.session
    received, refused = session.received, session.refused
    outcome = session.handle(text, Time.from_ns(now_ns))
    assert session.received == received + 1
    assert session.refused in (refused, refused + 1)
    _check_sendable(outcome.replies)
    if session.refused == refused + 1 and session.level != "none":
        assert any(r.get("level") == "error" or r.get("result") is False
                   for r in outcome.replies), outcome.replies
    for topic, message in outcome.publish:
        assert topic in ("/tf", "/tf_static")
        for ts in message.transforms:
            ts.header.frame_id.encode("utf-8")
            ts.child_frame_id.encode("utf-8")
            assert all(math.isfinite(c) for c in (*ts.transform.translation,
                                                  *ts.transform.rotation))
        # what the server's TransformListener does with it: a batch store, never raising
        w.sink.set_transforms(message.transforms, "fuzz", is_static=topic == "/tf_static")
    for tick in (now_ns, now_ns + S // 2, now_ns + 10 * S):
        _check_sendable(session.tick(Time.from_ns(tick)))
    due = session.next_due_ns()
    assert due is None or 0 <= due < 2**63


@FUZZ
@given(texts=st.lists(TEXT, min_size=1, max_size=4))
def test_any_text_is_answered_never_raised(texts: list[str]) -> None:
    """Random and mutated messages, up to four on one session: each is answered or
    refused (counted, with an error status), never raised; what the session sends and
    publishes can be sent and stored."""
    w = World()
    for i, text in enumerate(texts):
        _feed(w, text, (i + 1) * S)


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(message=mutated())
def test_mutated_valid_ops_after_a_valid_session(message: Any) -> None:
    """Every valid op first (subscriptions, goals, a request running), then one mutated
    op: answered or refused, the running goals still tick."""
    w = World()
    for i, valid in enumerate(VALID[:-1]):
        _feed(w, json.dumps(valid), (i + 1) * S)
    _feed(w, json.dumps(message), 20 * S)


# ------------------------------------------------------------ minimal failing inputs

def _goal_with(**fields: Any) -> str:
    return json.dumps({"op": "send_action_goal", "action": "/tf2_web_republisher",
                       "id": "a1", "args": {**_goal(), **fields}})


@pytest.mark.parametrize(("text", "why"), [
    (_goal_with(rate=10**400), "goal.rate must be finite"),
    (_goal_with(trans_thres=10**400), "goal.trans_thres must be finite"),
    (json.dumps({"op": "publish", "topic": "/tf", "msg": {"transforms": [
        {**transform_to_json(_ts(1.0)), "transform": {
            "translation": {"x": 10**400, "y": 0, "z": 0},
            "rotation": {"x": 0, "y": 0, "z": 0, "w": 1}}}]}}),
     "transforms[0].transform.translation.x must be finite"),
    (_goal_with(rate=1e-300), "goal.rate must be at least"),
    (_goal_with(rate=1e-12), "goal.rate must be at least"),
    (json.dumps({"op": "publish", "topic": "/tf", "msg": {"transforms": [
        {**transform_to_json(_ts(1.0)), "child_frame_id": "a\ud800"}]}}),
     "transforms[0].child_frame_id must be valid Unicode"),
    (_goal_with(target_frame="\udfffworld"), "goal.target_frame must be valid Unicode"),
    (_goal_with(source_frames=["base\ud800"]), "goal.source_frames must be strings"),
    (json.dumps({"op": "subscribe", "topic": "/tf", "type": "x\ud800"}),
     "subscribe.type must be a string"),
])
def test_minimal_inputs_that_raised_are_refused(text: str, why: str) -> None:
    """Found by the fuzz tests above: an integer beyond a double (``10**400``) raised
    OverflowError out of the session (``math.isfinite``); a rate so low that its period
    is beyond int64 nanoseconds raised OverflowError (or, a little higher, made the
    client's ticker fail on ``Time.from_ns``); a frame id with a lone surrogate (a JSON
    ``\\ud800`` escape) was published, and cannot be encoded on a bus (UTF-8). Each is now
    refused with a status naming the field, and nothing else changes."""
    w = World()
    outcome = w.session.handle(text, Time.from_ns(S))
    (status,) = outcome.replies
    assert status["op"] == "status" and status["level"] == "error"
    assert why in status["msg"], status["msg"]
    assert outcome.publish == [] and w.session.republishers == {}
    assert w.session.refused == 1


def test_rate_below_the_lowest_refused_the_lowest_served() -> None:
    """A rate of 0.0001 Hz was taken (its first tick 10 000 s on); rates below
    :data:`MIN_RATE` (0.001 Hz) are refused, the lowest is served: one update each
    1000 s."""
    w = World()
    (status,) = w.session.handle(_goal_with(rate=0.0001), Time.from_ns(S)).replies
    assert "goal.rate must be at least 0.001 Hz, got 0.0001" in status["msg"]
    assert w.session.handle(_goal_with(rate=MIN_RATE), Time.from_ns(S)).replies == []
    (r,) = w.session.republishers.values()
    assert r.period_ns == 1000 * S
    assert w.session.tick(Time.from_ns(S + 999 * S)) == []
    (feedback,) = w.session.tick(Time.from_ns(S + 1000 * S))
    assert [t["child_frame_id"] for t in feedback["values"]["transforms"]] == \
        ["base_link", "odom"]


# ------------------------------------------------------------ a real tfbus web process

GARBAGE: list[str] = [
    "{not json", "[]", "null", '"op"', "1e999", "[" * 50_000 + "]" * 50_000,
    '{"op":"frobnicate"}', '{"op":5}', '{"op":"subscribe"}', '{"op":"subscribe","topic":7}',
    '{"op":"subscribe","topic":"/secret"}', '{"op":"publish","topic":"/tf","msg":[]}',
    '{"op":"publish","topic":"/tf","msg":{"transforms":[{}]}}',
    '{"op":"set_level","level":' + "9" * 5000 + "}",
    _goal_with(rate=10**400), _goal_with(rate=1e-300), '{"op":"set_level","level":"loud"}',
    json.dumps({"op": "subscribe", "topic": "/x" + "y" * 100_000}),
    json.dumps({"op": "publish", "topic": "/tf", "msg": {"transforms": [
        {**transform_to_json(_ts(1.0)), "child_frame_id": "a\ud800"}]}}),
]


@pytest.mark.anyio
async def test_garbage_burst_on_one_connection_the_other_still_gets_tf() -> None:
    """A real ``tfbus web --bag`` process: one connection sends a burst of garbage (every
    message above, three times: text, binary frames and a 2 MB frame among them); each is
    answered with an error status on that connection (the server's count of refused
    requests, as the client sees it), in order, and a well-behaved second client that
    subscribed to /tf before and after keeps receiving the bag's transforms. The process
    ends with status 0 on SIGTERM, no traceback on stderr."""
    import signal

    from wsproto.events import BytesMessage, TextMessage

    argv = [sys.executable, "-m", "tfbus.cli", "web", "--bag", str(TURTLE), "--port", "0"]
    proc = await anyio.open_process(argv, env=ENV)
    try:
        assert proc.stderr is not None
        err = b""
        with anyio.fail_after(BOUND):
            while b"ws://" not in err or not err.endswith(b"\n"):
                err += await proc.stderr.receive()
        port = int(err.decode().strip().rsplit(":", 1)[1].strip("/"))
        async with RawClient.connect(port) as good, RawClient.connect(port) as bad:
            await good.send({"op": "subscribe", "topic": "/tf"})
            await good.receive_until(lambda m: m.get("topic") == "/tf")
            sent = 0
            for _ in range(3):
                for text in GARBAGE:
                    await bad.send(text)
                    sent += 1
                await bad.stream.send(bad.ws.send(BytesMessage(b"\x00\xff" * 10)))
                await bad.stream.send(bad.ws.send(TextMessage("x" * (2 << 20))))
                sent += 2
            await bad.send({"op": "call_service", "service": "/rosapi/topics", "id": "end"})
            errors = 0
            while True:
                m = await bad.receive()
                if m.get("id") == "end":
                    break
                assert m["op"] == "status" and m["level"] == "error", m
                errors += 1
            assert errors == sent
            assert m["result"] is True and "/tf" in m["values"]["topics"]
            # the good client is still served, and so is the bad one after its garbage
            await bad.send({"op": "subscribe", "topic": "/tf"})
            for c in (good, bad):
                m = await c.receive_until(lambda m: m.get("topic") == "/tf")
                frames = {t["child_frame_id"] for t in m["msg"]["transforms"]}
                assert frames <= {"turtle1", "turtle2"} and frames, m
        proc.send_signal(signal.SIGTERM)  # the process this test started
        with anyio.fail_after(BOUND):
            code = await proc.wait()
            rest = b"".join([chunk async for chunk in proc.stderr])
        assert code == 0, rest
        assert b"Traceback" not in rest, rest
    finally:
        if proc.returncode is None:
            proc.kill()
        with anyio.CancelScope(shield=True), anyio.move_on_after(BOUND):
            await proc.aclose()
