"""ROS 2's ``tf2_msgs/action/LookupTransform`` action in CDR: the samples of its three
services and its status topic as rmw_cyclonedds_cpp puts them on DDS.

Used by the ROS 2 transport's lookup server and client
(:mod:`tfbus.transports.ros2.action`). Synchronous, free of I/O and of optional
dependencies.

**The action's messages** (``rosidl`` generates them from ``LookupTransform.action``,
``action_msgs`` and ``unique_identifier_msgs``; rcl_action ``names.c`` names the
services):

* ``send_goal``: request ``LookupTransform_SendGoal_Request`` (``UUID goal_id``: 16
  ``uint8``; ``LookupTransform_Goal goal``: ``string target_frame, source_frame``,
  ``Time source_time``, ``Duration timeout``, ``Time target_time``, ``string
  fixed_frame``, ``bool advanced``), reply ``LookupTransform_SendGoal_Response``
  (``bool accepted``, ``Time stamp``);
* ``get_result``: request ``LookupTransform_GetResult_Request`` (``UUID goal_id``),
  reply ``LookupTransform_GetResult_Response`` (``int8 status``; ``LookupTransform_Result
  result``: ``geometry_msgs/TransformStamped transform``, ``tf2_msgs/TF2Error error``:
  ``uint8 error``, ``string error_string``);
* ``cancel_goal``: ``action_msgs/srv/CancelGoal`` (request ``GoalInfo goal_info``: UUID
  and stamp; reply ``int8 return_code``, ``GoalInfo[] goals_canceling``);
* ``status`` topic: ``action_msgs/msg/GoalStatusArray`` (``GoalStatus[]``: ``GoalInfo``
  and ``int8 status``).

``builtin_interfaces`` ``Time`` and ``Duration`` are ``int32 sec``, ``uint32 nanosec``.

**Encoding.** XCDR1 little-endian (encapsulation ``00 01 00 00``), every primitive aligned
to its size from the first byte after the encapsulation header, as
:mod:`tfbus.codecs.cdr`; decoding also reads big-endian and ``PLAIN_CDR2`` (8-byte
primitives aligned to 4).

**Request identity.** rmw_cyclonedds_cpp prefixes every service request and reply with its
``cdds_request_header_t`` (``serdata.hpp``): ``uint64 guid`` (the client's request
writer's instance handle) and ``int64 seq`` (the request's sequence number); the server
copies both into its reply, and a client keeps the replies carrying its own guid
(``rmw_node.cpp`` ``rmw_send_request`` / ``rmw_take_response_request``). Every service
sample here is :class:`RequestId` plus the message. (rmw_fastrtps_cpp carries the same
identity out of band, in the RTPS ``related_sample_identity`` inline QoS; Cyclone DDS
cannot write that, so services between the two do not interoperate:
rmw_fastrtps_shared_cpp ``__rmw_take_response`` keeps only the replies whose
``related_sample_identity`` names its client.)

**Errors.** Decoding raises :class:`~tfbus.errors.WireDecodeError` and nothing else;
encoding raises :class:`~tfbus.errors.WireEncodeError` for a value the wire cannot carry
(a stamp outside int32 seconds, a NUL or a lone surrogate in a frame id, a goal id that is
not 16 bytes), naming the field.
"""

from __future__ import annotations

import math
import struct
import uuid
from collections.abc import Callable, Sequence
from typing import Any, Final, NamedTuple, TypeVar

