"""tf2_ros's own buffer protocol on ROS 1: the ``tf2_msgs/LookupTransform`` action
(actionlib over TCPROS, through a ROS 1 master), both ends.

* :class:`Ros1BufferClient` is tf2_ros ``BufferClient`` (``buffer_client.py``): it
  publishes ``/tf2_buffer_server/goal`` (``tf2_msgs/LookupTransformActionGoal``) and
  subscribes to ``/tf2_buffer_server/result``; the server's ``TF2Error`` comes back as
  the tf2 exception of the same kind with the server's message
  (``BufferClient.__process_result``). Answered by Debian's real ``buffer_server``.
* :class:`Ros1BufferServer` is tf2_ros ``buffer_server`` (``buffer_server.cpp``)
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
  later so stamped. It holds at most ``max_goals`` goals (more are REJECTED at once with
  the status text "buffer server busy: ...") and waits at most ``max_wait`` seconds for
  one (tf2_ros's server waits for as long as the goal asks, up to 2**31 s).

Loopback only: the node listens on 127.0.0.1 and contacts only 127.0.0.1 / localhost
peers. A goal that does not decode is counted and dropped; so is a publisher URI that is
not a loopback ``http://host:port`` (or whose ``requestTopic`` answer is not), and an
answer ROS 1 cannot carry (a stamp at or after 2**32 s). Each subscriber has its own
bounded queue of frames (the oldest dropped when full), so one that does not read holds up
no other.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import secrets
import struct
import time as _wallclock
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Final, NamedTuple
from urllib.parse import urlsplit

import anyio
import anyio.abc
from anyio.streams.buffered import BufferedByteReceiveStream

from tfbus import errors
from tfbus._aio import coroutine_method
from tfbus.errors import TransformException, TransportError
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import Duration, Time
from tfbus.transports.ros1.rpc import SlaveServer, call, serve_listener
from tfbus.transports.ros1.tcpros import (
    FrameQueue,
    decode_header,
    encode_header,
    frame,
    read_frame,
    serve_subscriber,
)

if TYPE_CHECKING:
    from tfbus.buffer import Buffer

__all__ = [
    "CANCEL_MD5",
    "CANCEL_TYPE",
    "GOAL_MD5",
    "GOAL_TYPE",
    "MAX_GOAL_ID_BYTES",
    "MAX_HELD_GOAL_BYTES",
    "RESULT_MD5",
    "RESULT_TYPE",
    "Ros1BufferClient",
    "Ros1BufferServer",
    "decode_goal",
    "decode_goal_id",
    "decode_result",
    "decode_result_status",
    "encode_goal",
    "encode_goal_id",
    "encode_result",
    "result_transform",
]

GOAL_TYPE: Final = "tf2_msgs/LookupTransformActionGoal"
GOAL_MD5: Final = "f2e7bcdb75c847978d0351a13e699da5"
"""md5sum of ``tf2_msgs/LookupTransformActionGoal`` (tf2_msgs 0.7.6; checked against
Debian's python3-tf2-msgs by the tests)."""
RESULT_TYPE: Final = "tf2_msgs/LookupTransformActionResult"
RESULT_MD5: Final = "ac26ce75a41384fa8bb4dc10f491ab90"
"""md5sum of ``tf2_msgs/LookupTransformActionResult`` (tf2_msgs 0.7.6)."""
FEEDBACK_TYPE: Final = "tf2_msgs/LookupTransformActionFeedback"
FEEDBACK_MD5: Final = "aae20e09065c3809e8a8e87c4c8953fd"
STATUS_TYPE: Final = "actionlib_msgs/GoalStatusArray"
STATUS_MD5: Final = "8b2b82f13216d0a8ea88bd3af735e619"
CANCEL_TYPE: Final = "actionlib_msgs/GoalID"
CANCEL_MD5: Final = "302881f31927c1df708a2dbab0e80ee8"
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
"""Longest goal id (bytes) :class:`Ros1BufferServer` holds; a longer one is counted as
malformed (actionlib's ids, ``/node-count-secs.nsecs``, are tens of bytes)."""
MAX_HELD_GOAL_BYTES: Final = 32 << 20
"""Most bytes of goals :class:`Ros1BufferServer` holds at once (with ``max_goals``)."""
_STATUS_KEPT: Final = 5.0  # actionlib's status_list_timeout: a finished goal stays listed

_ERRORS: Final[dict[int, type[TransformException]]] = {
    1: errors.LookupException,  # tf2_msgs/TF2Error LOOKUP_ERROR
    2: errors.ConnectivityException,
    3: errors.ExtrapolationException,
    4: errors.InvalidArgumentException,
    5: errors.TimeoutException,
    6: errors.TransformException,
}
_MAX_FRAME: Final = 1 << 20
# Frames queued per subscriber, at most: beyond either bound its oldest are dropped.
_QUEUE_FRAMES = 1000
_QUEUE_BYTES = 8 << 20
_log = logging.getLogger("tfbus.remote")
_peer_log = CountLimitedLog(_log, 1, period=5.0, clock=_wallclock.monotonic)
_U8 = struct.Struct("<B")
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<II")
_DURATION = struct.Struct("<ii")
_POSE = struct.Struct("<7d")


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _time(t: Time) -> bytes:
    sec, nsec = divmod(t.ns, 1_000_000_000)
    if sec > 0xFFFF_FFFF:
        raise ValueError(f"stamp {sec}.{nsec:09d} s is past ROS 1 time (uint32 seconds)")
    return _TIME.pack(sec, nsec)


class _Reader:
    def __init__(self, raw: bytes) -> None:
        self.raw, self.off = raw, 0

    def take(self, st: struct.Struct) -> tuple[Any, ...]:
        out = st.unpack_from(self.raw, self.off)
        self.off += st.size
        return out

    def string(self) -> str:
        (n,) = self.take(_U32)
        if n > len(self.raw) - self.off:
            raise ValueError(f"a string of {n} bytes runs past the end of the message")
        text = self.raw[self.off : self.off + n].decode()
        self.off += n
        return text

    def time(self) -> Time:
        sec, nsec = self.take(_TIME)
        return Time.from_ns(sec * 1_000_000_000 + nsec)

    def header(self) -> Header:
        self.take(_U32)  # seq
        stamp = self.time()
        return Header(stamp, self.string())


def encode_goal(goal_id: str, seq: int, target: str, source: str, source_time: Time,
                timeout: float, target_time: Time, fixed: str, advanced: bool) -> bytes:
    """A ``tf2_msgs/LookupTransformActionGoal`` in ROS 1 serialisation.

    Raises:
        ValueError: a time at or after 2**32 s, past ROS 1 time (uint32 seconds).
    """
    now = Time.from_ns(_wallclock.time_ns())
    seconds = math.floor(timeout)
    return b"".join((
        _U32.pack(seq), _time(now), _string(""),                       # header
        _time(now), _string(goal_id),                                  # goal_id
        _string(target), _string(source), _time(source_time),
        _DURATION.pack(seconds, round((timeout - seconds) * 1e9)),
        _time(target_time), _string(fixed), _U8.pack(1 if advanced else 0),
    ))


def decode_result(raw: bytes) -> tuple[str, TransformStamped, int, str]:
    """``(goal id, transform, TF2Error code, error string)`` of a
    ``tf2_msgs/LookupTransformActionResult``.

    Raises:
        ValueError: the bytes are not such a message.
    """
    return decode_result_status(raw)[:4]


class Goal(NamedTuple):
    """A decoded ``tf2_msgs/LookupTransformActionGoal``."""

    goal_id: str
    goal_stamp: Time
    target_frame: str
    source_frame: str
    source_time: Time
    timeout: float
    target_time: Time
    fixed_frame: str
    advanced: bool


def decode_goal(raw: bytes) -> Goal:
    """The fields of a ``tf2_msgs/LookupTransformActionGoal``.

    Raises:
        ValueError: the bytes are not such a message.
    """
    try:
        r = _Reader(raw)
        r.header()
        stamp = r.time()
        goal_id = r.string()
        target, source = r.string(), r.string()
        source_time = r.time()
        sec, nsec = r.take(_DURATION)
        target_time = r.time()
        fixed = r.string()
        (advanced,) = r.take(_U8)
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"malformed {GOAL_TYPE}: {exc}") from exc
    return Goal(goal_id, stamp, target, source, source_time, max(0.0, sec + nsec / 1e9),
                target_time, fixed, bool(advanced))


