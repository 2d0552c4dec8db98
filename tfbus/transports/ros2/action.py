"""tf2_ros's buffer protocol on ROS 2: the ``tf2_msgs/action/LookupTransform`` action
over DDS, both ends, on the DomainParticipant of a running
:class:`~tfbus.transports.ros2.Ros2Transport` (one participant per transport: the one
that carries ``/tf`` carries the action too).

**Wire** (rcl_action ``names.c``; rmw_dds_common's ``rq``/``rr``/``rt`` prefixes; samples
by :mod:`tfbus.codecs.lookup_action_cdr`), for the action ``/tf2_buffer_server``:

* services ``rq/tf2_buffer_server/_action/send_goalRequest`` /
  ``rr/tf2_buffer_server/_action/send_goalReply`` (types
  ``tf2_msgs::action::dds_::LookupTransform_SendGoal_Request_`` / ``..._Response_``),
  ``.../get_resultRequest`` / ``...Reply`` (``LookupTransform_GetResult_*``),
  ``.../cancel_goalRequest`` / ``...Reply`` (``action_msgs::srv::dds_::CancelGoal_*``);
* topics ``rt/tf2_buffer_server/_action/status``
  (``action_msgs::msg::dds_::GoalStatusArray_``; reliable, transient-local, keep-last 1:
  rcl_action's ``rcl_action_qos_profile_status_default``) and ``.../feedback``
  (``LookupTransform_FeedbackMessage_``; tf2_ros's server sends no feedback);
* service QoS ``rmw_qos_profile_services_default`` (reliable, volatile); every endpoint's
  user data carries ``typehash=RIHS01_...;`` (REP-2011, the hashes of the rosidl-generated
  ``LookupTransform.json``) and, on service endpoints, rmw_cyclonedds_cpp's
  ``clientid=``/``serviceid=`` (which request writer and reply reader belong together);
* every request and reply starts with rmw_cyclonedds_cpp's request header (the client's
  64-bit id and the request's sequence number, :class:`RequestId`).

That is rmw_cyclonedds_cpp's mapping: ROS 2 nodes on Cyclone DDS are peers. rmw_fastrtps_cpp
matches the endpoints (its graph sees the server) but carries the request identity out
of band, which Cyclone DDS cannot write, so its clients never accept a reply from a
Cyclone server (and the other way round): services do not interoperate across DDS vendors
(rmw_fastrtps_shared_cpp ``__rmw_take_response`` keeps only the replies whose
``related_sample_identity`` names its own writer or reader). :class:`LookupActionClient`
therefore sends no goal to a Fast DDS server and says so (TransportError).

* :class:`LookupActionServer` is tf2_ros ``buffer_server`` (``buffer_server.cpp``): every
  goal is accepted (up to ``max_pending``, ``max_per_peer`` per client; more are answered
  ``accepted=False``), waits on the buffer for at most its timeout and ``max_wait``, and
  ends SUCCEEDED with the lookup's transform or its ``TF2Error``; a cancel request ends
  the goals it names CANCELED (rcl_action's cancel semantics: a zero id and stamp cancel
  every goal, an id that goal, a stamp every goal accepted at or before it); a goal whose
  client left (its request writer no longer matched) is cancelled. Results are kept for
  ``get_result`` (the last ``max_pending``, for ``result_timeout`` seconds).
* :class:`LookupActionClient` is tf2_ros ``BufferClient`` (``buffer_client.py``) with
  :class:`~tfbus.buffer.Buffer`'s awaitable lookups.

A request that does not decode is counted (``malformed``) and dropped; so is a reply. A
Fast DDS client's request (no request header) does not fit the request type: Cyclone's
deserialisation drops it before the server sees it (Cyclone logs "deserialization ...
failed"), so it is never misread as a goal.
"""

from __future__ import annotations

import contextlib
import logging
import math
import secrets
import time as _wallclock
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final, Protocol, TypeVar

import anyio
import anyio.abc
from cyclonedds import _clayer
from cyclonedds.core import InstanceState, Listener, SampleState, ViewState
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from tfbus import errors
from tfbus._aio import coroutine_method
from tfbus.codecs.lookup_action_cdr import (
    GoalInfo,
    LookupGoal,
    LookupResult,
    RequestId,
    decode_cancel_goal_request,
    decode_cancel_goal_response,
    decode_get_result_request,
    decode_get_result_response,
    decode_send_goal_request,
    decode_send_goal_response,
    encode_cancel_goal_request,
    encode_cancel_goal_response,
    encode_get_result_request,
    encode_get_result_response,
    encode_goal_status_array,
    encode_send_goal_request,
    encode_send_goal_response,
)
from tfbus.errors import TransformException, TransportError, WireDecodeError, WireEncodeError
from tfbus.messages import Header, Transform, TransformStamped
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import Duration, Time
from tfbus.transports._base import (
    DEFAULT_MAX_WAIT,
    LOOKUPS_OWN_ERROR,
    ServerStatistics,
    ThreadWakeup,
    action_client_limits,
    goal_timeout,
    refuse_fail_fast,
    transform_remotely,
)
from tfbus.transports.ros2.dds import (
    CancelGoalRequest_,
    CancelGoalResponse_,
    FeedbackMessage_,
    GetResultRequest_,
    GetResultResponse_,
    GoalStatusArray_,
    SendGoalRequest_,
    SendGoalResponse_,
)