from tfbus.errors import WireDecodeError, WireEncodeError
from tfbus.messages import (
    Header,
    LookupTransformGoal,
    LookupTransformResult,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import NSEC_PER_SEC, Time

__all__ = [
    "GOAL_ID_BYTES",
    "GoalInfo",
    "LookupGoal",
    "LookupResult",
    "RequestId",
    "decode_cancel_goal_request",
    "decode_cancel_goal_response",
    "decode_get_result_request",
    "decode_get_result_response",
    "decode_goal_status_array",
    "decode_lookup_goal",
    "decode_lookup_result",
    "decode_send_goal_request",
    "decode_send_goal_response",
    "encode_cancel_goal_request",
    "encode_cancel_goal_response",
    "encode_get_result_request",
    "encode_get_result_response",
    "encode_goal_status_array",
    "encode_lookup_goal",
    "encode_lookup_result",
    "encode_send_goal_request",
    "encode_send_goal_response",
]

GOAL_ID_BYTES: Final = 16
"""Length of a goal id (``unique_identifier_msgs/UUID``: ``uint8[16]``)."""
_INT32_MAX: Final = 2**31 - 1
_HEADER_LE: Final = b"\x00\x01\x00\x00"
_T = TypeVar("_T")
_ENCAPSULATIONS: Final = {  # kind -> (byte order, alignment of 8-byte primitives)
    0x0000: (">", 8), 0x0001: ("<", 8),  # CDR_BE, CDR_LE (XCDR1)
    0x0006: (">", 4), 0x0007: ("<", 4),  # PLAIN_CDR2_BE, PLAIN_CDR2_LE
}  # fmt: skip


class RequestId(NamedTuple):
    """rmw_cyclonedds_cpp's ``cdds_request_header_t``: which client asked (``guid``, its
    request writer's 64-bit instance handle) and which of its requests (``seq``)."""

    guid: int
    seq: int


class LookupGoal(NamedTuple):
    """A ``LookupTransform`` goal (``LookupTransform_Goal``) with its id.

    Attributes:
        goal_id: 16 bytes (``unique_identifier_msgs/UUID``).
        target_frame, source_frame: frame ids.
        source_time: the time of the lookup (``lookup_transform``'s ``time``).
        timeout: the server's longest wait, seconds (``builtin_interfaces/Duration``).
        target_time, fixed_frame: ``lookup_transform_full``'s (with ``advanced``).
        advanced: True for ``lookup_transform_full``.
    """

    goal_id: bytes
    target_frame: str
    source_frame: str
    source_time: Time
    timeout: float
    target_time: Time
    fixed_frame: str
    advanced: bool


class LookupResult(NamedTuple):
    """A ``LookupTransform_GetResult_Response``: the goal's ``action_msgs/GoalStatus``
    status (4 SUCCEEDED, 5 CANCELED, 6 ABORTED, 0 UNKNOWN), the transform and the
    ``TF2Error`` (``error`` code 0..6, ``error_string``)."""

    status: int
    transform: TransformStamped
    error: int
    error_string: str


class GoalInfo(NamedTuple):
    """``action_msgs/GoalInfo``: a goal id (16 bytes) and the time it was accepted."""

    goal_id: bytes
    stamp: Time


class _Writer:
    """XCDR1 little-endian, offsets from the first byte after the encapsulation."""

    __slots__ = ("parts", "pos")

    def __init__(self, request_id: RequestId | None) -> None:
        self.parts: list[bytes] = [_HEADER_LE]
        self.pos = 0
        if request_id is not None:
            self.put("<Qq", 8, request_id.guid & 0xFFFF_FFFF_FFFF_FFFF, request_id.seq)

    def put(self, fmt: str, align: int, *values: object) -> None:
        pad = -self.pos % align
        raw = b"\0" * pad + struct.pack(fmt, *values)
        self.parts.append(raw)
        self.pos += len(raw)

    def string(self, text: str, what: str) -> None:
        if not isinstance(text, str):
            raise WireEncodeError(f"{what} must be a str, got {type(text).__name__}")
        if "\0" in text:
            raise WireEncodeError(f"{what} holds a NUL character, which a CDR string cannot "
                                  f"carry: {text!r:.100}")
        try:
            raw = text.encode()
        except UnicodeEncodeError:
            raise WireEncodeError(f"{what} is not UTF-8 encodable (a lone surrogate): "
                                  f"{text!r:.100}") from None
        self.put("<I", 4, len(raw) + 1)
        self.parts.append(raw + b"\0")
        self.pos += len(raw) + 1

    def time(self, t: Time, what: str) -> None:
        if not isinstance(t, Time):
            raise WireEncodeError(f"{what} must be a Time, got {t!r:.100}")
        sec, nanosec = divmod(t.ns, NSEC_PER_SEC)
        if not 0 <= sec <= _INT32_MAX:
            raise WireEncodeError(f"{what}: sec={sec} is outside ROS 2's int32 range "
                                  f"[0, {_INT32_MAX}] (builtin_interfaces/Time)")
        self.put("<iI", 4, sec, nanosec)

    def uuid(self, goal_id: bytes) -> None:
        if not isinstance(goal_id, bytes) or len(goal_id) != GOAL_ID_BYTES:
            raise WireEncodeError(f"goal_id must be {GOAL_ID_BYTES} bytes, got {goal_id!r:.60}")
        self.parts.append(goal_id)
        self.pos += GOAL_ID_BYTES

    def done(self) -> bytes:
        self.parts.append(b"\0" * (-self.pos % 4))  # DDS writers pad samples to 4
        return b"".join(self.parts)


class _Reader:
    __slots__ = ("align8", "body", "order", "pos")

    def __init__(self, data: bytes | memoryview, what: str) -> None:
        if len(data) < 4:
            raise WireDecodeError(f"{what}: sample too short: {len(data)} bytes")
        kind = (data[0] << 8) | data[1]
        enc = _ENCAPSULATIONS.get(kind)
        if enc is None:
            raise WireDecodeError(f"{what}: unsupported CDR encapsulation 0x{kind:04x}")
        self.order, self.align8 = enc
        self.body = bytes(data[4:])
        self.pos = 0

    def get(self, fmt: str, size: int) -> tuple[Any, ...]:
        align = min(size, self.align8)
        self.pos += -self.pos % align
        st = struct.Struct(self.order + fmt)
        values = st.unpack_from(self.body, self.pos)  # struct.error past the end
        self.pos += st.size
        return values

    def request_id(self) -> RequestId:
        guid, seq = self.get("Qq", 8)
        return RequestId(int(guid), int(seq))

    def u8(self) -> int:
        return int(self.get("B", 1)[0])

    def i8(self) -> int:
        return int(self.get("b", 1)[0])

    def u32(self) -> int:
        return int(self.get("I", 4)[0])

    def string(self, what: str) -> str:
        n = self.u32()
        end = self.pos + n
        if n < 1 or end > len(self.body) or self.body[end - 1] != 0:
            raise WireDecodeError(f"{what} is not a NUL-terminated string")
        text = self.body[self.pos : end - 1].decode()  # UnicodeDecodeError: caught
        self.pos = end
        return text

    def time(self, what: str) -> Time:
        sec, nanosec = self.get("iI", 4)
        assert isinstance(sec, int) and isinstance(nanosec, int)
        if sec < 0 or nanosec >= NSEC_PER_SEC:
            raise WireDecodeError(f"{what} ({sec} s, {nanosec} ns) is not a time after 1970")
        return Time.from_ns(sec * NSEC_PER_SEC + nanosec)

    def uuid(self) -> bytes:
        end = self.pos + GOAL_ID_BYTES
        if end > len(self.body):
            raise WireDecodeError("goal_id runs past the end of the sample")
        raw = self.body[self.pos : end]
        self.pos = end
        return raw

    def count(self, smallest: int, what: str) -> int:
        n = self.u32()
        if n * smallest > len(self.body) - self.pos:
            raise WireDecodeError(f"{what} announces {n} elements in "
                                  f"{len(self.body) - self.pos} bytes")
        return n


def _decoding(what: str) -> Callable[[Callable[[_Reader], _T]],
                                     Callable[[bytes | memoryview], _T]]:
    """Run a decoder turning its struct and UTF-8 failures into WireDecodeError."""

    def wrap(fn: Callable[[_Reader], _T]) -> Callable[[bytes | memoryview], _T]:
        def decode(data: bytes | memoryview) -> _T:
            try:
                return fn(_Reader(data, what))
            except struct.error as exc:
                raise WireDecodeError(f"{what} sample truncated: {exc}") from None
            except UnicodeDecodeError as exc:
                raise WireDecodeError(f"{what}: a string is not UTF-8: {exc}") from None

        decode.__name__ = fn.__name__
        decode.__doc__ = fn.__doc__
        return decode

    return wrap


def _duration(seconds: float) -> tuple[int, int]:
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
            or math.isnan(seconds) or seconds < 0:
        raise WireEncodeError(f"timeout must be seconds >= 0, got {seconds!r}")
    if seconds >= _INT32_MAX:
        return _INT32_MAX, NSEC_PER_SEC - 1  # the longest Duration: "forever"
    ns = round(seconds * NSEC_PER_SEC)
    return ns // NSEC_PER_SEC, ns % NSEC_PER_SEC


# -- send_goal -----------------------------------------------------------------------------


def encode_send_goal_request(request_id: RequestId, goal: LookupGoal) -> bytes:
    """A ``LookupTransform_SendGoal_Request`` sample (request identity, goal id, goal).

    Raises:
        WireEncodeError: a goal id that is not 16 bytes, a frame id with a NUL or a lone
            surrogate, a time outside int32 seconds, a negative or NaN timeout (named). A
            timeout of 2**31 s or more is sent as the longest ``Duration``.
    """
    w = _Writer(request_id)
    _write_goal(w, goal)
    return w.done()


def _write_goal(w: _Writer, goal: LookupGoal) -> None:
    """``UUID goal_id`` and ``LookupTransform_Goal goal`` of a ``SendGoal_Request``."""
    w.uuid(goal.goal_id)
    w.string(goal.target_frame, "target_frame")
    w.string(goal.source_frame, "source_frame")
    w.time(goal.source_time, "source_time")
    w.put("<iI", 4, *_duration(goal.timeout))
    w.time(goal.target_time, "target_time")
    w.string(goal.fixed_frame, "fixed_frame")
    w.put("<B", 1, 1 if goal.advanced else 0)


@_decoding("LookupTransform_SendGoal_Request")
def decode_send_goal_request(r: _Reader) -> tuple[RequestId, LookupGoal]:
    """``(request identity, goal)`` of a ``LookupTransform_SendGoal_Request`` sample.

    Raises:
        WireDecodeError: the sample is not such a message (truncated, a string not
            NUL-terminated UTF-8, a time before 1970, a negative timeout).
    """
    rid = r.request_id()
    return rid, _read_goal(r)


def _read_goal(r: _Reader) -> LookupGoal:
    """``UUID goal_id`` and ``LookupTransform_Goal goal`` of a ``SendGoal_Request``."""
    goal_id = r.uuid()
    target = r.string("target_frame")
    source = r.string("source_frame")
    source_time = r.time("source_time")
    sec, nanosec = r.get("iI", 4)
    assert isinstance(sec, int) and isinstance(nanosec, int)
    if sec < 0 or nanosec >= NSEC_PER_SEC:
        raise WireDecodeError(f"timeout ({sec} s, {nanosec} ns) is not a duration >= 0")
    target_time = r.time("target_time")
    fixed = r.string("fixed_frame")
    advanced = r.u8()
    return LookupGoal(goal_id, target, source, source_time, sec + nanosec / NSEC_PER_SEC,
                      target_time, fixed, advanced != 0)


def encode_send_goal_response(request_id: RequestId, accepted: bool, stamp: Time) -> bytes:
    """A ``LookupTransform_SendGoal_Response`` sample (``accepted``, the time accepted).

    Raises:
        WireEncodeError: a stamp outside int32 seconds.
    """
    w = _Writer(request_id)
    w.put("<B", 1, 1 if accepted else 0)
    w.time(stamp, "stamp")
    return w.done()


@_decoding("LookupTransform_SendGoal_Response")
def decode_send_goal_response(r: _Reader) -> tuple[RequestId, bool, Time]:
    """``(request identity, accepted, stamp)`` of a ``LookupTransform_SendGoal_Response``.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    rid = r.request_id()
    accepted = r.u8() != 0
    return rid, accepted, r.time("stamp")


# -- get_result ----------------------------------------------------------------------------


def encode_get_result_request(request_id: RequestId, goal_id: bytes) -> bytes:
    """A ``LookupTransform_GetResult_Request`` sample.

    Raises:
        WireEncodeError: a goal id that is not 16 bytes.
    """
    w = _Writer(request_id)
    w.uuid(goal_id)
    return w.done()


@_decoding("LookupTransform_GetResult_Request")
def decode_get_result_request(r: _Reader) -> tuple[RequestId, bytes]:
    """``(request identity, goal id)`` of a ``LookupTransform_GetResult_Request``.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    rid = r.request_id()
    return rid, r.uuid()


def encode_get_result_response(request_id: RequestId, result: LookupResult) -> bytes:
    """A ``LookupTransform_GetResult_Response`` sample.

    Raises:
        WireEncodeError: a stamp outside int32 seconds, a frame id or error string with a
            NUL or a lone surrogate, a status outside int8 or an error code outside uint8.
    """
    w = _Writer(request_id)
    _write_result(w, result)
    return w.done()


def _write_result(w: _Writer, result: LookupResult) -> None:
    """``int8 status`` and ``LookupTransform_Result result`` of a
    ``GetResult_Response``."""
    ts = result.transform
    try:
        w.put("<b", 1, result.status)
        w.time(ts.header.stamp, "transform.header.stamp")
        w.string(ts.header.frame_id, "transform.header.frame_id")
        w.string(ts.child_frame_id, "transform.child_frame_id")
        t = ts.transform
        w.put("<7d", 8, *map(float, t.translation), *map(float, t.rotation))
        w.put("<B", 1, result.error)
    except struct.error as exc:
        raise WireEncodeError(f"LookupTransform result: {exc}") from None
    w.string(result.error_string, "error.error_string")


@_decoding("LookupTransform_GetResult_Response")
def decode_get_result_response(r: _Reader) -> tuple[RequestId, LookupResult]:
    """``(request identity, result)`` of a ``LookupTransform_GetResult_Response``.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    rid = r.request_id()
    return rid, _read_result(r)


def _read_result(r: _Reader) -> LookupResult:
    """``int8 status`` and ``LookupTransform_Result result`` of a
    ``GetResult_Response``."""
    status = r.i8()
    stamp = r.time("transform.header.stamp")
    frame = r.string("transform.header.frame_id")
    child = r.string("transform.child_frame_id")
    x, y, z, qx, qy, qz, qw = (float(v) for v in r.get("7d", 8))
    code = r.u8()
    message = r.string("error.error_string")
    ts = TransformStamped(Header(stamp, frame), child,
                          Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)))
    return LookupResult(status, ts, code, message)


# -- cancel_goal and status ------------------------------------------------------------------


def encode_cancel_goal_request(request_id: RequestId, goal: GoalInfo) -> bytes:
    """An ``action_msgs/srv/CancelGoal`` request sample (``CancelGoal_Request``).

    Raises:
        WireEncodeError: a goal id that is not 16 bytes, a stamp outside int32 seconds.
    """
    w = _Writer(request_id)
    w.uuid(goal.goal_id)
    w.time(goal.stamp, "goal_info.stamp")
    return w.done()


@_decoding("CancelGoal_Request")
def decode_cancel_goal_request(r: _Reader) -> tuple[RequestId, GoalInfo]:
    """``(request identity, goal info)`` of an ``action_msgs/srv/CancelGoal`` request.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    rid = r.request_id()
    goal_id = r.uuid()
    return rid, GoalInfo(goal_id, r.time("goal_info.stamp"))


def encode_cancel_goal_response(request_id: RequestId, return_code: int,
                                goals: Sequence[GoalInfo]) -> bytes:
    """An ``action_msgs/srv/CancelGoal`` response sample (``return_code`` 0 NONE,
    1 REJECTED, 2 UNKNOWN_GOAL_ID, 3 GOAL_TERMINATED; the goals now canceling).

    Raises:
        WireEncodeError: a goal id that is not 16 bytes, a stamp outside int32 seconds.
    """
    w = _Writer(request_id)
    w.put("<b", 1, return_code)
    w.put("<I", 4, len(goals))
    for g in goals:
        w.uuid(g.goal_id)
        w.time(g.stamp, "goals_canceling[].stamp")
    return w.done()


@_decoding("CancelGoal_Response")
def decode_cancel_goal_response(r: _Reader) -> tuple[RequestId, int, tuple[GoalInfo, ...]]:
    """``(request identity, return code, goals canceling)`` of an
    ``action_msgs/srv/CancelGoal`` response.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    rid = r.request_id()
    code = r.i8()
    n = r.count(24, "goals_canceling")
    goals = []
    for _ in range(n):
        goal_id = r.uuid()
        goals.append(GoalInfo(goal_id, r.time("goals_canceling[].stamp")))
    return rid, code, tuple(goals)


def encode_goal_status_array(statuses: Sequence[tuple[GoalInfo, int]]) -> bytes:
    """An ``action_msgs/msg/GoalStatusArray`` sample (the ``status`` topic; no request
    identity): each goal's info and ``GoalStatus`` status (1 ACCEPTED, 2 EXECUTING,
    3 CANCELING, 4 SUCCEEDED, 5 CANCELED, 6 ABORTED).

    Raises:
        WireEncodeError: a goal id that is not 16 bytes, a stamp outside int32 seconds.
    """
    w = _Writer(None)
    w.put("<I", 4, len(statuses))
    for info, status in statuses:
        w.uuid(info.goal_id)
        w.time(info.stamp, "status_list[].goal_info.stamp")
        w.put("<b", 1, status)
    return w.done()


@_decoding("GoalStatusArray")
def decode_goal_status_array(r: _Reader) -> tuple[tuple[GoalInfo, int], ...]:
    """``((goal info, status), ...)`` of an ``action_msgs/msg/GoalStatusArray``.

    Raises:
        WireDecodeError: the sample is not such a message.
    """
    n = r.count(25, "status_list")
    out = []
    for _ in range(n):
        goal_id = r.uuid()
        stamp = r.time("status_list[].goal_info.stamp")
        out.append((GoalInfo(goal_id, stamp), r.i8()))
    return tuple(out)


# -- the action's goal and result in every codec's shape ------------------------------------


def _goal_id_bytes(goal_id: str) -> bytes:
    try:
        return uuid.UUID(goal_id).bytes
    except (ValueError, TypeError, AttributeError):
        raise WireEncodeError(
            f"goal_id must be a UUID (32 hex digits, RFC 4122), got {goal_id!r:.60}") from None


def encode_lookup_goal(message: LookupTransformGoal) -> bytes:
    """A :class:`~tfbus.messages.LookupTransformGoal` as a ROS 2
    ``tf2_msgs/action/LookupTransform_SendGoal_Request`` (the goal id, a
    ``unique_identifier_msgs/UUID``, then ``LookupTransform_Goal``), XCDR1 little-endian,
    as :func:`encode_send_goal_request` writes it after the rmw request identity
    (:mod:`tfbus.codecs.ros1`'s function of the same name writes ROS 1's
    ``LookupTransformActionGoal``).

    ``goal_id`` is the UUID's text (32 hex digits, with or without RFC 4122's dashes);
    ``goal_stamp`` is not carried (ROS 2's server stamps the goal when it accepts it, in
    ``send_goal``'s response). A ``timeout`` of 2**31 s or more is sent as the longest
    ``Duration``.

    Raises:
        WireEncodeError: a goal id that is not a UUID, a frame id with a NUL or a lone
            surrogate, a time outside int32 seconds, a negative or NaN timeout (named).
    """
    g = message
    w = _Writer(None)
    _write_goal(w, LookupGoal(_goal_id_bytes(g.goal_id), g.target_frame, g.source_frame,
                              g.source_time, g.timeout, g.target_time, g.fixed_frame,
                              g.advanced))
    return w.done()


@_decoding("LookupTransform_SendGoal_Request")
def decode_lookup_goal(r: _Reader) -> LookupTransformGoal:
    """A ROS 2 ``tf2_msgs/action/LookupTransform_SendGoal_Request`` (CDR, no rmw request
    identity) as a :class:`~tfbus.messages.LookupTransformGoal`: ``goal_id`` the UUID's
    RFC 4122 text (``"6ba7b810-9dad-11d1-80b4-00c04fd430c8"``), ``goal_stamp``
    ``Time(0)`` (not on this message).

    Raises:
        WireDecodeError: the bytes are not such a message (truncated, a string not
            NUL-terminated UTF-8, a time before 1970, a negative timeout).
    """
    g = _read_goal(r)
    return LookupTransformGoal(g.target_frame, g.source_frame, g.source_time, g.timeout,
                               g.target_time, g.fixed_frame, g.advanced,
                               str(uuid.UUID(bytes=g.goal_id)))


def encode_lookup_result(message: LookupTransformResult) -> bytes:
    """A :class:`~tfbus.messages.LookupTransformResult` as a ROS 2
    ``tf2_msgs/action/LookupTransform_GetResult_Response`` (``int8 status``, then
    ``LookupTransform_Result``: the transform and the ``TF2Error``), XCDR1 little-endian,
    as :func:`encode_get_result_response` writes it after the rmw request identity.

    ``status`` is written as it is: on ROS 2 it is an ``action_msgs/GoalStatus`` code (4
    SUCCEEDED, 5 CANCELED, 6 ABORTED), not actionlib's (ROS 1: 3 SUCCEEDED). ``goal_id``,
    ``goal_stamp``, ``status_text`` and ``stamp`` are not carried (ROS 2's
    ``get_result`` response names its goal by the request it answers).

    Raises:
        WireEncodeError: a stamp outside int32 seconds, a frame id or error string with a
            NUL, a status outside int8 or an error code outside uint8.
    """
    m = message
    w = _Writer(None)
    _write_result(w, LookupResult(m.status, m.transform, m.error, m.error_string))
    return w.done()


@_decoding("LookupTransform_GetResult_Response")
def decode_lookup_result(r: _Reader) -> LookupTransformResult:
    """A ROS 2 ``tf2_msgs/action/LookupTransform_GetResult_Response`` (CDR, no rmw
    request identity) as a :class:`~tfbus.messages.LookupTransformResult` (``status``
    the ``action_msgs/GoalStatus`` code; the fields the message does not carry at their
    defaults).

    Raises:
        WireDecodeError: the bytes are not such a message.
    """
    res = _read_result(r)
    return LookupTransformResult(res.transform, res.error, res.error_string,
                                 status=res.status)