def _goal_status(goal_id: str, stamp: Time, status: int, text: str = "") -> bytes:
    return _time(stamp) + _string(goal_id) + _U8.pack(status) + _string(text)


def decode_goal_id(raw: bytes) -> tuple[Time, str]:
    """``(stamp, id)`` of an ``actionlib_msgs/GoalID`` (a cancel request).

    Raises:
        ValueError: the bytes are not such a message.
    """
    try:
        r = _Reader(raw)
        stamp = r.time()
        goal_id = r.string()
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"malformed {CANCEL_TYPE}: {exc}") from exc
    return stamp, goal_id


def encode_goal_id(stamp: Time, goal_id: str) -> bytes:
    """An ``actionlib_msgs/GoalID`` (a cancel request: actionlib's client cancels its goal
    with ``GoalID(stamp=0, id=goal_id)``).

    Raises:
        ValueError: a stamp at or after 2**32 s.
    """
    return _time(stamp) + _string(goal_id)


def decode_result_status(raw: bytes) -> tuple[str, TransformStamped, int, str, int, str]:
    """``(goal id, transform, TF2Error code, error string, GoalStatus status, status
    text)`` of a ``tf2_msgs/LookupTransformActionResult``.

    Raises:
        ValueError: the bytes are not such a message.
    """
    try:
        r = _Reader(raw)
        r.header()
        r.time()
        goal_id = r.string()
        (status,) = r.take(_U8)
        text = r.string()
        header = r.header()
        child = r.string()
        x, y, z, qx, qy, qz, qw = r.take(_POSE)
        (code,) = r.take(_U8)
        message = r.string()
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"malformed {RESULT_TYPE}: {exc}") from exc
    ts = TransformStamped(header, child, Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)))
    return goal_id, ts, code, message, status, text