if TYPE_CHECKING:
    from cyclonedds.domain import DomainParticipant

    from tfbus.buffer import Buffer

__all__ = [
    "DEFAULT_ACTION",
    "TYPE_HASHES",
    "LookupActionClient",
    "LookupActionServer",
    "action_topics",
]

DEFAULT_ACTION: Final = "/tf2_buffer_server"
"""tf2_ros's action name (the ``buffer_server`` node's ``tf2_buffer_server``)."""

TYPE_HASHES: Final = {
    "send_goal_request":
        "RIHS01_eb1312eb7aab35e35c71bb87c2ba3a94747c5a6544ea32bb2b32b0f75775b8ca",
    "send_goal_reply":
        "RIHS01_c1ada93304793c08813657255e7bde2e40e2114aa634b702c3f8d4b72ae098bc",
    "get_result_request":
        "RIHS01_148f9bdc01f98922d6fb2072cb64468b89c57c7825d9d83b932c183deaa4697d",
    "get_result_reply":
        "RIHS01_954de3efc36b164c4d21116abdbdcc52746e454fd9c169b55d9cfd89e83d299d",
    "cancel_goal_request":
        "RIHS01_3d3c84653c1f96918086887e1dcb236faec88b81a5b14fd4cf4840065bcdf8af",
    "cancel_goal_reply":
        "RIHS01_35e682cf3f510e83c70a82a4aac888496dedee56773bf9d8e5e0aa81f9e1c960",
    "status": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
    "feedback": "RIHS01_10cb89922dcb103e95c185d43e8a5efa3d38db996f733151a2f3e2ac133f4839",
}
"""REP-2011 type hashes of the action's DDS types (``type_hashes`` of the rosidl-generated
``share/tf2_msgs/action/LookupTransform.json`` and ``action_msgs``' ``CancelGoal.json`` /
``GoalStatusArray.json``, ROS 2 Kilted), as rmw puts them in the endpoints' user data."""

# action_msgs/msg/GoalStatus
_UNKNOWN: Final = 0
_EXECUTING: Final = 2
_SUCCEEDED: Final = 4
_CANCELED: Final = 5
_ABORTED: Final = 6
_STATUS_NAMES: Final = {0: "UNKNOWN", 1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING",
                        4: "SUCCEEDED", 5: "CANCELED", 6: "ABORTED"}
# action_msgs/srv/CancelGoal return codes
_CANCEL_NONE: Final = 0
_CANCEL_REJECTED: Final = 1
_CANCEL_UNKNOWN_GOAL: Final = 2
_CANCEL_TERMINATED: Final = 3
_ZERO_ID: Final = bytes(16)
_FAST_DDS_VENDOR: Final = b"\x01\x0f"  # eProsima's RTPS vendor id

_EMPTY: Final = TransformStamped(Header(), "", Transform())
_ANY_STATE: Final = SampleState.Any | ViewState.Any | InstanceState.Any
_MAX_TAKE: Final = 256
_MAX_RESULT_WAITERS: Final = 8  # get_result requests kept per goal still running
_TICK: Final = 0.2  # status publication and client-presence checks, seconds
_RESEND: Final = 1.0  # a client re-asks an unanswered request (idempotent) this often
_log = logging.getLogger("tfbus.remote")
_peer_log = CountLimitedLog(_log, 1, period=5.0, clock=_wallclock.monotonic)
_M = TypeVar("_M")


_SERVICES: Final = {  # service -> (request type, reply type)
    "send_goal": (SendGoalRequest_, SendGoalResponse_),
    "get_result": (GetResultRequest_, GetResultResponse_),
    "cancel_goal": (CancelGoalRequest_, CancelGoalResponse_),
}


def _action_name(name: str) -> str:
    """``name`` as a fully qualified ROS 2 name (``tf2_buffer_server`` ->
    ``/tf2_buffer_server``).

    Raises:
        ValueError: an empty name or one that is not a ROS graph name.
    """
    full = "/" + name.strip("/") if isinstance(name, str) else ""
    tokens = full[1:].split("/")
    if full == "/" or not all(
        t and t.replace("_", "a").isascii() and t.replace("_", "a").isalnum()
        and not t[0].isdigit() for t in tokens
    ):
        raise ValueError(f"name {name!r} is not a ROS graph name for the action")
    return full


def action_topics(name: str) -> dict[str, str]:
    """The DDS topics of the action ``name`` (rcl_action ``names.c``, rmw's prefixes):
    ``{"send_goal_request": "rq/<name>/_action/send_goalRequest", ...,
    "status": "rt/<name>/_action/status", "feedback": ...}``.

    Raises:
        ValueError: ``name`` is not a ROS graph name.
    """
    base = _action_name(name)[1:] + "/_action/"
    out = {}
    for service in _SERVICES:
        out[f"{service}_request"] = f"rq/{base}{service}Request"
        out[f"{service}_reply"] = f"rr/{base}{service}Reply"
    out["status"] = f"rt/{base}status"
    out["feedback"] = f"rt/{base}feedback"
    return out


