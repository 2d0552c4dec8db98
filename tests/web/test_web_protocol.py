"""The rosbridge session of ``tfbus web`` without a socket (tfbus.web.rosbridge): the ops
roslibjs's and roslibpy's TF clients send, tf2_web_republisher's thresholds and rate
(``tf_pair.h``, ``tf_web_republisher.cpp``), and hostile input answered with ``status``
messages, counted, nothing else changed."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from tfbus import BufferCore, Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.messages import TFMessage
from tfbus.web.rosbridge import (
    MAX_MESSAGE_BYTES,
    MAX_REPUBLISHERS,
    MAX_SUBSCRIPTIONS,
    Session,
    TfPair,
    transform_from_json,
    transform_to_json,
)

S = 1_000_000_000


def _ts(x: float, *, child: str = "base_link", parent: str = "world", yaw: float = 0.0,
        stamp: int = 1) -> TransformStamped:
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return TransformStamped(Header(Time.from_ns(stamp), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), q))


class World:
    """A BufferCore the session looks transforms up in, and the session."""

    def __init__(self) -> None:
        self.core = BufferCore(cache_time=100.0)
        self.stamp = 0
        self.session = Session(lambda t, s: self.core.lookup_transform(t, s, Time(0)))

    def set(self, x: float, yaw: float = 0.0, child: str = "base_link") -> None:
        self.stamp += S // 100
        assert self.core.set_transform(_ts(x, yaw=yaw, child=child, stamp=self.stamp), "test")

    def send(self, message: Any, now_ns: int = 0) -> list[dict[str, Any]]:
        text = message if isinstance(message, str) else json.dumps(message)
        return self.session.handle(text, Time.from_ns(now_ns)).replies


def _goal(frames: list[str], *, angular: float = 0.1, trans: float = 0.01,
          rate: float = 10.0) -> dict[str, Any]:
    return {"source_frames": frames, "target_frame": "/world", "angular_thres": angular,
            "trans_thres": trans, "rate": rate}


def _ros1_goal(w: World, goal: dict[str, Any], goal_id: str = "goal_1") -> None:
    assert w.send({"op": "advertise", "topic": "/tf2_web_republisher/goal",
                   "type": "tf2_web_republisher/TFSubscriptionActionGoal"}) == []
    assert w.send({"op": "subscribe", "topic": "/tf2_web_republisher/feedback",
                   "type": "tf2_web_republisher/TFSubscriptionActionFeedback"}) == []
    assert w.send({"op": "publish", "topic": "/tf2_web_republisher/goal", "msg": {
        "goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": goal_id}, "goal": goal}}) == []


def _xs(messages: list[dict[str, Any]]) -> list[float]:
    out = []
    for m in messages:
        values = m.get("msg", {}).get("feedback") or m.get("msg") or m.get("values")
        out += [t["transform"]["translation"]["x"] for t in values["transforms"]]
    return out


def test_tf_pair_thresholds_as_tf_pair_h() -> None:
    pair = TfPair("base_link", "world", angular_thres=0.1, trans_thres=0.01)
    sent = []
    for i in range(10):  # 4 mm steps: sent at 0, 12 mm, 24 mm, 36 mm
        t = _ts(0.004 * i).transform
        if pair.update_needed(t):
            pair.sent = t
            sent.append(round(t.translation.x, 6))
    assert sent == [0.0, 0.012, 0.024, 0.036]
    # angular: tf's Quaternion::angle is half the rotation; 0.15 rad turn -> 0.075 < 0.1
    assert not pair.update_needed(_ts(0.036, yaw=0.15).transform)
    assert pair.update_needed(_ts(0.036, yaw=0.25).transform)  # 0.125 > 0.1
    # either threshold 0: every transform is sent (tf_pair.h's first clause)
    zero = TfPair("base_link", "world", angular_thres=0.0, trans_thres=0.01, sent=pair.sent)
    assert zero.update_needed(pair.sent)  # type: ignore[arg-type]


def test_ros1_goal_feedback_thresholds_and_rate() -> None:
    w = World()
    w.set(0.0)
    _ros1_goal(w, _goal(["base_link"], rate=10.0))
    assert w.session.next_due_ns() == S // 10
    assert w.session.tick(Time.from_ns(S // 10 - 1)) == []  # not due yet
    first = w.session.tick(Time.from_ns(S // 10))
    assert len(first) == 1
    m = first[0]
    assert m["op"] == "publish" and m["topic"] == "/tf2_web_republisher/feedback"
    assert m["msg"]["status"]["goal_id"]["id"] == "goal_1"
    (t,) = m["msg"]["feedback"]["transforms"]
    assert t["header"]["frame_id"] == "world" and t["child_frame_id"] == "base_link"
    assert t["header"]["stamp"] == {"secs": 0, "nsecs": 100_000_000}  # the clock's now
    # the next tick is one period later: nothing in between, whatever moves
    w.set(1.0)
    assert w.session.tick(Time.from_ns(S // 10 + S // 10 - 1)) == []
    sent: list[dict[str, Any]] = []
    now = S // 10
    for i in range(1, 10):  # 4 mm steps from x = 1.0, one per period
        w.set(1.0 + 0.004 * (i - 1))
        now += S // 10
        sent += w.session.tick(Time.from_ns(now))
    assert [round(x, 6) for x in _xs(sent)] == [1.0, 1.012, 1.024]


def test_late_tick_delays_the_next_one_rate_is_an_upper_bound() -> None:
    w = World()
    w.set(0.0)
    _ros1_goal(w, _goal(["base_link"], trans=0.0, rate=4.0))  # every tick sends
    ticks = [S // 4 + S // 10]  # a tick 0.1 s late
    assert len(w.session.tick(Time.from_ns(ticks[0]))) == 1
    assert w.session.next_due_ns() == ticks[0] + S // 4
    assert w.session.tick(Time.from_ns(2 * S // 4)) == []  # the original schedule: no


def test_cancel_ends_a_ros1_goal_and_an_empty_id_cancels_all() -> None:
    w = World()
    w.set(0.0)
    _ros1_goal(w, _goal(["base_link"]), "a")
    _ros1_goal(w, _goal(["base_link"]), "b")
    assert set(w.session.republishers) == {"a", "b"}
    w.send({"op": "publish", "topic": "/tf2_web_republisher/cancel", "msg": {"id": "a"}})
    assert set(w.session.republishers) == {"b"}
    w.send({"op": "publish", "topic": "/tf2_web_republisher/cancel",
            "msg": {"stamp": {"secs": 0, "nsecs": 0}, "id": ""}})
    assert w.session.republishers == {}


def test_republish_tfs_service_topic_and_expiry() -> None:
    w = World()
    w.set(2.5)
    out = w.send({"op": "call_service", "id": "call:1", "service": "/republish_tfs",
                  "args": {**_goal(["/base_link"], rate=5.0), "timeout": {"secs": 2,
                                                                          "nsecs": 0}}})
    assert len(out) == 1 and out[0]["op"] == "service_response" and out[0]["result"] is True
    assert out[0]["id"] == "call:1"
    topic = out[0]["values"]["topic_name"]
    assert topic.startswith("/tf2_web_republisher/tf_repub_")
    assert w.session.tick(Time.from_ns(S // 5)) == []  # nobody subscribed: nothing sent
    assert w.send({"op": "subscribe", "topic": topic,
                   "type": "tf2_web_republisher/TFArray"}) == []
    (m,) = w.session.tick(Time.from_ns(2 * S // 5))
    assert m == {"op": "publish", "topic": topic, "msg": {"transforms": [transform_to_json(
        TransformStamped(Header(Time.from_ns(2 * S // 5), "world"), "base_link",
                         _ts(2.5).transform))]}}
    # unsubscribed for the request's timeout (2 s): the request ends (unadvertiseCB)
    w.send({"op": "unsubscribe", "topic": topic}, now_ns=S)
    w.session.tick(Time.from_ns(S + S // 5))
    assert topic in w.session.republishers
    w.session.tick(Time.from_ns(3 * S + S // 5))
    assert topic not in w.session.republishers


def test_ros2_action_goal_feedback_and_cancel() -> None:
    w = World()
    w.set(-1.25)
    assert w.send({"op": "send_action_goal", "id": "send_action_goal:/tf2_web_republisher:1",
                   "action": "/tf2_web_republisher",
                   "action_type": "tf2_web_republisher_interfaces/TFSubscription",
                   "args": _goal(["base_link"], rate=2.0), "feedback": True}) == []
    (m,) = w.session.tick(Time.from_ns(S // 2))
    assert m["op"] == "action_feedback" and m["id"] == "send_action_goal:/tf2_web_republisher:1"
    (t,) = m["values"]["transforms"]
    assert t["header"] == {"stamp": {"sec": 0, "nanosec": 500_000_000}, "frame_id": "world"}
    assert t["transform"]["translation"] == {"x": -1.25, "y": 0.0, "z": 0.0}
    out = w.send({"op": "cancel_action_goal", "id": "send_action_goal:/tf2_web_republisher:1",
                  "action": "/tf2_web_republisher"})
    assert out == [{"op": "action_result", "id": "send_action_goal:/tf2_web_republisher:1",
                    "action": "/tf2_web_republisher", "values": {}, "status": 5,
                    "result": True}]
    assert w.session.republishers == {}


def test_tf_subscription_and_publish_round_trip() -> None:
    w = World()
    assert w.send({"op": "subscribe", "topic": "/tf", "type": "tf2_msgs/msg/TFMessage"}) == []
    msg = w.session.tf_message("/tf", TFMessage([_ts(3.0, stamp=5 * S + 7)]))
    assert msg is not None
    (t,) = msg["msg"]["transforms"]
    assert t["header"]["stamp"] == {"sec": 5, "nanosec": 7}  # a ROS 2 type: ROS 2 stamps
    assert transform_from_json(t) == _ts(3.0, stamp=5 * S + 7)
    assert w.session.tf_message("/tf_static", TFMessage([_ts(1.0)])) is None
    outcome = w.session.handle(json.dumps({"op": "publish", "topic": "/tf", "msg": {
        "transforms": [transform_to_json(_ts(4.0))]}}), Time(0))
    assert outcome.publish == [("/tf", TFMessage([_ts(4.0)]))] and outcome.replies == []


def test_rosapi_topics() -> None:
    w = World()
    (out,) = w.send({"op": "call_service", "id": "t", "service": "/rosapi/topics"})
    assert out["result"] is True
    assert out["values"]["topics"][:2] == ["/tf", "/tf_static"]
    assert out["values"]["types"][:2] == ["tf2_msgs/TFMessage", "tf2_msgs/TFMessage"]


HOSTILE: list[tuple[object, str]] = [
    ("{not json", "not JSON"),
    ("[1, 2]", "must be a JSON object"),
    ("[" * 100_000 + "]" * 100_000, "not JSON"),
    ({"op": "frobnicate"}, "unknown or unsupported op"),
    ({"op": 7}, "unknown or unsupported op"),
    ({"op": "subscribe", "id": 5, "topic": "/tf"}, "id must be a string"),
    ({"op": "subscribe", "topic": "/chatter"}, "is not served"),
    ({"op": "subscribe", "topic": ["/tf"]}, "subscribe.topic must be a string"),
    ({"op": "publish", "topic": "/cmd_vel", "msg": {}}, "cannot be published here"),
    ({"op": "call_service", "service": "/republish_tfs",
      "args": {**_goal(["a"]), "rate": float("nan")}}, "must be finite"),
    ({"op": "call_service", "service": "/republish_tfs", "args": {**_goal(["a"]), "rate": 0}},
     "rate must be at least 0.001 Hz"),
    ({"op": "call_service", "service": "/republish_tfs",
      "args": {**_goal(["a"]), "trans_thres": -1}}, "thresholds must be >= 0"),
    ({"op": "call_service", "service": "/republish_tfs",
      "args": _goal(["a"] * 1001)}, "over the limit of 1000"),
    ({"op": "send_action_goal", "id": "g", "action": "/other", "args": _goal(["a"])},
     "is not served"),
    ({"op": "set_level", "level": "loud"}, "set_level.level must be one of"),
]


@pytest.mark.parametrize(("message", "why"), HOSTILE)
def test_hostile_input_answered_with_status_counted_nothing_else_changed(
        message: object, why: str) -> None:
    w = World()
    w.set(0.0)
    _ros1_goal(w, _goal(["base_link"], trans=0.0))
    before = dict(w.session.subscriptions), set(w.session.republishers)
    text = message if isinstance(message, str) else json.dumps(message)
    out = w.send(text)
    assert len(out) == 1 and out[0]["op"] == "status" and out[0]["level"] == "error"
    assert why in out[0]["msg"], out[0]["msg"]
    assert w.session.refused == 1
    assert (dict(w.session.subscriptions), set(w.session.republishers)) == before
    assert len(w.session.tick(Time.from_ns(S))) == 1  # the goal still delivers


def test_hostile_service_call_gets_a_failed_response() -> None:
    w = World()
    (out,) = w.send({"op": "call_service", "id": "x", "service": "/rosapi/params"})
    assert out["op"] == "service_response" and out["result"] is False and out["id"] == "x"
    assert w.session.refused == 1


def test_published_transforms_bad_ones_dropped_good_ones_kept() -> None:
    w = World()
    bad_rot = transform_to_json(_ts(1.0))
    bad_rot["transform"]["rotation"]["w"] = 3.0
    no_frame = transform_to_json(_ts(2.0))
    del no_frame["child_frame_id"]
    outcome = w.session.handle(json.dumps({"op": "publish", "topic": "/tf_static", "msg": {
        "transforms": [bad_rot, transform_to_json(_ts(5.0)), no_frame, "x"]}}), Time(0))
    assert outcome.publish == [("/tf_static", TFMessage([_ts(5.0)]))]
    assert w.session.bad_transforms == 3 and w.session.refused == 1
    (status,) = outcome.replies
    assert status["level"] == "error" and "3 transform(s) dropped, 1 kept" in status["msg"]


def test_subscriptions_and_goals_capped_per_client() -> None:
    w = World()
    for i in range(MAX_REPUBLISHERS):
        assert w.send({"op": "call_service", "service": "/republish_tfs",
                       "args": _goal([f"f{i}"])})[0]["result"] is True
    for i in range(MAX_SUBSCRIPTIONS):
        topic = list(w.session.republishers)[i % MAX_REPUBLISHERS] if i < MAX_REPUBLISHERS \
            else ("/tf", "/tf_static", "/tf2_web_republisher/feedback")[i % 3]
        w.send({"op": "subscribe", "topic": topic})
    assert len(w.session.subscriptions) == MAX_REPUBLISHERS + 3
    (over,) = w.send({"op": "call_service", "service": "/republish_tfs",
                      "args": _goal(["g"])})
    assert over["op"] == "status" and f"over {MAX_REPUBLISHERS} goals" in over["msg"]
    assert len(w.session.republishers) == MAX_REPUBLISHERS


def test_subscription_cap() -> None:
    w = World()
    for i in range(MAX_SUBSCRIPTIONS):  # filled with tf_repub topics of many requests
        w.session.subscriptions[f"/x{i}"] = ""
    (over,) = w.send({"op": "subscribe", "topic": "/tf"})
    assert f"over {MAX_SUBSCRIPTIONS} subscriptions" in over["msg"]
    assert "/tf" not in w.session.subscriptions


def test_binary_and_oversize_messages() -> None:
    w = World()
    (b,) = w.session.handle_binary(10).replies
    (o,) = w.session.handle_oversize(MAX_MESSAGE_BYTES).replies
    assert "binary messages" in b["msg"] and "over the limit" in o["msg"]
    assert w.session.refused == 2


def test_set_level_none_silences_status_but_still_counts() -> None:
    w = World()
    assert w.send({"op": "set_level", "level": "none"}) == []
    assert w.send("{bad") == []
    assert w.session.refused == 1