def encode_result(seq: int, goal_id: str, goal_stamp: Time, ts: TransformStamped, code: int,
                  message: str, status: int = _SUCCEEDED, text: str = "") -> bytes:
    """A ``tf2_msgs/LookupTransformActionResult``; by default with status SUCCEEDED (as
    tf2_ros's buffer_server sends every answer, the error in ``TF2Error``); ``status`` and
    ``text`` are the ``actionlib_msgs/GoalStatus`` of a goal ended otherwise (PREEMPTED 2,
    REJECTED 5, RECALLED 8).

    Raises:
        ValueError: ``goal_stamp`` or the transform's stamp is at or after 2**32 s, past
            ROS 1 time (uint32 seconds).
    """
    now = Time.from_ns(_wallclock.time_ns())
    t = ts.transform
    return b"".join((
        _U32.pack(seq), _time(now), _string(""),
        _goal_status(goal_id, goal_stamp, status, text),
        _U32.pack(0), _time(ts.header.stamp), _string(ts.header.frame_id),
        _string(ts.child_frame_id),
        _POSE.pack(*t.translation, *t.rotation),
        _U8.pack(code), _string(message),
    ))


def _loopback(host: str | None) -> bool:
    return host in ("127.0.0.1", "localhost")


def _loopback_uri(uri: str) -> bool:
    """Whether ``uri`` parses and names 127.0.0.1 or localhost (``urlsplit`` raises
    ValueError for e.g. ``http://[::1``)."""
    try:
        return _loopback(urlsplit(uri).hostname)
    except ValueError:
        return False


_Handler = Callable[[bytes], None]
_Answer = tuple[TransformStamped, int, str, int, str]  # transform, code, message, status, text


