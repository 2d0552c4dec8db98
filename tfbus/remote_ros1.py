"""tf2_ros's own buffer protocol on ROS 1: a client of the ``tf2_msgs/LookupTransform``
action (actionlib over TCPROS), answered by tf2_ros's real ``buffer_server`` node.

:class:`Ros1BufferClient` is tf2_ros ``BufferClient`` (``buffer_client.cpp`` /
``buffer_client.py``) as a tfbus node of its own: it publishes
``/tf2_buffer_server/goal`` (``tf2_msgs/LookupTransformActionGoal``) and subscribes to
``/tf2_buffer_server/result`` (``tf2_msgs/LookupTransformActionResult``) through a ROS 1
master; the server's ``TF2Error`` comes back as the tf2 exception of the same kind with
the server's message (tf2_ros ``BufferClient::processResult``). Loopback only: the
node listens on 127.0.0.1 and contacts only 127.0.0.1 / localhost peers.

Not done yet: a tfbus ``BufferServer`` answering Debian's ``tf2_ros.BufferClient`` over
this action (issue 25).
"""

from __future__ import annotations

import contextlib
import math
import os
import secrets
import struct
import time as _wallclock
from collections.abc import Sequence
from typing import Any, Final
from urllib.parse import urlsplit

import anyio
import anyio.abc
from anyio.streams.buffered import BufferedByteReceiveStream

from tfbus import errors
from tfbus.errors import TransformException, TransportError
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Duration, Time
from tfbus.transports.ros1.rpc import SlaveServer, call, serve_listener
from tfbus.transports.ros1.tcpros import decode_header, encode_header, frame, read_frame

__all__ = ["GOAL_MD5", "GOAL_TYPE", "RESULT_MD5", "RESULT_TYPE", "Ros1BufferClient"]

GOAL_TYPE: Final = "tf2_msgs/LookupTransformActionGoal"
GOAL_MD5: Final = "f2e7bcdb75c847978d0351a13e699da5"
"""md5sum of ``tf2_msgs/LookupTransformActionGoal`` (tf2_msgs 0.7.6; checked against
Debian's python3-tf2-msgs by the tests)."""
RESULT_TYPE: Final = "tf2_msgs/LookupTransformActionResult"
RESULT_MD5: Final = "ac26ce75a41384fa8bb4dc10f491ab90"
"""md5sum of ``tf2_msgs/LookupTransformActionResult`` (tf2_msgs 0.7.6)."""

