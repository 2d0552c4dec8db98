"""The rosbridge session of ``tfbus web`` under random and mutated client messages
(hypothesis, a fixed budget, derandomized): every message valid roslibjs / roslibpy TF
clients send, with fields dropped, replaced by random JSON values (huge numbers, NaN-like
strings, nesting, long strings), ops swapped, or the text cut or spliced. Whatever comes,
the session answers without raising, every reply is strict JSON (the server sends with
``allow_nan=False``), what a client holds stays within its caps, and a valid client
request still works after the garbage."""

from __future__ import annotations

import json
import math
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tfbus import BufferCore, Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.messages import TFMessage
from tfbus.web.rosbridge import MAX_REPUBLISHERS, MAX_SUBSCRIPTIONS, Session

S = 1_000_000_000

VALID: list[dict[str, Any]] = [
    {"op": "subscribe", "topic": "/tf", "type": "tf2_msgs/TFMessage", "id": "s1"},
    {"op": "subscribe", "topic": "/tf_static", "throttle_rate": 100, "queue_length": 1},
    {"op": "unsubscribe", "topic": "/tf", "id": "s1"},
    {"op": "advertise", "topic": "/tf2_web_republisher/goal",
     "type": "tf2_web_republisher/TFSubscriptionActionGoal"},
    {"op": "publish", "topic": "/tf2_web_republisher/goal", "msg": {
        "goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": "g1"},
        "goal": {"source_frames": ["base_link"], "target_frame": "world",
                 "angular_thres": 0.1, "trans_thres": 0.01, "rate": 10.0}}},
    {"op": "publish", "topic": "/tf", "msg": {"transforms": [{
        "header": {"frame_id": "world", "stamp": {"sec": 1, "nanosec": 0}},
        "child_frame_id": "arm", "transform": {
            "translation": {"x": 1.0, "y": 0.0, "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}}]}},
    {"op": "call_service", "service": "/republish_tfs", "id": "c1", "args": {
        "source_frames": ["base_link"], "target_frame": "world", "angular_thres": 0.1,
        "trans_thres": 0.01, "rate": 10.0, "timeout": 2.0}},
    {"op": "call_service", "service": "/rosapi/topics", "id": "c2"},
    {"op": "send_action_goal", "action": "/tf2_web_republisher", "id": "a1",
     "action_type": "tf2_web_republisher_msgs/action/TFSubscription", "args": {
         "source_frames": ["base_link"], "target_frame": "world", "angular_thres": 0.1,
         "trans_thres": 0.01, "rate": 10.0}},
    {"op": "cancel_action_goal", "action": "/tf2_web_republisher", "id": "a1"},
    {"op": "set_level", "level": "info"},
]

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=40)
    | st.sampled_from(["", "/", "/tf", "world", "base_link", "x" * 3000, "\x00\x1b[2J",
                       "NaN", "Infinity", "-1e400"]),
    lambda children: st.lists(children, max_size=5)
    | st.dictionaries(st.text(max_size=10), children, max_size=5),
    max_leaves=20,
)


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a field of a nested JSON value."""
    out = [prefix] if prefix else []
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out += _paths(v, (*prefix, i))
    return out


@st.composite
def mutated(draw: st.DrawFn) -> str:
    """A valid message with one to three fields replaced, dropped or its text cut."""
    message = json.loads(json.dumps(draw(st.sampled_from(VALID))))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(message)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = message
        for key in path[:-1]:
            parent = parent[key]
        if draw(st.booleans()):
            parent[path[-1]] = draw(JSON)
        elif isinstance(parent, dict):
            del parent[path[-1]]
    text = json.dumps(message)
    how = draw(st.sampled_from(["whole", "cut", "splice", "nan"]))
    if how == "cut":
        text = text[: draw(st.integers(0, len(text)))]
    elif how == "splice":
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.text(max_size=20)) + text[at:]
    elif how == "nan":  # Python's json reads NaN and Infinity: a client may send them
        text = text.replace("1.0", "NaN", 1).replace("10.0", "Infinity", 1)
    return text


def _world() -> tuple[BufferCore, Session]:
    core = BufferCore(cache_time=100.0)
    for k in range(1, 4):
        core.set_transform(TransformStamped(
            Header(Time.from_ns(k * S), "world"), "base_link",
            Transform(Vector3(0.1 * k, 0.0, 0.0), Quaternion())), "test")
    return core, Session(lambda t, s: core.lookup_transform(t, s, Time(0)))


def _strict(replies: list[dict[str, Any]]) -> None:
    for reply in replies:
        json.dumps(reply, allow_nan=False)  # what the server sends, or ValueError


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(mutated(), min_size=1, max_size=8))
def test_mutated_client_messages_are_answered_and_bounded(texts: list[str]) -> None:
    core, session = _world()
    for k, text in enumerate(texts):
        outcome = session.handle(text, Time.from_ns((4 + k) * S))
        _strict(outcome.replies)
        for _topic, message in outcome.publish:
            assert isinstance(message, TFMessage)
            for t in message.transforms:  # a published transform is one tf2 accepts
                assert all(math.isfinite(v) for v in (*t.transform.translation,
                                                       *t.transform.rotation))
        _strict(session.tick(Time.from_ns((4 + k) * S + S // 2)))
        message = session.tf_message("/tf", TFMessage([core.lookup_transform(
            "world", "base_link", Time(0))]))
        if message is not None:
            json.dumps(message, allow_nan=False)
    assert len(session.subscriptions) <= MAX_SUBSCRIPTIONS
    assert len(session.republishers) <= MAX_REPUBLISHERS
    # A well-behaved request still works after the garbage.
    replies = session.handle(json.dumps({"op": "call_service", "service": "/rosapi/topics",
                                         "id": "after"}), Time.from_ns(20 * S)).replies
    assert [r.get("id") for r in replies if r.get("op") == "service_response"] == ["after"]


@settings(max_examples=200, deadline=None, derandomize=True)
@given(JSON)
def test_any_json_value_as_a_message_is_answered(value: Any) -> None:
    _, session = _world()
    _strict(session.handle(json.dumps(value), Time.from_ns(5 * S)).replies)