class _Node:
    """A minimal ROS 1 node (slave API + TCPROS) for a few topics of fixed types."""

    def __init__(self, master_uri: str, name: str) -> None:
        if not _loopback(urlsplit(master_uri).hostname):
            raise ValueError(f"master_uri must be on 127.0.0.1 or localhost, got {master_uri!r}")
        self._master = master_uri
        self.name = name
        self._pubs: dict[str, tuple[str, str]] = {}
        self._subs: dict[str, tuple[str, str, _Handler]] = {}
        self._out: dict[str, list[FrameQueue]] = {}
        self._in: dict[str, set[str]] = {}
        self._changed = anyio.Event()
        self._slave_uri = ""
        self._tcpros: tuple[str, int] | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self.malformed = 0
        self.refused = 0  # publisher URIs / requestTopic answers refused
        self.dropped = 0  # frames dropped from a full subscriber queue

    def publish(self, topic: str, msg_type: str, md5: str) -> None:
        self._pubs[topic] = (msg_type, md5)
        self._out[topic] = []

    def subscribe(self, topic: str, msg_type: str, md5: str, handler: _Handler) -> None:
        self._subs[topic] = (msg_type, md5, handler)
        self._in[topic] = set()

    def subscribers(self, topic: str) -> int:
        return len(self._out.get(topic, ()))

    def publishers(self, topic: str) -> int:
        return len(self._in.get(topic, ()))

    async def changed(self) -> None:
        """Wait until a connection opens or closes."""
        await self._changed.wait()

    def _wake(self) -> None:
        event, self._changed = self._changed, anyio.Event()
        event.set()

    def send_nowait(self, topic: str, payload: bytes) -> None:
        """Queue ``payload`` for every subscriber of ``topic``. Each connection sends its
        own queue, so a subscriber that does not read holds up no other; its queue keeps
        at most ``_QUEUE_FRAMES`` frames and ``_QUEUE_BYTES`` bytes (but always the
        newest frame), the oldest dropped and counted in ``dropped``."""
        data = frame(payload)
        for sub in self._out.get(topic, ()):
            self.dropped += sub.put(data)

    def refuse(self, what: str, uri: str) -> None:
        """Count and log (limited in time) a publisher that is not followed."""
        self.refused += 1
        _peer_log.log(logging.WARNING, "ros1: %s: not following publisher %r: %s",
                      self.name, uri[:200], what)

    # SlaveNode
    @property
    def master_uri(self) -> str:
        return self._master

    def bus_info(self) -> list[list[Any]]:
        return []

    def subscriptions(self) -> Sequence[str]:
        return list(self._subs)

    def topic_type(self, topic: str) -> str:
        """The ROS 1 type this node subscribes to ``topic`` with (``getSubscriptions``)."""
        return self._subs[topic][0] if topic in self._subs else ""

    def publications(self) -> Sequence[str]:
        return list(self._pubs)

    def tcpros_endpoint(self, topic: str) -> tuple[str, int] | None:
        return self._tcpros if topic in self._pubs else None

    def on_publisher_update(self, topic: str, publishers: list[str]) -> None:
        if topic in self._subs and self._tg is not None:
            for uri in publishers[:64]:
                self._tg.start_soon(self._receive, topic, uri)

    def on_shutdown(self, caller_id: str, message: str) -> None:
        """Ignored: the owner's context manager decides when the node ends."""

    def on_bad_request(self, reason: str) -> None:
        """Counted by nobody: SlaveServer answers it."""

    async def start(self, tg: anyio.abc.TaskGroup) -> None:
        self._tg = tg
        slave = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
        tcpros = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
        port = slave.listeners[0].extra(anyio.abc.SocketAttribute.local_port)
        self._tcpros = ("127.0.0.1", tcpros.listeners[0].extra(
            anyio.abc.SocketAttribute.local_port))
        self._slave_uri = f"http://127.0.0.1:{port}/"
        tg.start_soon(serve_listener, slave, SlaveServer(self).handle, "slave API")
        tg.start_soon(serve_listener, tcpros, self._serve, "TCPROS")
        for topic, (msg_type, _md5) in self._pubs.items():
            await call(self._master, "registerPublisher", self.name, topic, msg_type,
                       self._slave_uri, timeout=10.0)
        for topic, (msg_type, _md5, _h) in self._subs.items():
            uris = await call(self._master, "registerSubscriber", self.name, topic, msg_type,
                              self._slave_uri, timeout=10.0)
            self.on_publisher_update(topic, [u for u in uris if isinstance(u, str)]
                                     if isinstance(uris, list) else [])

    async def open(self) -> anyio.abc.TaskGroup:
        """A task group entered here, with the node started in it (:meth:`start`); the
        group is left again if starting fails.

        Raises:
            TransportError: the master cannot be reached or refuses.
        """
        tg = anyio.create_task_group()
        await tg.__aenter__()
        try:
            await self.start(tg)
        except BaseException:
            tg.cancel_scope.cancel()
            await tg.__aexit__(None, None, None)
            raise
        return tg

    async def close(self, tg: anyio.abc.TaskGroup) -> None:
        """Unregister (:meth:`stop`), then end the task group :meth:`open` gave."""
        await self.stop()
        tg.cancel_scope.cancel()
        await tg.__aexit__(None, None, None)

    async def stop(self) -> None:
        with anyio.move_on_after(2.0, shield=True), contextlib.suppress(TransportError):
            for topic in self._pubs:
                await call(self._master, "unregisterPublisher", self.name, topic,
                           self._slave_uri, timeout=1.0)
            for topic in self._subs:
                await call(self._master, "unregisterSubscriber", self.name, topic,
                           self._slave_uri, timeout=1.0)

    async def _serve(self, stream: anyio.abc.SocketStream) -> None:
        """A subscriber of one of our topics connects."""
        async with stream:
            try:
                with anyio.fail_after(10):
                    header = decode_header(await read_frame(
                        BufferedByteReceiveStream(stream), 65536, "connection header"))
            except (TimeoutError, ValueError, OSError, anyio.EndOfStream, anyio.IncompleteRead,
                    anyio.BrokenResourceError):  # anyio's error for ECONNRESET
                return
            topic = header.get("topic", "")
            kind = self._pubs.get(topic)
            if kind is None or header.get("md5sum") not in (kind[1], "*"):
                with contextlib.suppress(OSError, anyio.BrokenResourceError):
                    await stream.send(encode_header({"error": f"{topic!r}: wrong md5sum"
                                                     if kind else f"no topic {topic!r}"}))
                return
            try:
                await stream.send(encode_header({
                    "callerid": self.name, "md5sum": kind[1], "type": kind[0], "topic": topic,
                    "latching": "0", "message_definition": ""}))
            except (OSError, anyio.BrokenResourceError):
                return
            if header.get("probe") == "1":
                return
            sub = FrameQueue(_QUEUE_FRAMES, _QUEUE_BYTES)
            self._out[topic].append(sub)
            self._wake()
            try:
                await serve_subscriber(stream, sub)
            finally:
                self._out[topic].remove(sub)
                self._wake()

    async def _receive(self, topic: str, uri: str) -> None:
        """Receive ``topic`` from one publisher."""
        connected = self._in[topic]
        if uri in connected:
            return
        if not _loopback_uri(uri):
            self.refuse("not an http URI on 127.0.0.1 or localhost", uri)
            return
        msg_type, md5, handler = self._subs[topic]
        try:
            answer = await call(uri, "requestTopic", self.name, topic, [["TCPROS"]],
                                timeout=10.0)
            if not (isinstance(answer, list) and len(answer) == 3 and answer[0] == "TCPROS"
                    and _loopback(str(answer[1])) and type(answer[2]) is int
                    and 0 < answer[2] < 65536):
                self.refuse(f"requestTopic answered {answer!r:.200}", uri)
                return
            stream = await anyio.connect_tcp(str(answer[1]), answer[2])
        except (TransportError, OSError):
            return
        async with stream:
            reader = BufferedByteReceiveStream(stream)
            try:
                await stream.send(encode_header({
                    "callerid": self.name, "topic": topic, "md5sum": md5, "type": msg_type,
                    "tcp_nodelay": "1"}))
                header = decode_header(await read_frame(reader, 65536, "connection header"))
                if "error" in header:
                    return
                connected.add(uri)
                self._wake()
                while True:
                    handler(await read_frame(reader, _MAX_FRAME, msg_type))
            except (ValueError, OSError, anyio.EndOfStream, anyio.IncompleteRead,
                    anyio.BrokenResourceError):
                return
            finally:
                connected.discard(uri)
                self._wake()