_ERRORS: Final[dict[int, type[TransformException]]] = {
    1: errors.LookupException,  # tf2_msgs/TF2Error LOOKUP_ERROR
    2: errors.ConnectivityException,
    3: errors.ExtrapolationException,
    4: errors.InvalidArgumentException,
    5: errors.TimeoutException,
    6: errors.TransformException,
}
_MAX_FRAME: Final = 1 << 20
_U8 = struct.Struct("<B")
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<II")
_DURATION = struct.Struct("<ii")
_POSE = struct.Struct("<7d")


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _time(t: Time) -> bytes:
    return _TIME.pack(t.ns // 1_000_000_000, t.ns % 1_000_000_000)


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
    """A ``tf2_msgs/LookupTransformActionGoal`` in ROS 1 serialisation."""
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


def _loopback(host: str | None) -> bool:
    return host in ("127.0.0.1", "localhost")


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
        if not _loopback(urlsplit(master_uri).hostname):
            raise ValueError(f"master_uri must be on 127.0.0.1 or localhost, got {master_uri!r}")
        self._master = master_uri
        self._name = name or f"/tfbus_buffer_client_{os.getpid()}"
        self._goal_topic = f"{server}/goal"
        self._result_topic = f"{server}/result"
        self._padding = timeout_padding
        self._slave_uri = ""
        self._tcpros: tuple[str, int] | None = None
        self._goal_streams: list[anyio.abc.SocketStream] = []
        self._result_from: set[str] = set()
        self._connected = anyio.Event()
        self._waiting: dict[str, tuple[anyio.Event, list[tuple[TransformStamped, int, str]]]] = {}
        self._seq = 0
        self._tg: anyio.abc.TaskGroup | None = None
        self.malformed = 0
        """Result messages that did not decode (counted, dropped)."""

    # -- SlaveNode -------------------------------------------------------------------

    @property
    def master_uri(self) -> str:
        """The master this node registered with."""
        return self._master

    def bus_info(self) -> list[list[Any]]:
        """No connection details are reported."""
        return []

    def subscriptions(self) -> Sequence[str]:
        """The result topic."""
        return [self._result_topic]

    def publications(self) -> Sequence[str]:
        """The goal topic."""
        return [self._goal_topic]

    def tcpros_endpoint(self, topic: str) -> tuple[str, int] | None:
        """Where subscribers of the goal topic connect."""
        return self._tcpros if topic == self._goal_topic else None

    def on_publisher_update(self, topic: str, publishers: list[str]) -> None:
        """Connect to new publishers of the result topic."""
        if topic == self._result_topic and self._tg is not None:
            for uri in publishers:
                self._tg.start_soon(self._subscribe, uri)

    def on_shutdown(self, caller_id: str, message: str) -> None:
        """Ignored (the context manager decides when the node ends)."""

    def on_bad_request(self, reason: str) -> None:
        """Ignored (SlaveServer answers it)."""

    # -- lifecycle -------------------------------------------------------------------

    async def __aenter__(self) -> Ros1BufferClient:
        """Start the node and register with the master.

        Raises:
            TransportError: the master cannot be reached or refuses.
        """
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        try:
            slave = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
            tcpros = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
            slave_port = slave.listeners[0].extra(anyio.abc.SocketAttribute.local_port)
            self._tcpros = ("127.0.0.1", tcpros.listeners[0].extra(
                anyio.abc.SocketAttribute.local_port))
            self._slave_uri = f"http://127.0.0.1:{slave_port}/"
            tg.start_soon(serve_listener, slave, SlaveServer(self).handle, "slave API")
            tg.start_soon(serve_listener, tcpros, self._serve_goal, "TCPROS")
            await call(self._master, "registerPublisher", self._name, self._goal_topic,
                       GOAL_TYPE, self._slave_uri, timeout=10.0)
            publishers = await call(self._master, "registerSubscriber", self._name,
                                    self._result_topic, RESULT_TYPE, self._slave_uri,
                                    timeout=10.0)
            for uri in publishers if isinstance(publishers, list) else ():
                tg.start_soon(self._subscribe, uri)
        except BaseException:
            tg.cancel_scope.cancel()
            await tg.__aexit__(None, None, None)
            self._tg = None
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Unregister and stop."""
        tg, self._tg = self._tg, None
        if tg is None:
            return
        with anyio.move_on_after(2.0, shield=True):
            with contextlib.suppress(TransportError):
                await call(self._master, "unregisterPublisher", self._name, self._goal_topic,
                           self._slave_uri, timeout=1.0)
                await call(self._master, "unregisterSubscriber", self._name,
                           self._result_topic, self._slave_uri, timeout=1.0)
        tg.cancel_scope.cancel()
        await tg.__aexit__(None, None, None)

    # -- lookups ---------------------------------------------------------------------

    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration = 0.0) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``: the server waits up to ``timeout``
        seconds of its clock.

        Raises:
            The server's tf2 error as the same tfbus class (its message kept);
            TimeoutException if no result came within ``timeout + timeout_padding``
            wall seconds (tf2_ros: "The LookupTransform goal sent to the BufferServer
            did not come back in the specified time").
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

    async def _goal(self, target: str, source: str, source_time: Time,
                    timeout: float | Duration, target_time: Time, fixed: str,
                    advanced: bool) -> TransformStamped:
        seconds = timeout.to_sec() if isinstance(timeout, Duration) else float(timeout)
        if not seconds >= 0 or math.isinf(seconds):
            raise ValueError(f"timeout must be finite seconds >= 0, got {timeout!r}")
        wall = seconds + self._padding
        self._seq += 1
        goal_id = f"{self._name}-{self._seq}-{secrets.token_hex(4)}"
        done = anyio.Event()
        box: list[tuple[TransformStamped, int, str]] = []
        self._waiting[goal_id] = (done, box)
        try:
            with anyio.move_on_after(wall):
                while not (self._goal_streams and self._result_from):
                    await self._connected.wait()
                payload = frame(encode_goal(goal_id, self._seq, target, source, source_time,
                                            seconds, target_time, fixed, advanced))
                for stream in list(self._goal_streams):
                    with contextlib.suppress(OSError, anyio.BrokenResourceError):
                        await stream.send(payload)
                await done.wait()
        finally:
            self._waiting.pop(goal_id, None)
        if not box:
            raise errors.TimeoutException(
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server.")
        ts, code, message = box[0]
        if code:
            raise _ERRORS.get(code, TransformException)(message)
        return ts

    # -- TCPROS ----------------------------------------------------------------------

    def _wake(self) -> None:
        event, self._connected = self._connected, anyio.Event()
        event.set()

    async def _serve_goal(self, stream: anyio.abc.SocketStream) -> None:
        """A subscriber of the goal topic (the buffer server) connects."""
        async with stream:
            try:
                with anyio.fail_after(10):
                    header = decode_header(await read_frame(
                        BufferedByteReceiveStream(stream), 65536, "connection header"))
            except (TimeoutError, ValueError, OSError, anyio.EndOfStream, anyio.IncompleteRead):
                return
            if header.get("topic") != self._goal_topic or header.get("md5sum") not in (
                    GOAL_MD5, "*"):
                with contextlib.suppress(OSError, anyio.BrokenResourceError):
                    await stream.send(encode_header({"error": "wrong topic or md5sum"}))
                return
            await stream.send(encode_header({
                "callerid": self._name, "md5sum": GOAL_MD5, "type": GOAL_TYPE,
                "topic": self._goal_topic, "latching": "0"}))
            self._goal_streams.append(stream)
            self._wake()
            try:
                with contextlib.suppress(anyio.EndOfStream, OSError, anyio.BrokenResourceError):
                    while await stream.receive():  # a subscriber sends nothing more
                        pass
            finally:
                self._goal_streams.remove(stream)

    async def _subscribe(self, uri: str) -> None:
        """Receive results from one publisher of the result topic."""
        if uri in self._result_from or not _loopback(urlsplit(uri).hostname):
            return
        try:
            answer = await call(uri, "requestTopic", self._name, self._result_topic,
                                [["TCPROS"]], timeout=10.0)
            if not (isinstance(answer, list) and len(answer) == 3 and answer[0] == "TCPROS"
                    and _loopback(str(answer[1])) and isinstance(answer[2], int)):
                return
            stream = await anyio.connect_tcp(str(answer[1]), answer[2])
        except (TransportError, OSError):
            return
        async with stream:
            await stream.send(encode_header({
                "callerid": self._name, "topic": self._result_topic, "md5sum": RESULT_MD5,
                "type": RESULT_TYPE, "tcp_nodelay": "1"}))
            reader = BufferedByteReceiveStream(stream)
            try:
                header = decode_header(await read_frame(reader, 65536, "connection header"))
                if "error" in header:
                    return
                self._result_from.add(uri)
                self._wake()
                while True:
                    raw = await read_frame(reader, _MAX_FRAME, RESULT_TYPE)
                    try:
                        goal_id, ts, code, message = decode_result(raw)
                    except ValueError:
                        self.malformed += 1
                        continue
                    waiting = self._waiting.get(goal_id)
                    if waiting is not None:
                        waiting[1].append((ts, code, message))
                        waiting[0].set()
            except (ValueError, OSError, anyio.EndOfStream, anyio.IncompleteRead,
                    anyio.BrokenResourceError):
                return
            finally:
                self._result_from.discard(uri)
