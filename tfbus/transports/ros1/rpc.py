"""ROS 1's XML-RPC side: calls to the master and to other nodes, and the slave API this
node serves (ROS wiki "ROS/Master_API", "ROS/Slave_API").

Both run natively on anyio sockets (no threads): HTTP/1.0 by hand, the XML-RPC body by
the standard library's :func:`xmlrpc.client.dumps` and its expat parser, read through a
:class:`xmlrpc.client.Unmarshaller` that refuses elements nested deeper than
:data:`MAX_XMLRPC_DEPTH`. Every call has one total deadline (connect, send, receive),
every body is bounded by :data:`MAX_XMLRPC_BYTES`, and each served request must arrive
within :data:`SLAVE_REQUEST_TIMEOUT`, so no peer, however slow or hostile, holds a call,
a thread or the node's shutdown for longer.
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
import xmlrpc.client
from collections.abc import Callable, Coroutine, Sequence
from typing import Any, Final, Protocol, cast
from urllib.parse import urlsplit

import anyio
import anyio.abc
from anyio.streams.stapled import MultiListener

from tfbus.codecs.ros1 import TF_TYPE
from tfbus.errors import BadReply, CallFailed, TransportError

__all__ = [
    "MAX_XMLRPC_BYTES",
    "MAX_XMLRPC_DEPTH",
    "SLAVE_REQUEST_TIMEOUT",
    "BadReply",
    "CallFailed",
    "SlaveNode",
    "SlaveServer",
    "call",
    "loads",
    "serve_listener",
]

_log = logging.getLogger("tfbus.transports.ros1")

MAX_XMLRPC_BYTES: Final = 1024 * 1024
"""Largest XML-RPC body read, in bytes: an answer to a call, or a request to the slave
API (larger ones are refused unread). 1 MiB holds a ``publisherUpdate`` or
``registerSubscriber`` answer listing ~15 000 publisher URIs; the requests and answers
ROS 1 nodes exchange are a few hundred bytes."""
MAX_XMLRPC_DEPTH: Final = 64
"""Deepest XML element nesting accepted in an XML-RPC body (ROS's deepest value,
``getSystemState``'s, nests ~20 elements)."""
SLAVE_REQUEST_TIMEOUT: Final = 5.0
"""Seconds a connection to the slave API may take to deliver its whole request."""
_MAX_HTTP_HEAD: Final = 16 * 1024


class _BoundedUnmarshaller(xmlrpc.client.Unmarshaller):
    """The standard unmarshaller, refusing nesting deeper than ``max_depth`` elements
    (it keeps its own stack, but a deep value breaks ``repr`` and comparisons later)."""

    def __init__(self, max_depth: int) -> None:
        super().__init__()
        self._depth = 0
        self._max_depth = max_depth

    def start(self, tag: str, attrs: dict[str, str]) -> None:
        self._depth += 1
        if self._depth > self._max_depth:
            raise ValueError(f"elements nested deeper than {self._max_depth}")
        super().start(tag, attrs)

    def end(self, tag: str) -> None:
        self._depth -= 1
        super().end(tag)


def loads(body: bytes, *, max_depth: int = MAX_XMLRPC_DEPTH) -> tuple[tuple[Any, ...], str | None]:
    """Parse an XML-RPC request or response body: ``(params, method name or None)``.

    Raises:
        xmlrpc.client.Fault: the body is a fault response.
        BadReply: anything else that is not XML-RPC (not XML, nested deeper than
            ``max_depth``, a value that does not parse), with the parser's reason.
    """
    unmarshaller = _BoundedUnmarshaller(max_depth)
    parser = xmlrpc.client.ExpatParser(unmarshaller)
    try:
        parser.feed(body)
        parser.close()
        params = unmarshaller.close()
    except xmlrpc.client.Fault:
        raise
    except Exception as exc:  # ExpatError, ResponseError, ValueError, IndexError, ...
        raise BadReply(f"not XML-RPC: {type(exc).__name__}: {exc}"[:300]) from None
    return tuple(params), unmarshaller.getmethodname()


def _endpoint(uri: str) -> tuple[str, int, str]:
    try:
        parts = urlsplit(uri)
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise BadReply(f"bad XML-RPC URI {uri!r:.200}: {exc}") from None
    if parts.scheme != "http" or not host or port is None:
        raise BadReply(f"bad XML-RPC URI {uri!r:.200}: not http://host:port/")
    return host, port, parts.path or "/"


async def _read_head(
    stream: anyio.abc.ByteReceiveStream, what: str
) -> tuple[bytes, dict[str, str], bytes]:
    """(first line, headers lower-cased, bytes after the blank line) of an HTTP message."""
    buf = bytearray()
    while (end := buf.find(b"\r\n\r\n")) < 0:
        if len(buf) > _MAX_HTTP_HEAD:
            raise BadReply(f"{what}: HTTP head over {_MAX_HTTP_HEAD} bytes")
        try:
            buf += await stream.receive()
        except anyio.EndOfStream:
            raise BadReply(
                f"{what}: connection closed before the HTTP head ({len(buf)} bytes)"
            ) from None
    lines = bytes(buf[:end]).split(b"\r\n")
    headers = {}
    for line in lines[1:]:
        key, sep, value = line.partition(b":")
        if sep:
            headers[key.strip().lower().decode("latin-1")] = value.strip().decode("latin-1")
    return lines[0], headers, bytes(buf[end + 4 :])


def _content_length(headers: dict[str, str], what: str) -> int | None:
    raw = headers.get("content-length")
    if raw is None:
        return None
    # ASCII digits only: str.isdigit is also true for '²', '³', '¹' (latin-1), which
    # int() refuses
    if not (raw.isascii() and raw.isdigit()) or len(raw) > 18:
        raise BadReply(f"{what}: bad Content-Length {raw[:40]!r}")
    return int(raw)


async def _read_body(
    stream: anyio.abc.ByteReceiveStream, first: bytes, length: int | None, limit: int, what: str
) -> bytes:
    if length is not None and length > limit:
        raise BadReply(f"{what}: body of {length} bytes exceeds the limit of {limit}")
    body = bytearray(first)
    while length is None or len(body) < length:
        if len(body) > limit:
            raise BadReply(f"{what}: body exceeds the limit of {limit} bytes")
        try:
            body += await stream.receive()
        except anyio.EndOfStream:
            if length is not None:
                raise BadReply(
                    f"{what}: connection closed after {len(body)} of {length} body bytes"
                ) from None
            break
    if len(body) > limit:
        raise BadReply(f"{what}: body exceeds the limit of {limit} bytes")
    return bytes(body[:length] if length is not None else body)


async def call(
    uri: str, method: str, *args: object, timeout: float, limit: int = MAX_XMLRPC_BYTES
) -> Any:
    """One XML-RPC call returning ROS's ``[code, statusMessage, value]`` value, within
    ``timeout`` seconds in all (connect, send, receive), reading at most ``limit`` bytes
    of answer body (HTTP/1.0 ``POST``, as ``xmlrpc.client`` sends it).

    Raises:
        BadReply: the peer answered, but not ROS XML-RPC (not HTTP 200, not XML, nested
            too deep, over ``limit``, a fault, the wrong shape).
        CallFailed: a ROS answer with a code other than 1.
        TransportError: the peer is unreachable or did not answer within ``timeout``.
    """
    what = f"{method} at {uri:.200}"
    host, port, path = _endpoint(uri)
    body = xmlrpc.client.dumps(cast("tuple[Any, ...]", args), method, allow_none=True).encode()
    request = (
        f"POST {path} HTTP/1.0\r\nHost: {host}:{port}\r\nUser-Agent: tfbus\r\n"
        f"Content-Type: text/xml\r\nContent-Length: {len(body)}\r\n\r\n"
    ).encode() + body
    try:
        with anyio.fail_after(timeout):
            stream = await anyio.connect_tcp(host, port)
            async with stream:
                await stream.send(request)
                status, headers, rest = await _read_head(stream, what)
                parts = status.split(None, 2)
                if len(parts) < 2 or not parts[0].startswith(b"HTTP/") or parts[1] != b"200":
                    raise BadReply(
                        f"{what}: answered {status[:80].decode('latin-1')!r}, "
                        "not an XML-RPC 200 (is this a ROS node or master?)"
                    )
                raw = await _read_body(stream, rest, _content_length(headers, what), limit, what)
    except TimeoutError:
        raise TransportError(f"{what}: no whole answer within {timeout} s") from None
    except (OSError, anyio.BrokenResourceError, ValueError) as exc:
        raise TransportError(f"{what}: {exc}") from exc
    try:
        params, _ = loads(raw)
    except xmlrpc.client.Fault as exc:
        raise BadReply(f"{what}: fault {exc.faultCode}: {exc.faultString!s:.200}") from None
    except BadReply as exc:
        raise BadReply(f"{what}: {exc} (is this a ROS node or master?)") from None
    reply = params[0] if len(params) == 1 else None
    if not (isinstance(reply, list) and len(reply) == 3):
        raise BadReply(f"{what}: malformed reply {params!r:.200}")
    code, status_message, value = reply
    if not isinstance(code, int) or isinstance(code, bool):
        raise BadReply(f"{what}: code {code!r:.40} is not an int")
    if code != 1:
        raise CallFailed(f"{what}: code {code}: {status_message!r:.200}", code)
    return value


async def serve_listener(
    listener: MultiListener[anyio.abc.SocketStream],
    handler: Callable[[anyio.abc.SocketStream], Coroutine[Any, Any, None]],
    what: str,
    on_accept_error: Callable[[OSError], None] | None = None,
) -> None:
    """Accept connections forever (on each socket of ``listener``, as made by
    :func:`anyio.create_tcp_listener`) and run ``handler`` on each in its own task.

    An ``accept`` that fails with an :class:`OSError` (``EMFILE``/``ENFILE``: out of
    file descriptors, ``ENOBUFS``, ``ENOMEM``, a peer that left first) is logged (at most
    once a second), reported to ``on_accept_error``, and retried after a back-off of 10
    ms doubling to 0.5 s, as roscpp's ``TransportTCP::accept`` and trio's
    ``serve_listeners`` do; the listener keeps serving. Closing the listener ends it.
    """
    async with anyio.create_task_group() as tg:
        for sub in listener.listeners:
            tg.start_soon(
                _accept_loop, cast("anyio.abc.SocketListener", sub), handler, what, on_accept_error
            )


async def _accept_loop(
    listener: anyio.abc.SocketListener,
    handler: Callable[[anyio.abc.SocketStream], Coroutine[Any, Any, None]],
    what: str,
    on_accept_error: Callable[[OSError], None] | None,
) -> None:
    delay = 0.01
    last_log = -1.0
    async with anyio.create_task_group() as tg:
        while True:
            try:
                stream = await listener.accept()
            except (OSError, anyio.BrokenResourceError) as raised:
                # trio's listener wraps the OSError in BrokenResourceError
                exc = raised if isinstance(raised, OSError) else raised.__cause__
                if not isinstance(exc, OSError):
                    raise
                if on_accept_error is not None:
                    on_accept_error(exc)
                now = time.monotonic()
                if last_log < 0 or now - last_log >= 1.0:
                    last_log = now
                    _log.warning("ros1: %s cannot accept (%s); backing off", what, exc)
                await anyio.sleep(delay)
                delay = min(delay * 2, 0.5)
                continue
            delay = 0.01
            tg.start_soon(handler, stream)


class SlaveNode(Protocol):
    """What the slave API asks of the node it serves (each called in the event loop)."""

    @property
    def master_uri(self) -> str: ...

    def bus_info(self) -> list[list[Any]]: ...

    def subscriptions(self) -> Sequence[str]: ...

    def topic_type(self, topic: str) -> str: ...

    def publications(self) -> Sequence[str]: ...

    def tcpros_endpoint(self, topic: str) -> tuple[str, int] | None: ...

    def on_publisher_update(self, topic: str, publishers: list[str]) -> None: ...

    def on_shutdown(self, caller_id: str, message: str) -> None: ...

    def on_bad_request(self, reason: str) -> None: ...


class SlaveServer:
    """The slave API of one node, served on anyio sockets by :meth:`handle` (one request
    per connection, HTTP/1.0; ``xmlrpc.client`` and roscpp's XmlRpc++ reconnect for the
    next). Answers are ROS's ``[code, status, value]``.

    A request must arrive whole within ``request_timeout`` seconds and its body may not
    exceed ``max_body`` bytes (answered ``413`` unread); a body that is not XML-RPC, an
    unknown method or wrong arguments get an XML-RPC fault. Each such request is reported
    to the node's ``on_bad_request``; no request affects another connection.
    """

    def __init__(
        self,
        node: SlaveNode,
        *,
        max_body: int = MAX_XMLRPC_BYTES,
        request_timeout: float = SLAVE_REQUEST_TIMEOUT,
    ) -> None:
        self._node = node
        self._max_body = max_body
        self._timeout = request_timeout
        self._methods: dict[str, Callable[..., list[object]]] = {
            name: getattr(self, name)
            for name in (
                "getBusStats",
                "getBusInfo",
                "getMasterUri",
                "shutdown",
                "getPid",
                "getSubscriptions",
                "getPublications",
                "paramUpdate",
                "publisherUpdate",
                "requestTopic",
            )
        }

    async def handle(self, stream: anyio.abc.SocketStream) -> None:
        """Serve one connection: read one request (bounded in time and size), answer it,
        close. Never raises for anything the peer does."""
        async with stream:
            try:
                with anyio.fail_after(self._timeout):
                    answer = await self._answer(stream)
                    await stream.send(answer)
            except (BadReply, ValueError) as exc:  # ValueError: a request parse we missed
                self._node.on_bad_request(str(exc))
                with contextlib.suppress(Exception), anyio.move_on_after(0.2):
                    await stream.send(_http(400, b"bad request\n", "text/plain"))
            except TimeoutError:
                self._node.on_bad_request(f"no whole request within {self._timeout} s")
            except (OSError, anyio.BrokenResourceError, anyio.ClosedResourceError):
                pass

    async def _answer(self, stream: anyio.abc.SocketStream) -> bytes:
        what = "slave API request"
        line, headers, rest = await _read_head(stream, what)
        if not line.startswith(b"POST "):
            raise BadReply(f"{what}: {line[:40].decode('latin-1')!r} is not a POST")
        length = _content_length(headers, what)
        if length is None:
            raise BadReply(f"{what}: no Content-Length")
        if length > self._max_body:
            self._node.on_bad_request(
                f"{what}: body of {length} bytes exceeds the limit of {self._max_body}"
            )
            return _http(413, b"request body too large\n", "text/plain")
        body = await _read_body(stream, rest, length, self._max_body, what)
        try:
            params, method = loads(body)
        except xmlrpc.client.Fault as exc:
            raise BadReply(f"{what}: a fault is not a request") from exc
        function = self._methods.get(method or "")
        if function is None:
            self._node.on_bad_request(f"{what}: unknown method {method!r:.80}")
            result: Any = xmlrpc.client.Fault(1, f"unknown method {method!r:.80}")
        else:
            try:
                result = (function(*params),)
            except (TypeError, ValueError) as exc:  # wrong argument count or type
                self._node.on_bad_request(f"{what}: {method}: {exc}")
                result = xmlrpc.client.Fault(1, f"{method}: {exc}"[:200])
        return _http(
            200, xmlrpc.client.dumps(result, methodresponse=True, allow_none=True).encode()
        )

    # The ROS slave API, by its names (ROS wiki "ROS/Slave_API").

    def getBusStats(self, caller_id: str) -> list[object]:
        """Empty statistics (publish, subscribe, service)."""
        return [1, "", [[], [], []]]

    def getBusInfo(self, caller_id: str) -> list[object]:
        """One entry per TCPROS connection."""
        return [1, "", self._node.bus_info()]

    def getMasterUri(self, caller_id: str) -> list[object]:
        """The master this node uses."""
        return [1, "", self._node.master_uri]

    def shutdown(self, caller_id: str, msg: str = "") -> list[object]:
        """Another node took this name, or a tool asked: stop the node."""
        self._node.on_shutdown(str(caller_id)[:200], str(msg)[:200])
        return [1, "", 0]

    def getPid(self, caller_id: str) -> list[object]:
        """This process id."""
        return [1, "", os.getpid()]

    def getSubscriptions(self, caller_id: str) -> list[object]:
        """[[topic, type], ...] subscribed."""
        return [1, "", [[t, self._node.topic_type(t)] for t in self._node.subscriptions()]]

    def getPublications(self, caller_id: str) -> list[object]:
        """[[topic, type], ...] published."""
        return [1, "", [[t, TF_TYPE] for t in self._node.publications()]]

    def paramUpdate(self, caller_id: str, key: str, value: object) -> list[object]:
        """Accepted and ignored (this node has no parameters)."""
        return [1, "", 0]

    def publisherUpdate(self, caller_id: str, topic: str, publishers: list[str]) -> list[object]:
        """The master's new list of publishers of ``topic`` (strings only; the node
        bounds how many it follows)."""
        if not isinstance(topic, str) or not isinstance(publishers, list):
            return [-1, "publisherUpdate(caller_id, topic: str, publishers: list)", 0]
        self._node.on_publisher_update(topic, [p for p in publishers if isinstance(p, str)])
        return [1, "", 0]

    def requestTopic(self, caller_id: str, topic: str, protocols: list[Any]) -> list[object]:
        """Where to connect for ``topic``: ``["TCPROS", host, port]``."""
        if not isinstance(topic, str):
            return [-1, "requestTopic(caller_id, topic: str, protocols: list)", []]
        endpoint = self._node.tcpros_endpoint(topic)
        if endpoint is None:
            return [-1, f"not a publisher of {topic:.200}", []]
        for proto in protocols if isinstance(protocols, list) else ():
            if isinstance(proto, list) and proto and proto[0] == "TCPROS":
                return [1, "ready", ["TCPROS", endpoint[0], endpoint[1]]]
        return [0, "no supported protocol (TCPROS only)", []]


def _http(code: int, body: bytes, content_type: str = "text/xml") -> bytes:
    reason = {200: "OK", 400: "Bad Request", 413: "Payload Too Large"}[code]
    return (
        f"HTTP/1.0 {code} {reason}\r\nServer: tfbus\r\nContent-Type: {content_type}\r\n"
        f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
    ).encode() + body