class Ros1BufferClient:
    """tf2_ros ``BufferClient`` on ROS 1 (module doc): ``async with
    Ros1BufferClient(master_uri) as client: await client.lookup_transform(...)``.

    Args:
        master_uri: the ROS 1 master (``http://127.0.0.1:11311``; loopback only).
        server: the action's namespace (tf2_ros's default ``/tf2_buffer_server``).
        name: this node's name (``/tfbus_buffer_client_<pid>`` by default).
        timeout_padding: wall seconds added to each lookup's timeout for the round trip
            (tf2_ros ``BufferClient``'s ``timeout_padding``, 2 s).

    Raises:
        ValueError: a master that is not on 127.0.0.1 / localhost.
    """

    def __init__(self, master_uri: str, *, server: str = "/tf2_buffer_server",
                 name: str | None = None, timeout_padding: float = 2.0) -> None:
        self._node = _Node(master_uri, name or f"/tfbus_buffer_client_{os.getpid()}")
        self._goal_topic = f"{server}/goal"
        self._cancel_topic = f"{server}/cancel"
        self._result_topic = f"{server}/result"
        self._node.publish(self._goal_topic, GOAL_TYPE, GOAL_MD5)
        self._node.publish(self._cancel_topic, CANCEL_TYPE, CANCEL_MD5)
        self._node.subscribe(self._result_topic, RESULT_TYPE, RESULT_MD5, self._on_result)
        self._padding = timeout_padding
        self._waiting: dict[str, tuple[anyio.Event, list[_Answer]]] = {}
        self._seq = 0
        self._tg: anyio.abc.TaskGroup | None = None

    @property
    def malformed(self) -> int:
        """Result messages that did not decode (counted, dropped)."""
        return self._node.malformed

    @property
    def refused(self) -> int:
        """Publishers of the results not followed: a URI that is not a loopback
        ``http://host:port``, or a ``requestTopic`` answer that is not a loopback TCPROS
        endpoint (counted, logged)."""
        return self._node.refused

    @property
    def dropped(self) -> int:
        """Goals dropped for a server that does not read them fast enough (the oldest,
        beyond 1000 goals or 8 MiB queued)."""
        return self._node.dropped

    async def __aenter__(self) -> Ros1BufferClient:
        """Start the node and register with the master.

        Raises:
            TransportError: the master cannot be reached or refuses.
        """
        self._tg = await self._node.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Unregister and stop."""
        tg, self._tg = self._tg, None
        if tg is not None:
            await self._node.close(tg)

    @coroutine_method
    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration = 0.0) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``: the server waits up to ``timeout``
        seconds of its clock.

        A lookup cancelled here (or not answered in time) is cancelled on the server too
        (``actionlib_msgs/GoalID`` with its goal id on ``{server}/cancel``).

        Raises:
            The server's tf2 error as the same tfbus class (its message kept);
            TimeoutException if no result came within ``timeout + timeout_padding``
            wall seconds, or the result's status is not SUCCEEDED (the goal was
            REJECTED, PREEMPTED or RECALLED; tf2_ros's messages, the status and its text
            appended); ValueError for a time at or after 2**32 s (past ROS 1 time).
        """
        return await self._goal(target_frame, source_frame, time, timeout, Time(0), "", False)

    @coroutine_method
    async def lookup_transform_full(self, target_frame: str, target_time: Time,
                                    source_frame: str, source_time: Time, fixed_frame: str,
                                    timeout: float | Duration = 0.0) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform_full`` (the advanced goal).

        Raises: as :meth:`lookup_transform`.
        """
        return await self._goal(target_frame, source_frame, source_time, timeout,
                                target_time, fixed_frame, True)

    def _on_result(self, raw: bytes) -> None:
        try:
            goal_id, ts, code, message, status, text = decode_result_status(raw)
        except ValueError:
            self._node.malformed += 1
            return
        waiting = self._waiting.get(goal_id)
        if waiting is not None:
            waiting[1].append((ts, code, message, status, text))
            waiting[0].set()

    async def _goal(self, target: str, source: str, source_time: Time,
                    timeout: float | Duration, target_time: Time, fixed: str,
                    advanced: bool) -> TransformStamped:
        seconds = timeout.to_sec() if isinstance(timeout, Duration) else float(timeout)
        if not seconds >= 0 or math.isinf(seconds):
            raise ValueError(f"timeout must be finite seconds >= 0, got {timeout!r}")
        self._seq += 1
        goal_id = f"{self._node.name}-{self._seq}-{secrets.token_hex(4)}"
        done = anyio.Event()
        box: list[_Answer] = []
        self._waiting[goal_id] = (done, box)
        node = self._node
        sent = False
        try:
            with anyio.move_on_after(seconds + self._padding):
                while not (node.subscribers(self._goal_topic)
                           and node.subscribers(self._cancel_topic)
                           and node.publishers(self._result_topic)):
                    await node.changed()
                node.send_nowait(self._goal_topic, encode_goal(
                    goal_id, self._seq, target, source, source_time, seconds, target_time,
                    fixed, advanced))
                sent = True
                await done.wait()
        finally:
            self._waiting.pop(goal_id, None)
            if sent and not box:
                # cancelled, or no answer in time: cancel the goal, as actionlib's
                # ClientGoalHandle.cancel (GoalID stamp 0, this id), so that the server
                # does not hold it for nobody
                node.send_nowait(self._cancel_topic, encode_goal_id(Time(0), goal_id))
        if not box:
            raise errors.TimeoutException(
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server.")
        return result_transform(*box[0])


def result_transform(ts: TransformStamped, code: int, message: str, status: int,
                     text: str) -> TransformStamped:
    """The transform of a decoded ``LookupTransformActionResult``
    (:func:`decode_result_status`), or its error raised as tf2_ros's ``BufferClient``
    does (``buffer_client.py`` ``__process_goal`` / ``__process_result``).

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
        raise _ERRORS.get(code, TransformException)(message)
    return ts


