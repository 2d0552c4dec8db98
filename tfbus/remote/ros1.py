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
  Debian's ``tf2_ros.BufferClient`` gets its answers.

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
    "GOAL_MD5",
    "GOAL_TYPE",
    "RESULT_MD5",
    "RESULT_TYPE",
    "Ros1BufferClient",
    "Ros1BufferServer",
    "decode_goal",
    "decode_result",
    "encode_goal",
    "encode_result",
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
_SUCCEEDED: Final = 3  # actionlib_msgs/GoalStatus SUCCEEDED

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
    try:
        r = _Reader(raw)
        r.header()
        r.time()
        goal_id = r.string()
        r.take(_U8)  # status
        r.string()  # text
        header = r.header()
        child = r.string()
        x, y, z, qx, qy, qz, qw = r.take(_POSE)
        (code,) = r.take(_U8)
        message = r.string()
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"malformed {RESULT_TYPE}: {exc}") from exc
    ts = TransformStamped(header, child, Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)))
    return goal_id, ts, code, message


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


def _goal_status(goal_id: str, stamp: Time, status: int) -> bytes:
    return _time(stamp) + _string(goal_id) + _U8.pack(status) + _string("")


def encode_result(seq: int, goal_id: str, goal_stamp: Time, ts: TransformStamped, code: int,
                  message: str) -> bytes:
    """A ``tf2_msgs/LookupTransformActionResult`` with status SUCCEEDED (as tf2_ros's
    buffer_server sends every answer, the error in ``TF2Error``).

    Raises:
        ValueError: ``goal_stamp`` or the transform's stamp is at or after 2**32 s, past
            ROS 1 time (uint32 seconds).
    """
    now = Time.from_ns(_wallclock.time_ns())
    t = ts.transform
    return b"".join((
        _U32.pack(seq), _time(now), _string(""),
        _goal_status(goal_id, goal_stamp, _SUCCEEDED),
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
        self._result_topic = f"{server}/result"
        self._node.publish(self._goal_topic, GOAL_TYPE, GOAL_MD5)
        self._node.subscribe(self._result_topic, RESULT_TYPE, RESULT_MD5, self._on_result)
        self._padding = timeout_padding
        self._waiting: dict[str, tuple[anyio.Event, list[tuple[TransformStamped, int, str]]]] = {}
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

    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration = 0.0) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``: the server waits up to ``timeout``
        seconds of its clock.

        Raises:
            The server's tf2 error as the same tfbus class (its message kept);
            TimeoutException if no result came within ``timeout + timeout_padding``
            wall seconds (tf2_ros's message); ValueError for a time at or after 2**32 s
            (past ROS 1 time).
        """
        return await self._goal(target_frame, source_frame, time, timeout, Time(0), "", False)

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
            goal_id, ts, code, message = decode_result(raw)
        except ValueError:
            self._node.malformed += 1
            return
        waiting = self._waiting.get(goal_id)
        if waiting is not None:
            waiting[1].append((ts, code, message))
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
        box: list[tuple[TransformStamped, int, str]] = []
        self._waiting[goal_id] = (done, box)
        node = self._node
        try:
            with anyio.move_on_after(seconds + self._padding):
                while not (node.subscribers(self._goal_topic)
                           and node.publishers(self._result_topic)):
                    await node.changed()
                node.send_nowait(self._goal_topic, encode_goal(
                    goal_id, self._seq, target, source, source_time, seconds, target_time,
                    fixed, advanced))
                await done.wait()
        finally:
            self._waiting.pop(goal_id, None)
        if not box:
            raise errors.TimeoutException(
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server.")
        ts, code, message = box[0]
        if code == 3:  # tf2_msgs/TF2Error has one extrapolation code: the text tells which
            raise errors.extrapolation_exception(message)
        if code:
            raise _ERRORS.get(code, TransformException)(message)
        return ts


class Ros1BufferServer:
    """tf2_ros ``buffer_server`` on ROS 1 answering from ``buffer`` (module doc):
    ``async with Ros1BufferServer(buffer, master_uri):``.

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from (its clock bounds the
            goals' timeouts).
        master_uri: the ROS 1 master (loopback only).
        server: the action's namespace (default ``/tf2_buffer_server``, the real node's).
        name: this node's name (default ``/tf2_buffer_server``, the real node's).

    Raises:
        ValueError: a master that is not on 127.0.0.1 / localhost.
    """

    def __init__(self, buffer: Buffer, master_uri: str, *,
                 server: str = "/tf2_buffer_server", name: str = "/tf2_buffer_server") -> None:
        self._buffer = buffer
        self._node = _Node(master_uri, name)
        self._topics = {k: f"{server}/{k}" for k in ("goal", "cancel", "result", "feedback",
                                                      "status")}
        self._node.subscribe(self._topics["goal"], GOAL_TYPE, GOAL_MD5, self._on_goal)
        self._node.subscribe(self._topics["cancel"], CANCEL_TYPE, CANCEL_MD5, lambda raw: None)
        self._node.publish(self._topics["result"], RESULT_TYPE, RESULT_MD5)
        self._node.publish(self._topics["feedback"], FEEDBACK_TYPE, FEEDBACK_MD5)
        self._node.publish(self._topics["status"], STATUS_TYPE, STATUS_MD5)
        self._tg: anyio.abc.TaskGroup | None = None
        self._seq = 0
        self.answered = 0
        """Goals answered (with a transform or a TF2Error)."""
        self.refused_answers = 0
        """Goals not answered because ROS 1 cannot carry the answer: the goal's stamp or
        the transform's is at or after 2**32 s (uint32 seconds); counted, logged."""

    @property
    def malformed(self) -> int:
        """Goals that did not decode (counted, dropped)."""
        return self._node.malformed

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
            self._node.send_nowait(self._topics["status"],
                                   _U32.pack(seq) + _time(now) + _string("") + _U32.pack(0))
            await anyio.sleep(0.2)

    def _on_goal(self, raw: bytes) -> None:
        try:
            goal = decode_goal(raw)
        except ValueError:
            self._node.malformed += 1
            return
        if self._tg is not None:
            self._tg.start_soon(self._answer, goal)

    async def _answer(self, goal: Goal) -> None:
        buffer = self._buffer
        empty = TransformStamped(Header(), "", Transform())
        try:
            if goal.advanced:
                g = goal
                try:
                    ts = await buffer.lookup_transform_full_async(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame, g.timeout)
                except errors.TimeoutException:  # buffer_server.cpp: lookup's own error
                    ts = buffer.lookup_transform_full(
                        g.target_frame, g.target_time, g.source_frame, g.source_time,
                        g.fixed_frame)
            else:
                try:
                    ts = await buffer.lookup_transform_async(
                        goal.target_frame, goal.source_frame, goal.source_time, goal.timeout)
                except errors.TimeoutException:
                    ts = buffer.lookup_transform(goal.target_frame, goal.source_frame,
                                                 goal.source_time)
            code, message = 0, ""
        except TransformException as exc:
            ts = empty
            code = next((c for c, cls in _ERRORS.items() if isinstance(exc, cls)), 6)
            message = str(exc)
        try:
            result = encode_result(self._seq + 1, goal.goal_id, goal.goal_stamp, ts, code,
                                   message)
        except ValueError as exc:  # a stamp past ROS 1 time
            self.refused_answers += 1
            _peer_log.log(logging.WARNING, "ros1: %s: not answering goal %r: %s",
                          self._node.name, goal.goal_id[:200], exc)
            return
        self._seq += 1
        self.answered += 1
        self._node.send_nowait(self._topics["result"], result)
