"""The rosbridge v2 JSON protocol, as far as tf goes: one client's session, sans I/O.

:class:`Session` reads the text of each WebSocket message a client sends
(:meth:`Session.handle`) and says what to do: messages to send back, transforms to
publish on the bus. It never touches a socket, a clock or a task: the server
(:mod:`tfbus.web.server`) does, and asks :meth:`Session.tick` each period for the
transforms the client's republishers must send.

Operations (rosbridge_suite ``ROSBRIDGE_PROTOCOL.md``, section 3.4):

* ``subscribe`` / ``unsubscribe``: ``/tf`` and ``/tf_static`` (the bus's ``TFMessage``\\ s
  relayed as they are; ``/tf_static``'s latched transforms at once), the
  ``tf2_web_republisher`` action's ``/feedback``, ``/status`` and ``/result`` topics, and
  the ``tf_repub_N`` topic that the ``republish_tfs`` service answered with.
* ``advertise`` / ``unadvertise`` / ``publish``: ``/tf`` and ``/tf_static`` (the
  transforms go on the bus, each checked: a bad one is counted and dropped, the others
  kept), and the action's ``/goal`` and ``/cancel`` topics (roslibjs ``TFClient``: ROS 1
  actionlib over rosbridge).
* ``call_service``: ``/republish_tfs`` (roslibpy ``TFClient``; the answer names the topic
  to subscribe), ``/rosapi/topics``.
* ``send_action_goal`` / ``cancel_action_goal``: the ROS 2 ``TFSubscription`` action
  (roslibjs ``ROS2TFClient``), its feedback as ``action_feedback``.
* ``set_level``: which ``status`` messages the client wants.

Each goal or request is a :class:`Republisher`, as in tf2_web_republisher's
``tf_web_republisher.cpp``: at ``rate`` Hz each source frame is looked up in the target
(fixed) frame at the latest common time (``Time(0)``) and sent, stamped with the clock's
now, when :meth:`TfPair.update_needed` (``tf_pair.h``) says it moved enough.

Anything else -- text that is not JSON, not an object, an unknown ``op``, a topic or
service not served, a field of the wrong type, a binary message, one over
:data:`MAX_MESSAGE_BYTES`, more than :data:`MAX_SUBSCRIPTIONS` subscriptions or
:data:`MAX_REPUBLISHERS` goals -- is answered with a ``status`` message of level
``error`` (with the request's ``id`` when it had one) and counted in
:attr:`Session.refused`; nothing else in the session changes.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from tfbus.errors import TransformException
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

__all__ = [
    "ACTION_TYPE",
    "MAX_MESSAGE_BYTES",
    "MAX_RATE",
    "MAX_REPUBLISHERS",
    "MAX_SOURCE_FRAMES",
    "MAX_SUBSCRIPTIONS",
    "MIN_RATE",
    "REPUBLISH_SERVICE",
    "SERVER_NAME",
    "Republisher",
    "Session",
    "TfPair",
    "transform_from_json",
    "transform_to_json",
]

SERVER_NAME: Final = "/tf2_web_republisher"
"""The action server's name (roslibjs ``TFClient``'s and ``ROS2TFClient``'s
``serverName`` default)."""
REPUBLISH_SERVICE: Final = "/republish_tfs"
"""tf2_web_republisher's service (``nh_.advertiseService("republish_tfs")``; roslibpy's
``repub_service_name`` default)."""
ACTION_TYPE: Final = "tf2_web_republisher/TFSubscriptionAction"
"""The ROS 1 action type roslibjs's ``TFClient`` names."""
MAX_MESSAGE_BYTES: Final = 1 << 20
"""Largest message a client may send, bytes (a larger one is answered with a status
and dropped)."""
MAX_SUBSCRIPTIONS: Final = 64
"""Subscriptions one client may hold at once."""
MAX_REPUBLISHERS: Final = 16
"""Goals and ``republish_tfs`` requests one client may have running at once."""
MAX_SOURCE_FRAMES: Final = 1000
"""Source frames one goal or request may name."""
MAX_RATE: Final = 100.0
"""Highest ``rate`` (Hz) a goal may ask; a higher one is served at this rate."""
MIN_RATE: Final = 0.001
"""Lowest ``rate`` (Hz) a goal may ask (one update each 1000 s); a lower one is refused
(its period, in int64 nanoseconds, would soon be past any clock's time)."""
MAX_TRANSFORMS: Final = 10_000
"""Transforms one published ``TFMessage`` may hold."""
MAX_ID: Final = 256
"""Longest ``id``, topic or frame id (characters) taken from a client."""
LEVELS: Final = ("none", "error", "warning", "info")
"""rosbridge's status levels, least to most verbose (``set_level``)."""
STATUS_ACTIVE: Final = 1
STATUS_CANCELED: Final = 2  # actionlib_msgs/GoalStatus PREEMPTED
ROS2_STATUS_CANCELED: Final = 5  # action_msgs/GoalStatus STATUS_CANCELED