class _Held:
    """A goal the server holds: its task's cancel scope, once it runs."""

    __slots__ = ("cancel_requested", "goal", "scope", "size")

    def __init__(self, goal: Goal, size: int) -> None:
        self.goal = goal
        self.size = size
        self.scope: anyio.CancelScope | None = None
        self.cancel_requested = False

    def cancel(self) -> None:
        self.cancel_requested = True
        if self.scope is not None:
            self.scope.cancel()


class Ros1BufferServer:
    """tf2_ros ``buffer_server`` on ROS 1 answering from ``buffer`` (module doc):
    ``async with Ros1BufferServer(buffer, master_uri):``.

    Goals wait on ``buffer`` for at most their timeout and at most ``max_wait`` seconds
    (of the buffer's clock, and of wall time), then are answered with the lookup's own
    result or error (``buffer_server.cpp`` ``checkTransforms``). A cancel request
    (``actionlib_msgs/GoalID`` on ``{server}/cancel``) ends the goals it names at once
    with a PREEMPTED result (module doc). At most ``max_goals`` goals, and at most
    :data:`MAX_HELD_GOAL_BYTES` of them, are held; more are answered at once with a
    REJECTED result whose status text says "buffer server busy: ...". The status array
    (5 Hz) lists the goals held (ACTIVE) and those ended in the last 5 s (actionlib's
    ``status_list_timeout``), so that actionlib clients follow them.

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from (its clock bounds the
            goals' timeouts).
        master_uri: the ROS 1 master (loopback only).
        server: the action's namespace (default ``/tf2_buffer_server``, the real node's).
        name: this node's name (default ``/tf2_buffer_server``, the real node's).
        max_goals: most goals held at once.
        max_wait: longest wait of one goal, seconds (default 60).

    Raises:
        ValueError: a master that is not on 127.0.0.1 / localhost, ``max_goals`` < 1, or
            ``max_wait`` not a positive finite number.
    """

    def __init__(self, buffer: Buffer, master_uri: str, *,
                 server: str = "/tf2_buffer_server", name: str = "/tf2_buffer_server",
                 max_goals: int = 1000, max_wait: float = 60.0) -> None:
        if max_goals < 1:
            raise ValueError(f"max_goals must be at least 1, got {max_goals!r}")
        if isinstance(max_wait, bool) or not isinstance(max_wait, (int, float)) \
                or not 0 < max_wait < math.inf:
            raise ValueError(f"max_wait must be positive finite seconds, got {max_wait!r}")
        self._buffer = buffer
        self._node = _Node(master_uri, name)
        self._topics = {k: f"{server}/{k}" for k in ("goal", "cancel", "result", "feedback",
                                                      "status")}
        self._node.subscribe(self._topics["goal"], GOAL_TYPE, GOAL_MD5, self._on_goal)
        self._node.subscribe(self._topics["cancel"], CANCEL_TYPE, CANCEL_MD5, self._on_cancel)
        self._node.publish(self._topics["result"], RESULT_TYPE, RESULT_MD5)
        self._node.publish(self._topics["feedback"], FEEDBACK_TYPE, FEEDBACK_MD5)
        self._node.publish(self._topics["status"], STATUS_TYPE, STATUS_MD5)
        self._max_goals = max_goals
        self._max_wait = float(max_wait)
        self._held: dict[str, _Held] = {}
        self._held_bytes = 0
        # goals ended lately, for the status array: id -> (stamp, status, text, when)
        self._ended: dict[str, tuple[Time, int, str, float]] = {}
        self._recall: dict[str, None] = {}  # cancelled by id before they came (bounded)
        self._last_cancel = Time(0)
        self._tg: anyio.abc.TaskGroup | None = None
        self._seq = 0
        self.answered = 0
        """Goals answered (with a transform or a TF2Error)."""
        self.refused_answers = 0
        """Goals not answered because ROS 1 cannot carry the answer: the goal's stamp or
        the transform's is at or after 2**32 s (uint32 seconds); counted, logged."""
        self.cancelled = 0
        """Goals ended by a cancel request (PREEMPTED, or RECALLED when it came first)."""
        self.rejected = 0
        """Goals REJECTED because ``max_goals`` goals (or :data:`MAX_HELD_GOAL_BYTES`)
        were held."""

    @property
    def malformed(self) -> int:
        """Goals and cancel requests that did not decode, or whose goal id is longer than
        :data:`MAX_GOAL_ID_BYTES` (counted, dropped)."""
        return self._node.malformed

    @property
    def pending(self) -> int:
        """Goals held now (waiting for their transform)."""
        return len(self._held)

    @property
    def refused(self) -> int:
        """Publishers of goals not followed: a URI that is not a loopback
        ``http://host:port``, or a ``requestTopic`` answer that is not a loopback TCPROS
        endpoint (counted, logged)."""
        return self._node.refused

    @property
    def dropped(self) -> int:
        """Frames (results, feedback, status) dropped for subscribers that do not read
        them fast enough (the oldest, beyond 1000 frames or 8 MiB queued for one)."""
        return self._node.dropped

    async def __aenter__(self) -> Ros1BufferServer:
        """Start the node, register with the master, publish status at 5 Hz.

        Raises:
            TransportError: the master cannot be reached or refuses.
        """
        self._tg = await self._node.open()
        self._tg.start_soon(self._status)
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Unregister and stop (goals still waiting are dropped)."""
        tg, self._tg = self._tg, None
        if tg is not None:
            await self._node.close(tg)

    async def _status(self) -> None:
        seq = 0
        while True:
            seq += 1
            now = Time.from_ns(_wallclock.time_ns())
            self._node.send_nowait(self._topics["status"], _U32.pack(seq) + _time(now)
                                   + _string("") + self._status_list())
            await anyio.sleep(0.2)

    def _status_list(self) -> bytes:
        """The ``status_list`` of a ``GoalStatusArray``: the goals held (ACTIVE), then
        those ended within the last 5 s (the older ones forgotten)."""
        horizon = _wallclock.monotonic() - _STATUS_KEPT
        ended = self._ended
        while ended:
            oldest = next(iter(ended))
            if ended[oldest][3] >= horizon:
                break
            del ended[oldest]
        parts = [_goal_status(h.goal.goal_id, h.goal.goal_stamp, _ACTIVE)
                 for h in self._held.values()]
        parts += [_goal_status(goal_id, stamp, status, text)
                  for goal_id, (stamp, status, text, _when) in ended.items()]
        return _U32.pack(len(parts)) + b"".join(parts)

    def _on_goal(self, raw: bytes) -> None:
        try:
            goal = decode_goal(raw)
        except ValueError:
            self._node.malformed += 1
            return
        if len(goal.goal_id) > MAX_GOAL_ID_BYTES // 4 \
                and len(goal.goal_id.encode()) > MAX_GOAL_ID_BYTES:
            self._node.malformed += 1
            return
        if self._tg is None or goal.goal_id in self._held or goal.goal_id in self._ended:
            return  # actionlib ActionServerBase::goalCallback: a known goal is ignored
        by_id = goal.goal_id in self._recall
        if by_id or (goal.goal_stamp != Time(0) and goal.goal_stamp <= self._last_cancel):
            # actionlib goalCallback: a goal cancelled before it came is RECALLED
            self._recall.pop(goal.goal_id, None)
            text = "" if by_id else _RECALLED_BY_STAMP
            self.cancelled += 1
            self._end(goal, _RECALLED, text)
            return
        if len(self._held) >= self._max_goals \
                or self._held_bytes + len(raw) > MAX_HELD_GOAL_BYTES:
            self.rejected += 1
            self._end(goal, _REJECTED, f"buffer server busy: {len(self._held)} goals waiting "
                                       f"({self._held_bytes} bytes; max_goals "
                                       f"{self._max_goals})")
            return
        held = _Held(goal, len(raw))
        self._held[goal.goal_id] = held
        self._held_bytes += held.size
        self._tg.start_soon(self._answer, held)

    def _on_cancel(self, raw: bytes) -> None:
        """actionlib ``ActionServerBase::cancelCallback`` (``action_server_base.h``) with
        tf2_ros ``BufferServer::cancelCB`` (``buffer_server.cpp``) as the cancel callback:
        an empty id and a zero stamp cancel every goal held; an id, that goal; a non-zero
        stamp, every goal stamped at or before it. An id not held is kept (bounded) so
        that its goal is RECALLED when it comes; the latest stamp is kept so that goals
        stamped at or before it are RECALLED when they come."""
        try:
            stamp, goal_id = decode_goal_id(raw)
        except ValueError:
            self._node.malformed += 1
            return
        if len(goal_id) > MAX_GOAL_ID_BYTES // 4 and len(goal_id.encode()) > MAX_GOAL_ID_BYTES:
            self._node.malformed += 1
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
            while len(self._recall) > self._max_goals:
                del self._recall[next(iter(self._recall))]
        if stamp > self._last_cancel:
            self._last_cancel = stamp

    def _end(self, goal: Goal, status: int, text: str) -> None:
        """Send a goal's result with ``status`` (no transform) and list it as ended."""
        self._send_result(goal, TransformStamped(Header(), "", Transform()), 0, "",
                          status, text)

    def _send_result(self, goal: Goal, ts: TransformStamped, code: int, message: str,
                     status: int = _SUCCEEDED, text: str = "") -> bool:
        try:
            result = encode_result(self._seq + 1, goal.goal_id, goal.goal_stamp, ts, code,
                                   message, status, text)
        except ValueError as exc:  # a stamp past ROS 1 time
            self.refused_answers += 1
            _peer_log.log(logging.WARNING, "ros1: %s: not answering goal %r: %s",
                          self._node.name, goal.goal_id[:200], exc)
            return False
        self._seq += 1
        self._ended[goal.goal_id] = (goal.goal_stamp, status, text, _wallclock.monotonic())
        while len(self._ended) > self._max_goals:
            del self._ended[next(iter(self._ended))]
        self._node.send_nowait(self._topics["result"], result)
        return True

    async def _answer(self, held: _Held) -> None:
        goal = held.goal
        try:
            with anyio.CancelScope() as scope:
                held.scope = scope
                if held.cancel_requested:
                    scope.cancel()
                with anyio.move_on_after(self._max_wait):
                    ts, code, message = await self._lookup(goal, min(goal.timeout,
                                                                     self._max_wait))
                    if self._send_result(goal, ts, code, message):
                        self.answered += 1
                    return
                # past max_wait of wall time: answered as an expired timeout
                ts, code, message = await self._lookup(goal, 0.0)
                if self._send_result(goal, ts, code, message):
                    self.answered += 1
                return
            # tf2_ros BufferServer::cancelCB: setCanceled() on the active goal: PREEMPTED
            self.cancelled += 1
            self._end(goal, _PREEMPTED, "")
        finally:
            del self._held[goal.goal_id]
            self._held_bytes -= held.size

    async def _lookup(self, goal: Goal, timeout: float) -> tuple[TransformStamped, int, str]:
        """The goal's transform, or its ``TF2Error`` code and message."""
        buffer = self._buffer
        g = goal
        try:
            if g.advanced:
                try:
                    ts = await buffer.lookup_transform_full_async(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame, timeout)
                except errors.TimeoutException:  # buffer_server.cpp: lookup's own error
                    ts = buffer.lookup_transform_full(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame)
            else:
                try:
                    ts = await buffer.lookup_transform_async(
                        g.target_frame, g.source_frame, g.source_time, timeout)
                except errors.TimeoutException:
                    ts = buffer.lookup_transform(g.target_frame, g.source_frame,
                                                 g.source_time)
        except TransformException as exc:
            code = next((c for c, cls in _ERRORS.items() if isinstance(exc, cls)), 6)
            return TransformStamped(Header(), "", Transform()), code, str(exc)
        return ts, 0, ""