def _user_data(key: str, endpoint_id: str = "") -> Policy.Userdata:
    return Policy.Userdata(data=f"{endpoint_id}typehash={TYPE_HASHES[key]};".encode())


_XCDR1: Final = Policy.DataRepresentation(use_cdrv0_representation=True)
_SERVICE_QOS: Final = (  # rmw_qos_profile_services_default: reliable, volatile, keep-last 10
    Policy.Durability.Volatile, Policy.History.KeepLast(100), _XCDR1,
)
_WRITE_RELIABLE: Final = Policy.Reliability.Reliable(max_blocking_time=0)
_READ_RELIABLE: Final = Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100))


def _endpoint_id() -> str:
    """rmw_cyclonedds_cpp's client/service id as its user data writes it: 16 octets in
    hex, dot-separated (``csid_to_string``)."""
    raw = secrets.token_bytes(16)
    return ".".join(f"{b:x}" for b in raw)


def _delete(entity: Any) -> None:
    with contextlib.suppress(Exception):  # deleted with its participant already
        entity.__del__()


def _take(reader: DataReader[Any]) -> list[tuple[bytes, Any]]:
    samples = _clayer.ddspy_take(reader._ref, _ANY_STATE, _MAX_TAKE)
    if isinstance(samples, int) or not samples:
        return []
    return [(data, info) for data, info in samples if info.valid_data]


def _write(writer: DataWriter[Any], payload: bytes) -> bool:
    ret = _clayer.ddspy_write(writer._ref, payload)
    return not (isinstance(ret, int) and ret < 0)