_ACTION_TOPICS: Final = tuple(f"{SERVER_NAME}/{t}" for t in
                               ("goal", "cancel", "feedback", "status", "result"))
_REPUB_PREFIX: Final = f"{SERVER_NAME}/tf_repub_"
_TF_TYPES: Final = {TF_TOPIC: "tf2_msgs/TFMessage", TF_STATIC_TOPIC: "tf2_msgs/TFMessage"}


# ---------------------------------------------------------------- JSON <-> messages

def _stamp_json(t: Time, ros2: bool) -> dict[str, int]:
    sec, nsec = divmod(t.ns, 1_000_000_000)
    return {"sec": sec, "nanosec": nsec} if ros2 else {"secs": sec, "nsecs": nsec}


def transform_to_json(ts: TransformStamped, *, ros2: bool = False) -> dict[str, Any]:
    """A ``geometry_msgs/TransformStamped`` as rosbridge's JSON object: ROS 1's
    ``{secs, nsecs}`` stamp and a ``seq``, or with ``ros2`` ROS 2's ``{sec, nanosec}``."""
    v, q = ts.transform.translation, ts.transform.rotation
    header: dict[str, Any] = {"stamp": _stamp_json(ts.header.stamp, ros2),
                              "frame_id": ts.header.frame_id}
    if not ros2:
        header = {"seq": 0, **header}
    return {"header": header, "child_frame_id": ts.child_frame_id,
            "transform": {"translation": {"x": v.x, "y": v.y, "z": v.z},
                          "rotation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w}}}


def _get(obj: Mapping[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    value = obj.get(key)
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        raise ValueError(f"{where}.{key} must be {_kind(kind)}, got {_short(value)}")
    return value


def _kind(kind: type | tuple[type, ...]) -> str:
    names = {str: "a string", dict: "an object", list: "a list", int: "an integer",
             float: "a number", bool: "true or false"}
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _short(value: object) -> str:
    text = json.dumps(value) if isinstance(value, (str, int, float, type(None))) else \
        type(value).__name__
    return text if len(text) <= 60 else text[:57] + "..."


def _number(obj: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in obj and default is not None:
        return default
    value = _get(obj, key, (int, float), where)
    try:
        number = float(value)  # an integer beyond a double (JSON 1 followed by 400 zeros)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ValueError(f"{where}.{key} must be finite, got {_short(value)}")
    return number


def _unicode(value: str) -> bool:
    """Whether ``value`` is valid Unicode: no lone surrogate (a JSON ``"\\ud800"``
    escape), so that it can be encoded as UTF-8, as a ROS string on a bus must be."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _name(obj: Mapping[str, Any], key: str, where: str) -> str:
    value: str = _get(obj, key, str, where)
    if len(value) > MAX_ID:
        raise ValueError(f"{where}.{key} is longer than {MAX_ID} characters")
    if not _unicode(value):
        raise ValueError(f"{where}.{key} must be valid Unicode (a lone surrogate cannot be "
                         f"encoded as UTF-8), got {_short(value)}")
    return value


def _stamp_from_json(obj: Mapping[str, Any], where: str) -> Time:
    if "sec" in obj or "nanosec" in obj:
        sec, nsec = obj.get("sec", 0), obj.get("nanosec", 0)
    else:
        sec, nsec = obj.get("secs", 0), obj.get("nsecs", 0)
    if not all(isinstance(x, int) and not isinstance(x, bool) for x in (sec, nsec)) or \
            not (0 <= nsec < 1_000_000_000 and 0 <= sec < 2**32):
        raise ValueError(f"{where} must hold integer seconds (0 to 2^32) and "
                            f"nanoseconds (0 to 1e9), got {_short(sec)}, {_short(nsec)}")
    return Time(sec, nsec)


def transform_from_json(obj: object, where: str = "transform") -> TransformStamped:
    """A ``geometry_msgs/TransformStamped`` from rosbridge's JSON (either stamp form).

    Raises:
        ValueError: a field is missing, of the wrong type, or not finite; a frame id
            is longer than :data:`MAX_ID`; the rotation's norm is not about 1 (tf2's
            ``setTransform`` refuses an unnormalized quaternion: ``buffer_core.cpp``).
    """
    if not isinstance(obj, dict):
        raise ValueError(f"{where} must be an object, got {_short(obj)}")
    header = _get(obj, "header", dict, where)
    stamp = _stamp_from_json(_get(header, "stamp", dict, f"{where}.header"),
                             f"{where}.header.stamp")
    tf = _get(obj, "transform", dict, where)
    t = _get(tf, "translation", dict, f"{where}.transform")
    r = _get(tf, "rotation", dict, f"{where}.transform")
    w = f"{where}.transform.translation"
    translation = Vector3(*(_number(t, k, w) for k in "xyz"))
    w = f"{where}.transform.rotation"
    rotation = Quaternion(*(_number(r, k, w) for k in "xyzw"))
    norm = math.sqrt(sum(c * c for c in rotation))
    if abs(norm - 1.0) > 1e-3:
        raise ValueError(f"{w} must be a unit quaternion, its norm is {norm:.6g}")
    return TransformStamped(
        Header(stamp, _name(header, "frame_id", f"{where}.header")),
        _name(obj, "child_frame_id", where), Transform(translation, rotation))


# ---------------------------------------------------------------- tf2_web_republisher

def _angle(a: Quaternion, b: Quaternion) -> float:
    """tf's ``Quaternion::angle(q)``: ``acos(a . b / (|a| |b|))``, half the angle of the
    rotation from one to the other (LinearMath ``Quaternion.h``), what ``tf_pair.h``
    compares with ``angular_thres``."""
    s = math.sqrt(sum(c * c for c in a) * sum(c * c for c in b))
    if s == 0.0:
        return 0.0
    return math.acos(max(-1.0, min(1.0, sum(x * y for x, y in zip(a, b, strict=True)) / s)))


@dataclass
class TfPair:
    """One source frame of a goal: tf2_web_republisher's ``TFPair`` (``tf_pair.h``).

    :meth:`update_needed` is true for a transform just looked up when it is the first, or
    either threshold is 0, or it moved more than ``trans_thres`` metres from the one last
    sent, or turned by more than ``angular_thres`` (tf's half angle, radians, as
    ``tf_pair.h`` compares).
    """

    source_frame: str
    target_frame: str
    angular_thres: float
    trans_thres: float
    sent: Transform | None = None
    """The transform last sent (None: none yet)."""

    def update_needed(self, received: Transform) -> bool:
        """Whether ``received`` must be sent (``TFPair::updateNeeded``)."""
        if self.sent is None or self.trans_thres == 0.0 or self.angular_thres == 0.0:
            return True
        a, b = self.sent.translation, received.translation
        if math.dist((a.x, a.y, a.z), (b.x, b.y, b.z)) > self.trans_thres:
            return True
        return _angle(self.sent.rotation, received.rotation) > self.angular_thres


Lookup = Callable[[str, str], TransformStamped]
"""``lookup(target_frame, source_frame)``: the latest transform (tf2's ``Time(0)``);
raises :class:`~tfbus.errors.TransformException` when there is none."""


@dataclass
class Republisher:
    """One ``TFSubscription`` goal or ``republish_tfs`` request of a client.

    ``kind`` is ``"action"`` (ROS 1 goal: feedback on ``/tf2_web_republisher/feedback``),
    ``"action2"`` (ROS 2 goal: ``action_feedback``) or ``"topic"`` (a request: a
    ``TFArray`` on :attr:`topic`, while subscribed).
    """

    kind: str
    goal_id: str
    pairs: list[TfPair]
    period_ns: int
    topic: str = ""
    timeout_ns: int = 0
    """A request ends after this long without a subscriber (``timeout``; 0: never)."""
    due_ns: int = 0
    """Clock time of the next tick."""
    unsubscribed_since_ns: int | None = None
    ticks: int = 0
    """Lookups made so far (one per tick that ran them)."""

    def updates(self, lookup: Lookup, now: Time) -> list[TransformStamped]:
        """The transforms to send now (``updateSubscriptions``): each pair's latest
        transform of ``source`` in ``target``, if it moved enough, stamped ``now`` with
        ``frame_id`` the target and ``child_frame_id`` the source."""
        out = []
        self.ticks += 1
        for pair in self.pairs:
            try:
                got = lookup(pair.target_frame, pair.source_frame)
            except TransformException:
                continue
            if pair.update_needed(got.transform):
                pair.sent = got.transform
                out.append(TransformStamped(Header(now, pair.target_frame),
                                            pair.source_frame, got.transform))
        return out


def _clean(frame_id: str) -> str:
    """tf2_web_republisher's ``cleanTfFrame``: one leading ``/`` dropped."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


# ---------------------------------------------------------------- the session

@dataclass
class Outcome:
    """What one client message asks of the server."""

    replies: list[dict[str, Any]] = field(default_factory=list)
    """Messages to send back to this client, in order."""
    publish: list[tuple[str, TFMessage]] = field(default_factory=list)
    """``(topic, message)`` to publish on the bus."""
    subscribed: list[str] = field(default_factory=list)
    """Bus topics the client has just subscribed to (the server sends ``/tf_static``'s
    latched transforms)."""


class Session:
    """One rosbridge client's state (module docstring).

    Args:
        lookup: the latest transform of a frame in another
            (``buffer.lookup_transform(target, source, Time(0))``).
        topics: the topics and their types ``/rosapi/topics`` answers with (by default
            :func:`served_topics`).

    Counters: :attr:`refused` (requests answered with an error status),
    :attr:`bad_transforms` (published transforms dropped), :attr:`received`.
    """

    _next_request = 0  # the n of tf_repub_n, over every session (names never repeat)

    def __init__(self, lookup: Lookup,
                 topics: Callable[[], Sequence[tuple[str, str]]] | None = None) -> None:
        self.lookup = lookup
        self.topics = topics if topics is not None else lambda: served_topics(())
        self.subscriptions: dict[str, str] = {}
        """Topic subscribed -> the message type the client named (``""``: none)."""
        self.advertised: set[str] = set()
        self.republishers: dict[str, Republisher] = {}
        """Running goals and requests by goal id (a request's by its topic)."""
        self.level = "error"
        self.refused = 0
        self.bad_transforms = 0
        self.received = 0

    # -- helpers
    def status(self, level: str, msg: str, op_id: object = None) -> list[dict[str, Any]]:
        """A rosbridge ``status`` message, if the client's ``set_level`` lets it through."""
        if LEVELS.index(level) > LEVELS.index(self.level):
            return []
        out: dict[str, Any] = {"op": "status", "level": level, "msg": msg}
        if isinstance(op_id, str):
            out["id"] = op_id
        return [out]

    def refuse(self, msg: str, op_id: object = None) -> Outcome:
        """Count a refused request and answer it with an ``error`` status."""
        self.refused += 1
        return Outcome(self.status("error", msg, op_id))

    def wants(self, topic: str) -> str | None:
        """The type the client subscribed ``topic`` with, None when not subscribed."""
        return self.subscriptions.get(topic)

    # -- input
    def handle_binary(self, size: int) -> Outcome:
        """A binary message (BSON/CBOR): not served."""
        return self.refuse(f"binary messages (BSON, CBOR) are not served; got {size} bytes:"
                           " send JSON text")

    def handle_oversize(self, size: int) -> Outcome:
        """A message over :data:`MAX_MESSAGE_BYTES` (dropped unread)."""
        return self.refuse(f"message of {size} bytes or more is over the limit of "
                           f"{MAX_MESSAGE_BYTES} bytes; dropped")

    def handle(self, text: str, now: Time) -> Outcome:
        """One text message of the client."""
        self.received += 1
        try:
            message = json.loads(text)
        except (ValueError, RecursionError) as err:
            return self.refuse(f"message is not JSON: {str(err)[:80]}")
        if not isinstance(message, dict):
            return self.refuse(f"message must be a JSON object, got {type(message).__name__}")
        op_id = message.get("id")
        if op_id is not None and not (isinstance(op_id, str) and len(op_id) <= MAX_ID):
            return self.refuse(f"id must be a string of at most {MAX_ID} characters")
        op = message.get("op")
        handler = _OPS.get(op) if isinstance(op, str) else None
        if handler is None:
            return self.refuse(f"unknown or unsupported op {_short(op)}", op_id)
        try:
            return handler(self, message, now)
        except ValueError as err:
            return self.refuse(f"{op}: {err}", op_id)

    def _subscribe(self, m: Mapping[str, Any], now: Time) -> Outcome:
        topic = _name(m, "topic", "subscribe")
        kind = m.get("type", "")
        if not isinstance(kind, str) or len(kind) > MAX_ID or not _unicode(kind):
            raise ValueError(f"subscribe.type must be a string of at most {MAX_ID} "
                             "characters (valid Unicode)")
        if topic not in _TF_TYPES and topic not in _ACTION_TOPICS and \
                not any(r.topic == topic for r in self.republishers.values()):
            raise ValueError(f"topic {_short(topic)} is not served (only /tf, /tf_static "
                                f"and {SERVER_NAME}'s)")
        if topic not in self.subscriptions and len(self.subscriptions) >= MAX_SUBSCRIPTIONS:
            raise ValueError(f"over {MAX_SUBSCRIPTIONS} subscriptions on this connection")
        self.subscriptions[topic] = kind
        for r in self.republishers.values():
            if r.topic == topic:
                r.unsubscribed_since_ns = None
        return Outcome(subscribed=[topic] if topic in _TF_TYPES else [])

    def _unsubscribe(self, m: Mapping[str, Any], now: Time) -> Outcome:
        topic = _name(m, "topic", "unsubscribe")
        self.subscriptions.pop(topic, None)
        for r in self.republishers.values():
            if r.topic == topic and r.unsubscribed_since_ns is None:
                r.unsubscribed_since_ns = now.ns
        return Outcome()

    def _advertise(self, m: Mapping[str, Any], now: Time) -> Outcome:
        topic = _name(m, "topic", "advertise")
        if topic not in _TF_TYPES and topic not in _ACTION_TOPICS:
            raise ValueError(f"topic {_short(topic)} cannot be published here (only /tf, "
                                f"/tf_static and {SERVER_NAME}'s goal and cancel)")
        self.advertised.add(topic)
        return Outcome()

    def _unadvertise(self, m: Mapping[str, Any], now: Time) -> Outcome:
        self.advertised.discard(_name(m, "topic", "unadvertise"))
        return Outcome()

    def _publish(self, m: Mapping[str, Any], now: Time) -> Outcome:
        topic = _name(m, "topic", "publish")
        msg = _get(m, "msg", dict, "publish")
        if topic in _TF_TYPES:
            return self._publish_tf(topic, msg)
        if topic == f"{SERVER_NAME}/goal":
            goal_id = _get(_get(msg, "goal_id", dict, "goal"), "id", str, "goal.goal_id")
            return self._start(_get(msg, "goal", dict, "goal"), "action", goal_id or
                               f"goal_{len(self.republishers)}", now)
        if topic == f"{SERVER_NAME}/cancel":
            goal_id = msg.get("id", "")
            if not isinstance(goal_id, str):
                raise ValueError("cancel.id must be a string")
            if goal_id == "":  # actionlib: an empty id cancels every goal
                for key in [k for k, r in self.republishers.items() if r.kind == "action"]:
                    del self.republishers[key]
            elif goal_id in self.republishers and self.republishers[goal_id].kind == "action":
                del self.republishers[goal_id]
            return Outcome()
        raise ValueError(f"topic {_short(topic)} cannot be published here (only /tf, "
                            f"/tf_static and {SERVER_NAME}'s goal and cancel)")

    def _publish_tf(self, topic: str, msg: Mapping[str, Any]) -> Outcome:
        items = _get(msg, "transforms", list, "publish.msg")
        if len(items) > MAX_TRANSFORMS:
            raise ValueError(f"publish.msg.transforms holds {len(items)} transforms, over "
                                f"the limit of {MAX_TRANSFORMS}")
        good, errors = [], []
        for i, item in enumerate(items):
            try:
                good.append(transform_from_json(item, f"transforms[{i}]"))
            except ValueError as err:
                errors.append(str(err))
        out = Outcome(publish=[(topic, TFMessage(good))] if good else [])
        if errors:
            self.bad_transforms += len(errors)
            self.refused += 1
            out.replies = self.status("error", f"publish {topic}: {len(errors)} transform(s) "
                                      f"dropped, {len(good)} kept: {errors[0]}")
        return out

    def _start(self, goal: Mapping[str, Any], kind: str, goal_id: str, now: Time,
               topic: str = "", timeout_ns: int = 0) -> Outcome:
        w = "goal"
        frames = _get(goal, "source_frames", list, w)
        if len(frames) > MAX_SOURCE_FRAMES:
            raise ValueError(f"goal.source_frames names {len(frames)} frames, over the "
                                f"limit of {MAX_SOURCE_FRAMES}")
        if not all(isinstance(f, str) and len(f) <= MAX_ID and _unicode(f) for f in frames):
            raise ValueError(f"goal.source_frames must be strings of at most {MAX_ID} "
                             "characters (valid Unicode)")
        target = _clean(_name(goal, "target_frame", w))
        angular = _number(goal, "angular_thres", w, 0.0)
        trans = _number(goal, "trans_thres", w, 0.0)
        rate = _number(goal, "rate", w, 10.0)
        if angular < 0 or trans < 0:
            raise ValueError(f"thresholds must be >= 0, got angular_thres {angular}, "
                                f"trans_thres {trans}")
        if not rate >= MIN_RATE:
            raise ValueError(f"goal.rate must be at least {MIN_RATE} Hz, got {rate}")
        if goal_id not in self.republishers and len(self.republishers) >= MAX_REPUBLISHERS:
            raise ValueError(f"over {MAX_REPUBLISHERS} goals on this connection")
        period = round(1e9 / min(rate, MAX_RATE))
        pairs = [TfPair(_clean(f), target, angular, trans) for f in dict.fromkeys(frames)]
        self.republishers[goal_id] = Republisher(
            kind, goal_id, pairs, period, topic=topic, timeout_ns=timeout_ns,
            due_ns=now.ns + period, unsubscribed_since_ns=now.ns if topic else None)
        return Outcome()

    def _call_service(self, m: Mapping[str, Any], now: Time) -> Outcome:
        service = _name(m, "service", "call_service")
        op_id = m.get("id")
        args = m.get("args", {})
        if args is None or args == []:
            args = {}
        if not isinstance(args, dict):
            raise ValueError("call_service.args must be an object")
        if service in (REPUBLISH_SERVICE, f"{SERVER_NAME}/republish_tfs"):
            timeout = args.get("timeout", {})
            timeout_ns = _stamp_from_json(timeout, "timeout").ns if isinstance(timeout, dict) \
                else 0
            topic = f"{_REPUB_PREFIX}{Session._next_request}"
            Session._next_request += 1
            self._start(args, "topic", topic, now, topic=topic,
                        timeout_ns=timeout_ns or 2_000_000_000)
            values: dict[str, Any] = {"topic_name": topic}
        elif service == "/rosapi/topics":
            pairs = list(self.topics())
            values = {"topics": [t for t, _ in pairs], "types": [k for _, k in pairs]}
        else:
            self.refused += 1
            reply = {"op": "service_response", "service": service, "result": False,
                     "values": f"service {_short(service)} is not served (only "
                               f"{REPUBLISH_SERVICE} and /rosapi/topics)"}
            if isinstance(op_id, str):
                reply["id"] = op_id
            return Outcome([reply])
        reply = {"op": "service_response", "service": service, "values": values,
                 "result": True}
        if isinstance(op_id, str):
            reply["id"] = op_id
        return Outcome([reply])

    def _send_action_goal(self, m: Mapping[str, Any], now: Time) -> Outcome:
        action = _name(m, "action", "send_action_goal")
        if action != SERVER_NAME:
            raise ValueError(f"action {_short(action)} is not served (only {SERVER_NAME})")
        op_id = _name(m, "id", "send_action_goal")
        return self._start(_get(m, "args", dict, "send_action_goal"), "action2", op_id, now)

    def _cancel_action_goal(self, m: Mapping[str, Any], now: Time) -> Outcome:
        op_id = _name(m, "id", "cancel_action_goal")
        gone = self.republishers.get(op_id)
        if gone is None or gone.kind != "action2":
            return Outcome()
        del self.republishers[op_id]
        return Outcome([{"op": "action_result", "id": op_id, "action": SERVER_NAME,
                         "values": {}, "status": ROS2_STATUS_CANCELED, "result": True}])

    def _set_level(self, m: Mapping[str, Any], now: Time) -> Outcome:
        level = _get(m, "level", str, "set_level")
        if level not in LEVELS:
            raise ValueError(f"set_level.level must be one of {', '.join(LEVELS)}, "
                                f"got {_short(level)}")
        self.level = level
        return Outcome()

    # -- output
    def tf_message(self, topic: str, message: TFMessage) -> dict[str, Any] | None:
        """The ``publish`` to send for a bus message on ``topic``, None if not subscribed."""
        kind = self.subscriptions.get(topic)
        if kind is None:
            return None
        ros2 = "/msg/" in kind
        return {"op": "publish", "topic": topic, "msg": {"transforms": [
            transform_to_json(ts, ros2=ros2) for ts in message.transforms]}}

    def next_due_ns(self) -> int | None:
        """Clock time of the earliest republisher tick, None without republishers."""
        return min((r.due_ns for r in self.republishers.values()), default=None)

    def tick(self, now: Time) -> list[dict[str, Any]]:
        """Run every republisher due at ``now`` (tf2_web_republisher's timers): the
        feedback, ``action_feedback`` and ``TFArray`` messages to send, in order."""
        out: list[dict[str, Any]] = []
        for key, r in list(self.republishers.items()):
            if r.due_ns > now.ns:
                continue
            r.due_ns = now.ns + r.period_ns  # a late tick delays the next: at most `rate`
            if r.kind == "topic":
                if r.topic not in self.subscriptions:
                    since = r.unsubscribed_since_ns
                    if since is not None and now.ns - since >= r.timeout_ns:
                        del self.republishers[key]  # unadvertiseCB
                    continue
            elif r.kind == "action" and f"{SERVER_NAME}/feedback" not in self.subscriptions:
                continue
            updates = r.updates(self.lookup, now)
            if not updates:
                continue
            if r.kind == "topic":
                out.append({"op": "publish", "topic": r.topic, "msg": {
                    "transforms": [transform_to_json(u) for u in updates]}})
            elif r.kind == "action":
                out.append({"op": "publish", "topic": f"{SERVER_NAME}/feedback", "msg": {
                    "header": {"seq": 0, "stamp": _stamp_json(now, False), "frame_id": ""},
                    "status": {"goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": r.goal_id},
                               "status": STATUS_ACTIVE, "text": ""},
                    "feedback": {"transforms": [transform_to_json(u) for u in updates]}}})
            else:
                out.append({"op": "action_feedback", "id": r.goal_id, "action": SERVER_NAME,
                            "values": {"transforms": [transform_to_json(u, ros2=True)
                                                      for u in updates]}})
        return out


def served_topics(bus_topics: Iterable[str]) -> list[tuple[str, str]]:
    """``/rosapi/topics``'s answer: the tf topics and the action's."""
    names = dict.fromkeys([TF_TOPIC, TF_STATIC_TOPIC, *bus_topics])
    return [(t, _TF_TYPES.get(t, "")) for t in names] + [
        (f"{SERVER_NAME}/feedback", f"{ACTION_TYPE[:-6]}ActionFeedback")]


_OPS: Final[dict[str, Callable[[Session, Mapping[str, Any], Time], Outcome]]] = {
    "subscribe": Session._subscribe,
    "unsubscribe": Session._unsubscribe,
    "advertise": Session._advertise,
    "unadvertise": Session._unadvertise,
    "publish": Session._publish,
    "call_service": Session._call_service,
    "send_action_goal": Session._send_action_goal,
    "cancel_action_goal": Session._cancel_action_goal,
    "set_level": Session._set_level,
}
