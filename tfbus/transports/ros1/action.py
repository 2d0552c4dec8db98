"""tf2_ros's own buffer protocol on ROS 1: the ``tf2_msgs/LookupTransform`` action
(actionlib over TCPROS), both ends, on the topics of a running
:class:`~tfbus.transports.ros1.Ros1Transport` (its ``subscribe_raw`` / ``advertise_raw``):
the node that carries ``/tf`` carries the action too, one ROS 1 node per process.

* :class:`ActionClient` is actionlib's ``SimpleActionClient(ns, LookupTransformAction)``:
  it publishes ``{ns}/goal`` (``tf2_msgs/LookupTransformActionGoal``) and ``{ns}/cancel``
  (``actionlib_msgs/GoalID``) and subscribes to ``{ns}/result`` and ``{ns}/status``;
  :func:`action_client` gives the one of a transport and namespace.
  :class:`LookupActionClient` is tf2_ros ``BufferClient`` (``buffer_client.py``) on it,
  with :class:`~tfbus.buffer.Buffer`'s awaitable lookups: the server's ``TF2Error`` comes
  back as the tf2 exception of the same kind with the server's message
  (``BufferClient.__process_result``). Answered by Debian's real ``buffer_server``.
* :class:`LookupActionServer` is tf2_ros ``buffer_server`` (``buffer_server.cpp``)
  answering from a tfbus :class:`~tfbus.buffer.Buffer`: it subscribes to ``goal`` and
  ``cancel``, publishes ``result``, ``feedback`` and ``status`` (``GoalStatusArray`` at
  5 Hz, actionlib's default, so that actionlib clients' ``wait_for_server`` sees it);
  every result has status SUCCEEDED with the lookup's ``TF2Error``, as the real server.
  Debian's ``tf2_ros.BufferClient`` gets its answers. It honours cancel requests as
  tf2_ros's ``BufferServer::cancelCB`` (``buffer_server.cpp``: the goal is removed and
  ``setCanceled``, a PREEMPTED result) with actionlib's ``GoalID`` semantics
  (``ActionServerBase::cancelCallback``, ``action_server_base.h``; rospy
  ``ActionServer.internal_cancel_callback``): an empty id and a zero stamp cancel every
  goal, an id cancels that goal (or, not yet received, recalls it when it comes), a
  non-zero stamp cancels every goal stamped at or before it and recalls those that come
  later so stamped. It holds at most ``max_pending`` goals (more are REJECTED at once
  with the status text "buffer server busy: ...") and waits at most ``max_wait`` seconds
  for one (tf2_ros's server waits for as long as the goal asks, up to 2**31 s).

A goal, cancel request or result that does not decode is counted and dropped; so is an
answer ROS 1 cannot carry (a stamp at or after 2**32 s). The connections, their bounds
and the loopback rules are the transport's (:class:`~tfbus.transports.ros1.Ros1Transport`).
"""

from __future__ import annotations

import logging
import math
import time as _wallclock
import weakref
from typing import TYPE_CHECKING, Any, Final, Protocol, TypeVar

import anyio
import anyio.abc