class ActionParticipant(Protocol):
    """What the action needs of :class:`~tfbus.transports.ros2.Ros2Transport`: its
    running DomainParticipant, and a call when it closes."""

    def participant(self) -> DomainParticipant:
        """The participant of the running transport.

        Raises:
            RuntimeError: the transport is not running.
        """
        ...

    def on_close(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` when the transport leaves the domain."""
        ...


def _now() -> Time:
    return Time.from_ns(_wallclock.time_ns())


# -- server ---------------------------------------------------------------------------------


class _Goal:
    __slots__ = ("cancel_requested", "client", "goal", "info", "result", "scope", "waiters",
                 "writer")

    def __init__(self, goal: LookupGoal, info: GoalInfo, client: int, writer: int) -> None:
        self.goal = goal
        self.info = info
        self.client = client  # the request header's guid
        self.writer = writer  # the request writer's instance handle (publication_handle)
        self.scope: anyio.CancelScope | None = None
        self.cancel_requested = False
        self.result: LookupResult | None = None
        self.waiters: list[RequestId] = []

    def cancel(self) -> None:
        self.cancel_requested = True
        if self.scope is not None:
            self.scope.cancel()


class LookupActionServer:
    """tf2_ros ``buffer_server`` answering from ``buffer`` over the participant of a
    running ROS 2 transport (module doc): ``async with LookupActionServer(transport,
    buffer):`` inside ``async with bus:``; :class:`tfbus.remote.BufferServer` makes it for
    a ROS 2 bus.

    Args:
        transport: the running :class:`~tfbus.transports.ros2.Ros2Transport`.
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from.
        name: the action's name (default ``/tf2_buffer_server``).
        max_pending: most goals held at once (more are answered ``accepted=False``).
        max_per_peer: most goals one client (request writer) holds at once.
        max_wait: longest wait of one goal, seconds (its timeout is capped to it).
        result_timeout: seconds a finished goal's result is kept for ``get_result``
            (rcl_action's ``result_timeout``; at most ``max_pending`` results are kept).

    Raises:
        ValueError: ``name`` is not a ROS graph name, a bound is not positive (named).
    """

    def __init__(self, transport: ActionParticipant, buffer: Buffer, *,
                 name: str = DEFAULT_ACTION, max_pending: int = 1000,
                 max_per_peer: int = 100, max_wait: float = DEFAULT_MAX_WAIT,
                 result_timeout: float = 60.0) -> None:
        for what, value in (("max_pending", max_pending), ("max_per_peer", max_per_peer)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{what} must be an integer >= 1, got {value!r}")
        for what, seconds in (("max_wait", max_wait), ("result_timeout", result_timeout)):
            if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
                    or not 0 < seconds < math.inf:
                raise ValueError(f"{what} must be positive finite seconds, got {seconds!r}")
        self._transport = transport
        self._buffer = buffer
        self.name = _action_name(name)
        """The action's name (``/tf2_buffer_server``)."""
        self._topics = action_topics(self.name)
        self._max_pending = max_pending
        self._max_per_peer = max_per_peer
        self._max_wait = float(max_wait)
        self._result_timeout = float(result_timeout)
        self._held: dict[bytes, _Goal] = {}
        self._per_client: dict[int, int] = {}
        self._done: dict[bytes, tuple[_Goal, float]] = {}  # finished: goal, when
        self._readers: dict[str, DataReader[Any]] = {}
        self._writers: dict[str, DataWriter[Any]] = {}
        self._entities: list[Any] = []
        self._wakeup: ThreadWakeup | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._status_dirty = False
        self._stats = ServerStatistics()

    @property
    def where(self) -> str:
        """Where the server answers, for log lines."""
        return f"the ROS 2 action {self.name} (tf2_msgs/action/LookupTransform) over DDS"

    def statistics(self) -> ServerStatistics:
        """A copy of the counters (:class:`~tfbus.transports._base.ServerStatistics`):
        ``requests`` goals received, ``answered`` with a transform, ``errors`` with a
        ``TF2Error``, ``busy`` refused (``accepted=False``), ``cancelled`` by a cancel
        request or because the client left, ``malformed`` requests that did not decode,
        ``unsendable`` results ROS 2 cannot carry (a stamp past int32 seconds: ABORTED),
        ``pending`` goals held now."""
        s = self._stats
        return ServerStatistics(s.requests, s.answered, s.errors, s.malformed, s.busy,
                                s.cancelled, len(self._held), s.unsendable)

    async def __aenter__(self) -> LookupActionServer:
        """Create the action's readers and writers on the transport's participant and
        start answering.

        Raises:
            RuntimeError: already running, or the transport is not running.
            TransportError: Cyclone refused an endpoint.
        """
        if self._tg is not None:
            raise RuntimeError("this LookupActionServer is already running")
        participant = self._transport.participant()
        wakeup = ThreadWakeup()
        try:
            self._open(participant, wakeup)
        except Exception:
            self._close_entities()
            wakeup.close()
            raise
        self._wakeup = wakeup
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        tg.start_soon(wakeup.serve, self._drain)
        tg.start_soon(self._tick)
        return self

    async def __aexit__(self, *exc: object) -> None:
        """End answering: goals still waiting are dropped; the endpoints are deleted."""
        tg, self._tg = self._tg, None
        if tg is not None:
            tg.cancel_scope.cancel()
            await tg.__aexit__(None, None, None)
        self._close_entities()
        if self._wakeup is not None:
            self._wakeup.close()
            self._wakeup = None

    def _open(self, participant: DomainParticipant, wakeup: ThreadWakeup) -> None:
        listener = Listener(on_data_available=lambda _r: wakeup.wake())  # type: ignore[no-untyped-call]
        sid = f"serviceid={_endpoint_id()};"
        try:
            for service, (req_t, rep_t) in _SERVICES.items():
                req: Topic[Any] = Topic(participant, self._topics[f"{service}_request"],
                                        req_t)
                rep: Topic[Any] = Topic(participant, self._topics[f"{service}_reply"],
                                        rep_t)
                self._readers[service] = DataReader(participant, req, Qos(
                    _READ_RELIABLE, *_SERVICE_QOS, _user_data(f"{service}_request", sid)),
                    listener=listener)
                self._writers[service] = DataWriter(participant, rep, Qos(
                    _WRITE_RELIABLE, *_SERVICE_QOS, _user_data(f"{service}_reply", sid)))
                self._entities += [self._readers[service], self._writers[service]]
            status = Topic(participant, self._topics["status"], GoalStatusArray_)
            self._writers["status"] = DataWriter(participant, status, Qos(
                _WRITE_RELIABLE, Policy.Durability.TransientLocal, Policy.History.KeepLast(1),
                _XCDR1, _user_data("status")))
            feedback = Topic(participant, self._topics["feedback"], FeedbackMessage_)
            self._writers["feedback"] = DataWriter(participant, feedback, Qos(
                _WRITE_RELIABLE, Policy.Durability.Volatile, Policy.History.KeepLast(10),
                _XCDR1, _user_data("feedback")))
            self._entities += [self._writers["status"], self._writers["feedback"]]
        except Exception as exc:
            raise TransportError(f"cannot serve {self.where}: {exc}") from None

    def _close_entities(self) -> None:
        for entity in self._entities:
            _delete(entity)
        self._entities.clear()
        self._readers.clear()
        self._writers.clear()

    # -- receiving (in the event loop) ------------------------------------------------------

    def _drain(self, _woken: bool) -> bool:
        more = False
        for service, handler in (("cancel_goal", self._on_cancel),
                                 ("send_goal", self._on_send_goal),
                                 ("get_result", self._on_get_result)):
            reader = self._readers.get(service)
            if reader is None:
                return False
            samples = _take(reader)
            more = more or len(samples) >= _MAX_TAKE
            for data, info in samples:
                handler(data, int(info.publication_handle))
        return more

    def _reply(self, service: str, payload: bytes) -> None:
        writer = self._writers.get(service)
        if writer is not None:
            _write(writer, payload)

    def _on_send_goal(self, data: bytes, writer: int) -> None:
        if self._tg is None:
            return
        self._stats.requests += 1
        try:
            rid, goal = decode_send_goal_request(data)
        except WireDecodeError:
            self._stats.malformed += 1
            return
        known = self._held.get(goal.goal_id)
        if known is None and goal.goal_id in self._done:
            known = self._done[goal.goal_id][0]
        if known is not None:  # a resent goal: the same answer again
            self._reply("send_goal", encode_send_goal_response(rid, True, known.info.stamp))
            return
        now = _now()
        share = self._per_client.get(rid.guid, 0)
        if len(self._held) >= self._max_pending or share >= self._max_per_peer:
            self._stats.busy += 1
            _peer_log.log(logging.WARNING, "ros2: %s: goal refused: %d goals held (%d of this "
                          "client; max_pending %d, max_per_peer %d)", self.name,
                          len(self._held), share, self._max_pending, self._max_per_peer)
            self._reply("send_goal", encode_send_goal_response(rid, False, now))
            return
        held = _Goal(goal, GoalInfo(goal.goal_id, now), rid.guid, writer)
        self._held[goal.goal_id] = held
        self._per_client[rid.guid] = share + 1
        self._reply("send_goal", encode_send_goal_response(rid, True, now))
        self._status_dirty = True
        self._tg.start_soon(self._answer, held)

    def _on_get_result(self, data: bytes, _writer: int) -> None:
        try:
            rid, goal_id = decode_get_result_request(data)
        except WireDecodeError:
            self._stats.malformed += 1
            return
        done = self._done.get(goal_id)
        if done is not None:
            self._send_result(rid, done[0])
            return
        held = self._held.get(goal_id)
        if held is None:  # rcl_action: an unknown goal's result is STATUS_UNKNOWN
            self._reply("get_result", encode_get_result_response(
                rid, LookupResult(_UNKNOWN, _EMPTY, 0, "")))
            return
        if rid not in held.waiters:
            held.waiters.append(rid)
            del held.waiters[:-_MAX_RESULT_WAITERS]

    def _on_cancel(self, data: bytes, _writer: int) -> None:
        """rcl_action ``rcl_action_process_cancel_request``: a zero goal id and a zero
        stamp cancel every goal; a zero id and a stamp, every goal accepted at or before
        it; an id, that goal (and, with a stamp, those at or before it too)."""
        try:
            rid, info = decode_cancel_goal_request(data)
        except WireDecodeError:
            self._stats.malformed += 1
            return
        everything = info.goal_id == _ZERO_ID and info.stamp == Time(0)
        canceling: list[GoalInfo] = []
        for held in list(self._held.values()):
            if everything or held.info.goal_id == info.goal_id or (
                    info.stamp != Time(0) and held.info.stamp <= info.stamp):
                if not held.cancel_requested:
                    canceling.append(held.info)
                held.cancel()
        if canceling:
            code = _CANCEL_NONE
        elif info.goal_id != _ZERO_ID and info.goal_id in self._done:
            code = _CANCEL_TERMINATED
        elif info.goal_id != _ZERO_ID:
            code = _CANCEL_UNKNOWN_GOAL
        else:
            code = _CANCEL_REJECTED
        self._reply("cancel_goal", encode_cancel_goal_response(rid, code, canceling))

    # -- answering ----------------------------------------------------------------------------

    async def _answer(self, held: _Goal) -> None:
        goal = held.goal
        result: LookupResult | None = None
        try:
            with anyio.CancelScope() as scope:
                held.scope = scope
                if held.cancel_requested:
                    scope.cancel()
                with anyio.move_on_after(self._max_wait):
                    result = await self._lookup(goal, min(goal.timeout, self._max_wait))
                if result is None:  # past max_wait of wall time: an expired timeout
                    result = await self._lookup(goal, 0.0)
            if result is None:
                if self._tg is None:
                    return  # the server ends: dropped unanswered
                self._stats.cancelled += 1  # tf2_ros BufferServer::cancelCB: canceled
                result = LookupResult(_CANCELED, _EMPTY, 0, "")
            self._finish(held, result)
        finally:
            self._held.pop(goal.goal_id, None)
            left = self._per_client.get(held.client, 1) - 1
            if left > 0:
                self._per_client[held.client] = left
            else:
                self._per_client.pop(held.client, None)
            self._status_dirty = True

    def _finish(self, held: _Goal, result: LookupResult) -> None:
        try:
            encode_get_result_response(RequestId(0, 0), result)
        except WireEncodeError as exc:  # a stamp ROS 2 cannot carry
            self._stats.unsendable += 1
            _peer_log.log(logging.WARNING, "ros2: %s: result not sendable: %s", self.name, exc)
            result = LookupResult(_ABORTED, _EMPTY, 6, f"result not sendable: {exc}"[:500])
        else:
            if result.status == _SUCCEEDED:
                if result.error:
                    self._stats.errors += 1
                else:
                    self._stats.answered += 1
        held.result = result
        self._done[held.info.goal_id] = (held, _wallclock.monotonic())
        while len(self._done) > self._max_pending:
            del self._done[next(iter(self._done))]
        for rid in held.waiters:
            self._send_result(rid, held)
        held.waiters.clear()

    def _send_result(self, rid: RequestId, held: _Goal) -> None:
        assert held.result is not None
        self._reply("get_result", encode_get_result_response(rid, held.result))

    async def _lookup(self, goal: LookupGoal, timeout: float) -> LookupResult:
        """The goal's transform, or its ``TF2Error`` (``buffer_server.cpp``: at the
        timeout the lookup's own error, not a timeout;
        :data:`~tfbus.transports._base.LOOKUPS_OWN_ERROR`)."""
        buffer = self._buffer
        g = goal
        try:
            if g.advanced:
                try:
                    ts = await buffer.lookup_transform_full_async(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame, timeout)
                except LOOKUPS_OWN_ERROR:
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
            return LookupResult(_SUCCEEDED, _EMPTY, code, str(exc))
        return LookupResult(_SUCCEEDED, ts, 0, "")

    async def _tick(self) -> None:
        """Publish the status array when it changed, forget results past
        ``result_timeout``, and cancel the goals whose client left (its request writer
        no longer matched), every :data:`_TICK` seconds."""
        n = 0
        while True:
            await anyio.sleep(_TICK)
            n += 1
            horizon = _wallclock.monotonic() - self._result_timeout
            while self._done:
                oldest = next(iter(self._done))
                if self._done[oldest][1] >= horizon:
                    break
                del self._done[oldest]
                self._status_dirty = True
            if n % 5 == 0 and self._held:
                self._cancel_orphans()
            if self._status_dirty:
                self._status_dirty = False
                self._publish_status()

    def _cancel_orphans(self) -> None:
        reader = self._readers.get("send_goal")
        if reader is None:
            return
        try:
            present = set(reader.get_matched_publications())
        except Exception:  # cyclonedds' list may change under it: next tick
            return
        for held in list(self._held.values()):
            if held.writer not in present and not held.cancel_requested:
                held.cancel()

    def _publish_status(self) -> None:
        statuses = [(h.info, _EXECUTING) for h in self._held.values()]
        statuses += [(g.info, g.result.status if g.result else _UNKNOWN)
                     for g, _when in self._done.values()]
        writer = self._writers.get("status")
        if writer is not None:
            _write(writer, encode_goal_status_array(statuses[-2 * self._max_pending:]))


# -- client ---------------------------------------------------------------------------------


class _ClientEndpoints:
    """The action client's request writers and reply readers of one name on one running
    transport (made on first use, deleted when the transport leaves the domain)."""

    def __init__(self, participant: DomainParticipant, name: str) -> None:
        topics = action_topics(name)
        self.wakeup = ThreadWakeup()
        listener = Listener(on_data_available=lambda _r: self.wakeup.wake())  # type: ignore[no-untyped-call]
        cid = f"clientid={_endpoint_id()};"
        self.writers: dict[str, DataWriter[Any]] = {}
        self.readers: dict[str, DataReader[Any]] = {}
        try:
            for service, (req_t, rep_t) in _SERVICES.items():
                req: Topic[Any] = Topic(participant, topics[f"{service}_request"],
                                        req_t)
                rep: Topic[Any] = Topic(participant, topics[f"{service}_reply"],
                                        rep_t)
                self.writers[service] = DataWriter(participant, req, Qos(
                    _WRITE_RELIABLE, *_SERVICE_QOS, _user_data(f"{service}_request", cid)))
                self.readers[service] = DataReader(participant, rep, Qos(
                    _READ_RELIABLE, *_SERVICE_QOS, _user_data(f"{service}_reply", cid)),
                    listener=listener)
        except Exception as exc:
            self.close()
            raise TransportError(f"cannot ask the ROS 2 action {name}: {exc}") from None
        # rmw_cyclonedds_cpp: the request header's guid is the request writer's handle
        self.guid = int(self.writers["send_goal"].instance_handle) & 0xFFFF_FFFF_FFFF_FFFF
        self.seq = 0
        self.waiting: dict[int, list[Any]] = {}  # seq -> [reply] once answered
        self.pumping = False
        self.tick = anyio.Event()
        self.malformed = 0
        self.closed = False

    def ready(self) -> bool:
        """rcl_action ``rcl_action_server_is_available``: every request writer matched by
        a server's reader and every reply reader matched by a server's writer."""
        try:
            return all(
                w.get_publication_matched_status().current_count > 0  # type: ignore[no-untyped-call]
                for w in self.writers.values()
            ) and all(
                r.get_subscription_matched_status().current_count > 0  # type: ignore[no-untyped-call]
                for r in self.readers.values()
            )
        except Exception:
            return False

    def fast_dds_servers(self) -> int:
        """How many of the ``send_goal`` request readers matched now are Fast DDS's (GUID
        prefix starting with eProsima's vendor id 01.0f, as Fast DDS makes every GUID
        prefix): servers whose rmw (rmw_fastrtps_cpp) takes the request identity out of
        band and so cannot read this client's requests."""
        writer = self.writers.get("send_goal")
        if writer is None:
            return 0
        try:
            handles = writer.get_matched_subscriptions()
        except Exception:  # cyclonedds' list may change under it: none known now
            return 0
        count = 0
        for handle in handles:
            try:
                endpoint = writer.get_matched_subscription_data(handle)
            except Exception:
                continue
            if endpoint is not None and endpoint.key.bytes[:2] == _FAST_DDS_VENDOR:
                count += 1
        return count

    def close(self) -> None:
        self.closed = True
        for entity in (*self.writers.values(), *self.readers.values()):
            _delete(entity)
        self.writers.clear()
        self.readers.clear()
        self.wakeup.close()
        self.tick.set()

    def _drain(self) -> None:
        decoders: dict[str, Callable[[bytes], tuple[Any, ...]]] = {
            "send_goal": decode_send_goal_response,
            "get_result": decode_get_result_response,
            "cancel_goal": decode_cancel_goal_response,
        }
        for service, reader in list(self.readers.items()):
            for data, _info in _take(reader):
                try:
                    reply = decoders[service](data)
                except WireDecodeError:
                    self.malformed += 1
                    continue
                rid = reply[0]
                if rid.guid != self.guid:
                    continue  # another client's reply
                box = self.waiting.get(rid.seq)
                if box is not None and not box:
                    box.append(reply)

    async def wait_reply(self, box: list[Any]) -> None:
        """Wait until ``box`` holds its reply; one waiter at a time watches the socket
        (trio allows one), the others wait for its turn to end."""
        while not box:
            if self.closed:
                raise TransportError("the ROS 2 transport left the domain")
            if self.pumping:
                await self.tick.wait()
                continue
            self.pumping = True
            try:
                await self.wakeup.wait()
                self.wakeup.rearm()
                self._drain()
            finally:
                self.pumping = False
                tick, self.tick = self.tick, anyio.Event()
                tick.set()

    def send(self, service: str, payload: bytes) -> None:
        if not _write(self.writers[service], payload):
            _peer_log.log(logging.WARNING, "ros2: a %s request was not written", service)

    async def call(self, service: str, encode: Callable[[RequestId], bytes]) -> tuple[Any, ...]:
        """Send a request and wait for its reply, re-sending it every :data:`_RESEND`
        seconds while none came (the action's requests are idempotent; a server that
        matched this client's reply reader late answers the next one)."""
        while True:
            self.seq += 1
            seq = self.seq
            box: list[Any] = []
            self.waiting[seq] = box
            try:
                self.send(service, encode(RequestId(self.guid, seq)))
                with anyio.move_on_after(_RESEND):
                    await self.wait_reply(box)
            finally:
                del self.waiting[seq]
            if box:
                return tuple(box[0])


_clients: weakref.WeakKeyDictionary[Any, dict[str, _ClientEndpoints]] = \
    weakref.WeakKeyDictionary()


def _client_endpoints(transport: ActionParticipant, name: str) -> _ClientEndpoints:
    clients = _clients.setdefault(transport, {})
    endpoints = clients.get(name)
    if endpoints is None or endpoints.closed:
        endpoints = _ClientEndpoints(transport.participant(), name)
        clients[name] = endpoints

        def closed(endpoints: _ClientEndpoints = endpoints) -> None:
            endpoints.close()
            if clients.get(name) is endpoints:
                del clients[name]

        transport.on_close(closed)
    return endpoints


def result_transform(result: LookupResult) -> TransformStamped:
    """The transform of a ``get_result`` reply, or its error raised as tf2_ros's
    ``BufferClient`` does (``buffer_client.py`` ``__process_result``).

    Raises:
        TimeoutException: the goal did not end SUCCEEDED (CANCELED, ABORTED, UNKNOWN).
        LookupException, ConnectivityException, ExtrapolationException,
            InvalidArgumentException, TimeoutException, TransformException: the
            ``TF2Error`` code 1..6 with the server's message.
    """
    if result.status != _SUCCEEDED:
        raise errors.TimeoutException(
            "The LookupTransform goal sent to the BufferServer did not come back with "
            f"SUCCEEDED status: {_STATUS_NAMES.get(result.status, result.status)}")
    if result.error == 3:  # one extrapolation code: the text tells which
        raise errors.extrapolation_exception(result.error_string)
    if result.error:
        raise errors.tf2_error(result.error, result.error_string)
    return result.transform


class LookupActionClient:
    """:class:`~tfbus.buffer.Buffer`'s awaitable lookups answered by a ``LookupTransform``
    action server over ROS 2 (tf2_ros ``BufferClient``; :class:`LookupActionServer` or a
    ROS 2 ``buffer_server`` on rmw_cyclonedds_cpp) through the participant of a running
    :class:`~tfbus.transports.ros2.Ros2Transport`; :class:`tfbus.remote.BufferClient`
    makes it for a ROS 2 bus.

    Timeouts are seconds of the **server's** clock (the goal's ``timeout``); the wait here
    is bounded by ``timeout + timeout_padding`` wall seconds (tf2_ros's
    ``timeout_padding``, 2 s), within which the server must also be matched. A timeout of
    None sends ``max_wait``. A lookup cancelled here (or not answered in time) is
    cancelled on the server too (``cancel_goal`` with its goal id).

    Args:
        transport: the running ROS 2 transport.
        name: the action's name (default ``/tf2_buffer_server``).
        timeout_padding: wall seconds added to each timeout for the round trip.
        max_wait: the goal timeout sent for a timeout of None, seconds.

    Raises:
        ValueError: ``name`` is not a ROS graph name, ``timeout_padding`` is negative or
            not finite, or ``max_wait`` is not positive finite.
    """

    def __init__(self, transport: ActionParticipant, *, name: str = DEFAULT_ACTION,
                 timeout_padding: float = 2.0, max_wait: float = 3600.0) -> None:
        self._padding, self._max_wait = action_client_limits(timeout_padding, max_wait)
        self._transport = transport
        self.name = _action_name(name)
        """The action's name."""

    @property
    def malformed(self) -> int:
        """Replies that did not decode (counted, dropped), 0 before the first lookup."""
        endpoints = _clients.get(self._transport, {}).get(self.name)
        return endpoints.malformed if endpoints is not None else 0

    def _seconds(self, timeout: float | Duration | None) -> float:
        return goal_timeout(timeout, self._max_wait)

    async def _lookup(self, goal: LookupGoal) -> TransformStamped:
        encode_send_goal_request(RequestId(0, 0), goal)  # checks the goal before anything
        endpoints = _client_endpoints(self._transport, self.name)
        accepted = False
        result: LookupResult | None = None
        try:
            with anyio.move_on_after(goal.timeout + self._padding):
                while not endpoints.ready():  # rcl_action's wait_for_server
                    await anyio.sleep(0.05)
                if endpoints.fast_dds_servers():
                    raise TransportError(
                        f"the ROS 2 action {self.name} is served by a Fast DDS node "
                        "(rmw_fastrtps_cpp): ROS 2 services do not interoperate across DDS "
                        "vendors, and tfbus speaks rmw_cyclonedds_cpp's; run that node with "
                        "RMW_IMPLEMENTATION=rmw_cyclonedds_cpp (no goal was sent)")
                reply = await endpoints.call(
                    "send_goal", lambda rid: encode_send_goal_request(rid, goal))
                accepted = bool(reply[1])
                if not accepted:
                    raise errors.TimeoutException(  # tf2_ros buffer_client.py's words
                        "The LookupTransform goal sent to the BufferServer did not come "
                        "back with accepted status. Something is likely wrong with the "
                        "server.")
                reply = await endpoints.call(
                    "get_result", lambda rid: encode_get_result_request(rid, goal.goal_id))
                result = reply[1]
        finally:
            if accepted and result is None and not endpoints.closed:
                endpoints.seq += 1  # cancel on the server what is no longer awaited
                with contextlib.suppress(Exception):
                    endpoints.send("cancel_goal", encode_cancel_goal_request(
                        RequestId(endpoints.guid, endpoints.seq),
                        GoalInfo(goal.goal_id, Time(0))))
        if result is None:
            raise errors.TimeoutException(
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server.")
        return result_transform(result)

    @coroutine_method
    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration | None = None, *,
                               fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``: the server waits up to ``timeout``
        seconds of its clock.

        Raises:
            The server's tf2 error as the same tfbus class (its message kept);
            TimeoutException if no result came within ``timeout + timeout_padding`` wall
            seconds or the goal was refused or cancelled; ValueError for a negative or
            non-finite timeout; WireEncodeError for a time ROS 2 cannot carry;
            RuntimeError if the transport is not running; TransportError (before any
            goal is sent) if the server matched is a Fast DDS node's; ValueError for
            ``fail_fast=True`` (the action's goal cannot carry it).
        """
        refuse_fail_fast(fail_fast, "ROS 2")
        return await self._lookup(LookupGoal(
            secrets.token_bytes(16), target_frame, source_frame, time, self._seconds(timeout),
            Time(0), "", False))

    @coroutine_method
    async def lookup_transform_full(self, target_frame: str, target_time: Time,
                                    source_frame: str, source_time: Time, fixed_frame: str,
                                    timeout: float | Duration | None = None, *,
                                    fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform_full`` (the advanced goal).

        Raises: as :meth:`lookup_transform`.
        """
        refuse_fail_fast(fail_fast, "ROS 2")
        return await self._lookup(LookupGoal(
            secrets.token_bytes(16), target_frame, source_frame, source_time,
            self._seconds(timeout), target_time, fixed_frame, True))

    @coroutine_method
    async def can_transform(self, target_frame: str, source_frame: str, time: Time,
                            timeout: float | Duration | None = None, *,
                            fail_fast: bool = False) -> bool:
        """Whether the server answers the lookup with a transform within ``timeout``
        (tf2_ros ``BufferClient.can_transform``).

        Raises:
            ValueError: as :meth:`lookup_transform`.
        """
        refuse_fail_fast(fail_fast, "ROS 2")
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
        ``type(obj)`` (:mod:`tfbus.convert`) is applied here.

        Raises:
            TypeError: no transform function for ``type(obj)`` (before any goal).
            The lookup's errors, as :meth:`lookup_transform`.
        """
        return await transform_remotely(self, obj, target_frame, timeout, fail_fast)