from tfbus import errors
from tfbus._aio import coroutine_method
from tfbus.codecs.ros1 import (
    GOAL_ID_MD5,
    GOAL_ID_TYPE,
    GOAL_STATUS_ARRAY_MD5,
    GOAL_STATUS_ARRAY_TYPE,
    LOOKUP_FEEDBACK_MD5,
    LOOKUP_FEEDBACK_TYPE,
    LOOKUP_GOAL_MD5,
    LOOKUP_GOAL_TYPE,
    LOOKUP_RESULT_MD5,
    LOOKUP_RESULT_TYPE,
    decode_goal_id,
    decode_lookup_goal,
    decode_lookup_result,
    encode_goal_id,
    encode_goal_status_array,
    encode_lookup_goal,
    encode_lookup_result,
)
from tfbus.errors import TransformException
from tfbus.messages import (
    Header,
    LookupTransformGoal,
    LookupTransformResult,
    Transform,
    TransformStamped,
)
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import Duration, Time
from tfbus.transports._base import (
    LOOKUPS_OWN_ERROR,
    ServerStatistics,
    action_client_limits,
    goal_timeout,
    refuse_fail_fast,
    transform_remotely,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from tfbus.buffer import Buffer


class RawTopicNode(Protocol):
    """The part of :class:`~tfbus.transports.ros1.Ros1Transport` the action uses: its
    topics of any ROS 1 type as serialised bytes, and its node's name."""

    @property
    def node_name(self) -> str:
        """The node's caller id."""
        ...

    def subscribe_raw(self, topic: str, msg_type: str, md5: str,
                      handler: Callable[[bytes, str], None]) -> None:
        """Subscribe to ``topic``; ``handler(payload, callerid)`` per message."""
        ...

    def advertise_raw(self, topic: str, msg_type: str, md5: str) -> None:
        """Register as a publisher of ``topic``."""
        ...

    def send_raw_nowait(self, topic: str, payload: bytes) -> None:
        """Queue ``payload`` for every subscriber of ``topic``."""
        ...

    def connections(self, topic: str) -> tuple[int, int]:
        """``(publishers, subscribers)`` of ``topic`` connected now."""
        ...

__all__ = [
    "DEFAULT_ACTION",
    "MAX_GOAL_ID_BYTES",
    "MAX_HELD_GOAL_BYTES",
    "ActionClient",
    "LookupActionClient",
    "LookupActionServer",
    "RawTopicNode",
    "action_client",
    "result_transform",
]

DEFAULT_ACTION: Final = "/tf2_buffer_server"
"""tf2_ros's action namespace (the ``buffer_server`` node's name)."""
# actionlib_msgs/GoalStatus
_ACTIVE: Final = 1
_PREEMPTED: Final = 2
_SUCCEEDED: Final = 3
_REJECTED: Final = 5
_RECALLED: Final = 8
_STATUS_NAMES: Final = {0: "PENDING", 1: "ACTIVE", 2: "PREEMPTED", 3: "SUCCEEDED",
                        4: "ABORTED", 5: "REJECTED", 6: "PREEMPTING", 7: "RECALLING",
                        8: "RECALLED", 9: "LOST"}
_RECALLED_BY_STAMP: Final = (
    "This goal handle was canceled by the action server because its timestamp is before "
    "the timestamp of the last cancel request")  # actionlib ActionServerBase::goalCallback
MAX_GOAL_ID_BYTES: Final = 1024
"""Longest goal id (bytes) :class:`LookupActionServer` holds; a longer one is counted as
malformed (actionlib's ids, ``/node-count-secs.nsecs``, are tens of bytes)."""
MAX_HELD_GOAL_BYTES: Final = 32 << 20
"""Most bytes of goals :class:`LookupActionServer` holds at once (with ``max_pending``)."""
_STATUS_KEPT: Final = 5.0  # actionlib's status_list_timeout: a finished goal stays listed

_log = logging.getLogger("tfbus.remote")
_peer_log = CountLimitedLog(_log, 1, period=5.0, clock=_wallclock.monotonic)
_Answer = tuple[TransformStamped, int, str, int, str]  # transform, code, message, status, text
_M = TypeVar("_M")


def result_transform(ts: TransformStamped, code: int, message: str, status: int,
                     text: str) -> TransformStamped:
    """The transform of a decoded ``LookupTransformActionResult``
    (:func:`~tfbus.codecs.ros1.decode_lookup_result`), or its error raised as tf2_ros's
    ``BufferClient`` does (``buffer_client.py`` ``__process_goal`` / ``__process_result``).

    Raises:
        TimeoutException: the goal's status is not SUCCEEDED (REJECTED, PREEMPTED,
            RECALLED...; tf2_ros's message, the status and its text appended).
        LookupException, ConnectivityException, ExtrapolationException,
            InvalidArgumentException, TimeoutException, TransformException: the
            ``TF2Error`` code 1..6, with the server's message.
    """
    if status != _SUCCEEDED:  # tf2_ros buffer_client.py __process_goal
        raise errors.TimeoutException(
            "The LookupTransform goal sent to the BufferServer did not come back with "
            "SUCCEEDED status. Something is likely wrong with the server. Status was "
            f"{_STATUS_NAMES.get(status, status)}: {text[:200]}")
    if code == 3:  # tf2_msgs/TF2Error has one extrapolation code: the text tells which
        raise errors.extrapolation_exception(message)
    if code:
        raise errors.tf2_error(code, message)
    return ts


class _Held:
    """A goal the server holds: its task's cancel scope, once it runs."""

    __slots__ = ("cancel_requested", "goal", "scope", "size")

    def __init__(self, goal: LookupTransformGoal, size: int) -> None:
        self.goal = goal
        self.size = size
        self.scope: anyio.CancelScope | None = None
        self.cancel_requested = False

    def cancel(self) -> None:
        self.cancel_requested = True
        if self.scope is not None:
            self.scope.cancel()


def _action_ns(name: str) -> str:
    """``name`` as a global action namespace (``tf2_buffer_server`` ->
    ``/tf2_buffer_server``).

    Raises:
        ValueError: an empty name, or one that is not a ROS graph name.
    """
    ns = "/" + name.strip("/")
    if ns == "/" or "//" in ns or not all(c.isalnum() or c in "/_" for c in ns):
        raise ValueError(f"name {name!r} is not a ROS graph name for the action")
    return ns


class _ServerSlot:
    """The action server topics of one name on one transport, registered once: their
    handlers forward to the server answering now (:attr:`server`, or nobody)."""

    __slots__ = ("server",)

    def __init__(self) -> None:
        self.server: LookupActionServer | None = None

    def on_goal(self, raw: bytes, callerid: str) -> None:
        if self.server is not None:
            self.server._on_goal(raw, callerid)

    def on_cancel(self, raw: bytes, callerid: str) -> None:
        if self.server is not None:
            self.server._on_cancel(raw, callerid)


_server_slots: weakref.WeakKeyDictionary[Any, dict[str, _ServerSlot]] = \
    weakref.WeakKeyDictionary()


def _server_slot(transport: RawTopicNode, topics: dict[str, str]) -> _ServerSlot:
    """The slot of the action whose topics are ``topics`` on ``transport``, its topics
    subscribed and advertised on first use.

    Raises:
        ValueError: a topic is carried otherwise on the transport.
    """
    slots = _server_slots.setdefault(transport, {})
    slot = slots.get(topics["goal"])
    if slot is None:
        slot = _ServerSlot()
        transport.subscribe_raw(topics["goal"], LOOKUP_GOAL_TYPE, LOOKUP_GOAL_MD5, slot.on_goal)
        transport.subscribe_raw(topics["cancel"], GOAL_ID_TYPE, GOAL_ID_MD5, slot.on_cancel)
        transport.advertise_raw(topics["result"], LOOKUP_RESULT_TYPE, LOOKUP_RESULT_MD5)
        transport.advertise_raw(topics["feedback"], LOOKUP_FEEDBACK_TYPE, LOOKUP_FEEDBACK_MD5)
        transport.advertise_raw(topics["status"], GOAL_STATUS_ARRAY_TYPE, GOAL_STATUS_ARRAY_MD5)
        slots[topics["goal"]] = slot
    return slot


class LookupActionServer:
    """tf2_ros ``buffer_server`` answering from ``buffer`` on the topics of ``transport``
    (module doc): ``async with LookupActionServer(transport, buffer):`` while the
    transport runs (inside ``async with bus:``); :class:`tfbus.remote.BufferServer` makes
    it for a ROS 1 bus.

    Goals wait on ``buffer`` for at most their timeout and at most ``max_wait`` seconds
    (of the buffer's clock, and of wall time), then are answered with the lookup's own
    result or error (``buffer_server.cpp`` ``checkTransforms``). A cancel request
    (``actionlib_msgs/GoalID`` on ``{name}/cancel``) ends the goals it names at once
    with a PREEMPTED result (module doc). At most ``max_pending`` goals, and at most
    :data:`MAX_HELD_GOAL_BYTES` of them, are held; more are answered at once with a
    REJECTED result whose status text says "buffer server busy: ...". The status array
    (5 Hz) lists the goals held (ACTIVE) and those ended in the last 5 s (actionlib's
    ``status_list_timeout``), so that actionlib clients follow them.

    The action's topics stay registered on the transport's node until it closes (ROS 1
    has no per-topic end here); after ``__aexit__`` goals are ignored and no status is
    sent, and another server of the same name may answer on them. One server of a name
    answers on a transport at a time.

    Args:
        transport: the ROS 1 transport whose node carries the action.
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from (its clock bounds the
            goals' timeouts).
        name: the action's namespace (default ``/tf2_buffer_server``, the real node's).
        max_pending: most goals held at once.
        max_wait: longest wait of one goal, seconds (default 60).

    Raises:
        ValueError: ``name`` is not a ROS graph name, ``max_pending`` < 1, or ``max_wait``
            not a positive finite number.
    """

    def __init__(self, transport: RawTopicNode, buffer: Buffer, *,
                 name: str = DEFAULT_ACTION, max_pending: int = 1000,
                 max_wait: float = 60.0) -> None:
        if isinstance(max_pending, bool) or not isinstance(max_pending, int) \
                or max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending!r}")
        if isinstance(max_wait, bool) or not isinstance(max_wait, (int, float)) \
                or not 0 < max_wait < math.inf:
            raise ValueError(f"max_wait must be positive finite seconds, got {max_wait!r}")
        self._transport = transport
        self._buffer = buffer
        self.name = _action_ns(name)
        """The action's namespace (``/tf2_buffer_server``)."""
        self._topics = {k: f"{self.name}/{k}" for k in ("goal", "cancel", "result",
                                                         "feedback", "status")}
        self._max_pending = max_pending
        self._max_wait = float(max_wait)
        self._held: dict[str, _Held] = {}
        self._held_bytes = 0
        # goals ended lately, for the status array: id -> (stamp, status, text, when)
        self._ended: dict[str, tuple[Time, int, str, float]] = {}
        self._recall: dict[str, None] = {}  # cancelled by id before they came (bounded)
        self._last_cancel = Time(0)
        self._tg: anyio.abc.TaskGroup | None = None
        self._stats = ServerStatistics()

    def statistics(self) -> ServerStatistics:
        """A copy of the counters (:class:`~tfbus.transports._base.ServerStatistics`):
        ``requests`` goals received, ``answered`` with a transform, ``errors`` with a
        ``TF2Error``, ``busy`` REJECTED, ``cancelled`` PREEMPTED or RECALLED,
        ``malformed`` goals and cancel requests that did not decode (or whose goal id is
        longer than :data:`MAX_GOAL_ID_BYTES`), ``unsendable`` answers ROS 1 cannot carry
        (a stamp at or after 2**32 s), ``pending`` goals held now."""
        s = self._stats
        return ServerStatistics(s.requests, s.answered, s.errors, s.malformed, s.busy,
                                s.cancelled, len(self._held), s.unsendable)

    @property
    def where(self) -> str:
        """Where the server answers, for log lines: the action's namespace and type, and
        the node that carries it."""
        return (f"the ROS 1 action {self.name} (tf2_msgs/LookupTransform) of node "
                f"{self._transport.node_name}")

    async def __aenter__(self) -> LookupActionServer:
        """Subscribe to ``goal`` and ``cancel`` and advertise ``result``, ``feedback``
        and ``status`` on the transport's node; publish status at 5 Hz.

        Raises:
            RuntimeError: the server is running already, or another server of this
                transport answers the same name now.
            ValueError: the action's topics are carried otherwise on this transport
                (e.g. by an :class:`ActionClient` of the same name).
        """
        if self._tg is not None:
            raise RuntimeError("this LookupActionServer is already running")
        slot = _server_slot(self._transport, self._topics)
        if slot.server is not None:
            raise RuntimeError(f"another server answers {self.name} on this transport")
        slot.server = self
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        tg.start_soon(self._status)
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Stop the status and end the goals still waiting (unanswered)."""
        tg, self._tg = self._tg, None
        if tg is not None:
            slot = _server_slot(self._transport, self._topics)
            if slot.server is self:
                slot.server = None
            tg.cancel_scope.cancel()
            await tg.__aexit__(None, None, None)

    async def _status(self) -> None:
        while True:
            now = Time.from_ns(_wallclock.time_ns())
            self._transport.send_raw_nowait(self._topics["status"],
                                            encode_goal_status_array(now, self._status_list()))
            await anyio.sleep(0.2)

    def _status_list(self) -> list[tuple[str, Time, int, str]]:
        """The ``status_list`` of a ``GoalStatusArray``: the goals held (ACTIVE), then
        those ended within the last 5 s (the older ones forgotten)."""
        horizon = _wallclock.monotonic() - _STATUS_KEPT
        ended = self._ended
        while ended:
            oldest = next(iter(ended))
            if ended[oldest][3] >= horizon:
                break
            del ended[oldest]
        parts = [(h.goal.goal_id, h.goal.goal_stamp, _ACTIVE, "")
                 for h in self._held.values()]
        parts += [(goal_id, stamp, status, text)
                  for goal_id, (stamp, status, text, _when) in ended.items()]
        return parts

    def _on_goal(self, raw: bytes, _callerid: str = "") -> None:
        if self._tg is None:
            return
        self._stats.requests += 1
        try:
            goal = decode_lookup_goal(raw)
        except ValueError:
            self._stats.malformed += 1
            return
        if len(goal.goal_id) > MAX_GOAL_ID_BYTES // 4 \
                and len(goal.goal_id.encode()) > MAX_GOAL_ID_BYTES:
            self._stats.malformed += 1
            return
        if goal.goal_id in self._held or goal.goal_id in self._ended:
            return  # actionlib ActionServerBase::goalCallback: a known goal is ignored
        by_id = goal.goal_id in self._recall
        if by_id or (goal.goal_stamp != Time(0) and goal.goal_stamp <= self._last_cancel):
            # actionlib goalCallback: a goal cancelled before it came is RECALLED
            self._recall.pop(goal.goal_id, None)
            text = "" if by_id else _RECALLED_BY_STAMP
            self._stats.cancelled += 1
            self._end(goal, _RECALLED, text)
            return
        if len(self._held) >= self._max_pending \
                or self._held_bytes + len(raw) > MAX_HELD_GOAL_BYTES:
            self._stats.busy += 1
            self._end(goal, _REJECTED, f"buffer server busy: {len(self._held)} goals waiting "
                                       f"({self._held_bytes} bytes; max_pending "
                                       f"{self._max_pending})")
            return
        held = _Held(goal, len(raw))
        self._held[goal.goal_id] = held
        self._held_bytes += held.size
        self._tg.start_soon(self._answer, held)

    def _on_cancel(self, raw: bytes, _callerid: str = "") -> None:
        """actionlib ``ActionServerBase::cancelCallback`` (``action_server_base.h``) with
        tf2_ros ``BufferServer::cancelCB`` (``buffer_server.cpp``) as the cancel callback:
        an empty id and a zero stamp cancel every goal held; an id, that goal; a non-zero
        stamp, every goal stamped at or before it. An id not held is kept (bounded) so
        that its goal is RECALLED when it comes; the latest stamp is kept so that goals
        stamped at or before it are RECALLED when they come."""
        if self._tg is None:
            return
        try:
            stamp, goal_id = decode_goal_id(raw)
        except ValueError:
            self._stats.malformed += 1
            return
        if len(goal_id) > MAX_GOAL_ID_BYTES // 4 and len(goal_id.encode()) > MAX_GOAL_ID_BYTES:
            self._stats.malformed += 1
            return
        everything = goal_id == "" and stamp == Time(0)
        found = goal_id in self._ended
        for held in list(self._held.values()):
            g = held.goal
            if everything or g.goal_id == goal_id or (stamp != Time(0)
                                                        and g.goal_stamp <= stamp):
                found = found or g.goal_id == goal_id
                held.cancel()
        if goal_id and not found:
            self._recall[goal_id] = None
            while len(self._recall) > self._max_pending:
                del self._recall[next(iter(self._recall))]
        if stamp > self._last_cancel:
            self._last_cancel = stamp

    def _end(self, goal: LookupTransformGoal, status: int, text: str) -> None:
        """Send a goal's result with ``status`` (no transform) and list it as ended."""
        self._send_result(goal, TransformStamped(Header(), "", Transform()), 0, "",
                          status, text)

    def _send_result(self, goal: LookupTransformGoal, ts: TransformStamped, code: int,
                     message: str, status: int = _SUCCEEDED, text: str = "") -> bool:
        try:
            result = encode_lookup_result(LookupTransformResult(
                ts, code, message, goal.goal_id, goal.goal_stamp, status, text,
                Time.from_ns(_wallclock.time_ns())))
        except ValueError as exc:  # a stamp past ROS 1 time
            self._stats.unsendable += 1
            _peer_log.log(logging.WARNING, "ros1: %s: not answering goal %r: %s",
                          self.name, goal.goal_id[:200], exc)
            return False
        self._ended[goal.goal_id] = (goal.goal_stamp, status, text, _wallclock.monotonic())
        while len(self._ended) > self._max_pending:
            del self._ended[next(iter(self._ended))]
        self._transport.send_raw_nowait(self._topics["result"], result)
        return True

    def _answered(self, goal: LookupTransformGoal,
                  answer: tuple[TransformStamped, int, str]) -> None:
        if self._send_result(goal, *answer):
            if answer[1]:
                self._stats.errors += 1
            else:
                self._stats.answered += 1

    async def _answer(self, held: _Held) -> None:
        goal = held.goal
        try:
            with anyio.CancelScope() as scope:
                held.scope = scope
                if held.cancel_requested:
                    scope.cancel()
                with anyio.move_on_after(self._max_wait):
                    self._answered(goal, await self._lookup(
                        goal, min(goal.timeout, self._max_wait)))
                    return
                # past max_wait of wall time: answered as an expired timeout
                self._answered(goal, await self._lookup(goal, 0.0))
                return
            if self._tg is None:
                return  # the server ends: the goal is dropped unanswered
            # tf2_ros BufferServer::cancelCB: setCanceled() on the active goal: PREEMPTED
            self._stats.cancelled += 1
            self._end(goal, _PREEMPTED, "")
        finally:
            del self._held[goal.goal_id]
            self._held_bytes -= held.size

    async def _lookup(self, goal: LookupTransformGoal,
                      timeout: float) -> tuple[TransformStamped, int, str]:
        """The goal's transform, or its ``TF2Error`` code and message (at the timeout,
        or for an argument that can never be valid, the synchronous lookup's own:
        :data:`~tfbus.transports._base.LOOKUPS_OWN_ERROR`)."""
        buffer = self._buffer
        g = goal
        try:
            if g.advanced:
                try:
                    ts = await buffer.lookup_transform_full_async(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame, timeout)
                except LOOKUPS_OWN_ERROR:  # buffer_server.cpp: lookup's own error
                    ts = buffer.lookup_transform_full(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame)
            else:
                try:
                    ts = await buffer.lookup_transform_async(
                        g.target_frame, g.source_frame, g.source_time, timeout)
                except LOOKUPS_OWN_ERROR:
                    ts = buffer.lookup_transform(g.target_frame, g.source_frame,
                                                 g.source_time)
        except TransformException as exc:
            code = errors.tf2_error_code(exc)
            return TransformStamped(Header(), "", Transform()), code, str(exc)
        return ts, 0, ""


class ActionClient:
    """actionlib's ``SimpleActionClient`` of the ``LookupTransform`` action at namespace
    ``ns`` on a ROS 1 transport (one per namespace and transport: use
    :func:`action_client`; make it in the transport's event loop).

    Attributes:
        malformed: results that did not decode (counted, dropped).
        cancelled: goals cancelled on the server because their wait ended here first.
    """

    def __init__(self, transport: RawTopicNode, ns: str) -> None:
        """Advertise ``goal`` and ``cancel`` and subscribe to ``result`` and ``status``
        under ``ns`` (made global: ``tf2_buffer_server`` is ``/tf2_buffer_server``).

        Raises:
            ValueError: ``ns`` is not a ROS graph name, or its topics are carried already.
        """
        base = _action_ns(ns)
        self.ns = base
        self._transport = transport
        self.goal_topic, self.cancel_topic = f"{base}/goal", f"{base}/cancel"
        self.result_topic, self.status_topic = f"{base}/result", f"{base}/status"
        transport.advertise_raw(self.goal_topic, LOOKUP_GOAL_TYPE, LOOKUP_GOAL_MD5)
        transport.advertise_raw(self.cancel_topic, GOAL_ID_TYPE, GOAL_ID_MD5)
        transport.subscribe_raw(self.result_topic, LOOKUP_RESULT_TYPE, LOOKUP_RESULT_MD5,
                                self._on_result)
        transport.subscribe_raw(self.status_topic, GOAL_STATUS_ARRAY_TYPE,
                                GOAL_STATUS_ARRAY_MD5, self._on_status)
        self._waiting: dict[str, tuple[anyio.Event, list[_Answer]]] = {}
        self._status = anyio.Event()
        self._seq = 0
        self.malformed = 0
        self.cancelled = 0

    def ready(self) -> bool:
        """actionlib ``ActionClient::waitForServer``'s condition: the server's node
        reads our ``goal`` and ``cancel`` and we receive its ``result`` and ``status``."""
        c = self._transport.connections
        return bool(c(self.goal_topic)[1] and c(self.cancel_topic)[1]
                    and c(self.result_topic)[0] and c(self.status_topic)[0])

    async def wait_ready(self) -> None:
        """Wait until :meth:`ready`: checked as each status message arrives (the
        server's ``GoalStatusArray`` at its ``status_frequency``, 5 Hz by default)."""
        while not self.ready():
            await self._status.wait()

    def _on_status(self, _payload: bytes, _callerid: str) -> None:
        event, self._status = self._status, anyio.Event()
        event.set()

    def _on_result(self, payload: bytes, _callerid: str) -> None:
        try:
            result = decode_lookup_result(payload)
        except ValueError:
            self.malformed += 1
            return
        waiting = self._waiting.get(result.goal_id)
        if waiting is not None and not waiting[1]:
            waiting[1].append((result.transform, result.error, result.error_string,
                               result.status, result.status_text))
            waiting[0].set()

    async def lookup(self, target: str, source: str, source_time: Time, timeout: float,
                     target_time: Time, fixed: str, advanced: bool,
                     padding: float) -> TransformStamped:
        """Send one goal and wait for its result at most ``timeout + padding`` wall
        seconds (tf2_ros ``BufferClient.__process_goal``: ``wait_for_result(goal.timeout
        + self.timeout_padding)``), waiting for the server first within the same bound.
        A goal whose wait ends here unanswered (the bound, or a cancellation) is
        cancelled on the server (``actionlib_msgs/GoalID`` with its id, as actionlib's
        ``ClientGoalHandle.cancel``), so the server does not hold it for nobody.

        Raises:
            TimeoutException: no result within the bound (tf2_ros's message), or a
                result whose status is not SUCCEEDED.
            ValueError: a time at or after 2**32 s (past ROS 1 time).
            the server's tf2 error, as :func:`result_transform`.
        """
        goal = LookupTransformGoal(target, source, source_time, timeout, target_time, fixed,
                                   advanced)
        encode_lookup_goal(goal)  # checks the times before anything is sent
        self._seq += 1
        now = _wallclock.time_ns()
        # actionlib's GoalIDGenerator: "<caller id>-<count>-<secs>.<nsecs>"
        goal_id = (f"{self._transport.node_name}-{self._seq}-{now // 1_000_000_000}."
                   f"{now % 1_000_000_000:09d}")
        done = anyio.Event()
        box: list[_Answer] = []
        self._waiting[goal_id] = (done, box)
        sent = False
        try:
            with anyio.move_on_after(timeout + padding):
                await self.wait_ready()
                self._transport.send_raw_nowait(self.goal_topic, encode_lookup_goal(
                    goal._replace(goal_id=goal_id,
                                  goal_stamp=Time.from_ns(_wallclock.time_ns()))))
                sent = True
                await done.wait()
        finally:
            self._waiting.pop(goal_id, None)
            if sent and not box:
                self.cancelled += 1
                self._transport.send_raw_nowait(self.cancel_topic,
                                                encode_goal_id(Time(0), goal_id))
        if not box:
            raise errors.TimeoutException(  # tf2_ros buffer_client.py's words, as they are
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server")
        return result_transform(*box[0])


_clients: weakref.WeakKeyDictionary[Any, dict[str, ActionClient]] = \
    weakref.WeakKeyDictionary()


def action_client(transport: RawTopicNode, ns: str) -> ActionClient:
    """The :class:`ActionClient` of ``ns`` on ``transport``, made on first use (one per
    namespace and transport: its topics are the node's; call it in the transport's event
    loop).

    Raises:
        ValueError: ``ns`` is not a ROS graph name.
    """
    clients = _clients.setdefault(transport, {})
    key = _action_ns(ns)
    if key not in clients:
        clients[key] = ActionClient(transport, key)
    return clients[key]


class LookupActionClient:
    """:class:`~tfbus.buffer.Buffer`'s awaitable lookups answered by a ``LookupTransform``
    action server over ROS 1 (tf2_ros ``BufferClient``, ``buffer_client.py``; Debian's
    ``buffer_server`` or :class:`LookupActionServer`), through the :class:`ActionClient`
    of ``name`` on ``transport``'s node; :class:`tfbus.remote.BufferClient` makes it for a
    ROS 1 bus.

    Timeouts are seconds of the **server's** clock (the goal's ``timeout``); the wait
    here is bounded by ``timeout + timeout_padding`` wall seconds (tf2_ros's
    ``timeout_padding``, 2 s), within which the server must also be connected. A timeout
    of None sends ``max_wait``. A lookup cancelled here (or not answered in time) is
    cancelled on the server too (``actionlib_msgs/GoalID`` with its goal id on
    ``{name}/cancel``).

    Args:
        transport: the ROS 1 transport whose node carries the action's client topics.
        name: the action's namespace (default ``/tf2_buffer_server``).
        timeout_padding: wall seconds added to each timeout for the round trip.
        max_wait: the goal timeout sent for a timeout of None, seconds.

    Raises:
        ValueError: ``name`` is not a ROS graph name, ``timeout_padding`` is negative or
            not finite, or ``max_wait`` is not positive finite.
    """

    def __init__(self, transport: RawTopicNode, *, name: str = DEFAULT_ACTION,
                 timeout_padding: float = 2.0, max_wait: float = 3600.0) -> None:
        self._padding, self._max_wait = action_client_limits(timeout_padding, max_wait)
        self._transport = transport
        self.name = _action_ns(name)
        """The action's namespace."""

    @property
    def client(self) -> ActionClient:
        """The transport's :class:`ActionClient` of this namespace (made on first use)."""
        return action_client(self._transport, self.name)

    def _seconds(self, timeout: float | Duration | None) -> float:
        return goal_timeout(timeout, self._max_wait)

    @coroutine_method
    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration | None = None, *,
                               fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``: the server waits up to ``timeout``
        seconds of its clock (:meth:`tfbus.buffer.Buffer.lookup_transform_async`).

        Raises:
            The server's tf2 error as the same tfbus class (its message kept);
            TimeoutException if no result came within ``timeout + timeout_padding``
            wall seconds, or the result's status is not SUCCEEDED (the goal was
            REJECTED, PREEMPTED or RECALLED; tf2_ros's messages, the status and its text
            appended); ValueError for a negative or non-finite timeout, a time at or
            after 2**32 s (past ROS 1 time), or ``fail_fast=True`` (the action's goal
            cannot carry it).
        """
        refuse_fail_fast(fail_fast, "ROS 1")
        seconds = self._seconds(timeout)
        return await self.client.lookup(target_frame, source_frame, time, seconds, Time(0),
                                        "", False, self._padding)

    @coroutine_method
    async def lookup_transform_full(self, target_frame: str, target_time: Time,
                                    source_frame: str, source_time: Time, fixed_frame: str,
                                    timeout: float | Duration | None = None, *,
                                    fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform_full`` (the advanced goal: time travel
        through ``fixed_frame``).

        Raises: as :meth:`lookup_transform`.
        """
        refuse_fail_fast(fail_fast, "ROS 1")
        seconds = self._seconds(timeout)
        return await self.client.lookup(target_frame, source_frame, source_time, seconds,
                                        target_time, fixed_frame, True, self._padding)

    @coroutine_method
    async def can_transform(self, target_frame: str, source_frame: str, time: Time,
                            timeout: float | Duration | None = None, *,
                            fail_fast: bool = False) -> bool:
        """Whether the server answers the lookup with a transform within ``timeout``
        (tf2_ros ``BufferClient.can_transform``: a lookup whose TransformException
        means False).

        Raises:
            ValueError: as :meth:`lookup_transform`.
        """
        refuse_fail_fast(fail_fast, "ROS 1")
        try:
            await self.lookup_transform(target_frame, source_frame, time, timeout)
        except TransformException:
            return False
        return True

    @coroutine_method
    async def transform(self, obj: _M, target_frame: str,
                        timeout: float | Duration | None = None, *,
                        fail_fast: bool = False) -> _M:
        """Express a stamped object in ``target_frame`` (tf2_ros
        ``BufferClient.transform``): the lookup is remote, the function registered for
        ``type(obj)`` (:mod:`tfbus.convert`) is applied here. ``fail_fast=True`` is a
        ValueError, as in :meth:`lookup_transform`.

        Raises:
            TypeError: no transform function for ``type(obj)`` (before any goal).
            The lookup's errors, as :meth:`lookup_transform`.
        """
        return await transform_remotely(self, obj, target_frame, timeout, fail_fast)
