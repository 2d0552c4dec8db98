"""Hostile ROS 1 peers for the tests and ``benchmarks/soak_ros1.py``, all on 127.0.0.1 (a
free port each): a minimal but real ROS master (:class:`FakeMaster`, whose answers can be
replaced by raw bytes) and XML-RPC servers that answer junk, trickle or never answer
(:class:`HostilePeer`).

Each serves from daemon threads; every wait in them is bounded (``stop`` ends them).
Addresses outside loopback appear only as data a node must refuse. Standard library only
(no pytest), like ``ros1_peers``.
"""

from __future__ import annotations

import contextlib
import http.client
import socket
import threading
import time
import xmlrpc.client
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import urlsplit

_MAX_WAIT = 60.0  # no hostile behaviour lasts longer than this


def xmlrpc_call(uri: str, method: str, *args: Any, timeout: float = 5.0) -> Any:
    """One XML-RPC call with a socket timeout (the stdlib's proxy has none)."""
    parts = urlsplit(uri)
    assert parts.hostname == "127.0.0.1", uri
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=timeout)
    try:
        body = xmlrpc.client.dumps(args, method, allow_none=True).encode()
        conn.request("POST", parts.path or "/", body, {"Content-Type": "text/xml"})
        resp = conn.getresponse()
        data = resp.read()
        if resp.status != 200:
            raise OSError(f"HTTP {resp.status}")
        return xmlrpc.client.loads(data)[0][0]
    finally:
        conn.close()


def http_answer(body: bytes, *, length: bool = True, status: str = "200 OK") -> bytes:
    """A raw HTTP/1.0 answer carrying ``body``."""
    head = f"HTTP/1.0 {status}\r\nContent-Type: text/xml\r\n"
    if length:
        head += f"Content-Length: {len(body)}\r\n"
    return head.encode() + b"\r\n" + body


def deep_array(depth: int) -> bytes:
    """An XML-RPC response whose value is ``depth`` nested arrays."""
    return (
        b"<?xml version='1.0'?><methodResponse><params><param><value>"
        + b"<array><data><value>" * depth
        + b"<int>1</int>"
        + b"</value></data></array>" * depth
        + b"</value></param></params></methodResponse>"
    )


def tcpros_answer(port_xml: str) -> bytes:
    """A requestTopic answer ``[1, "", ["TCPROS", "127.0.0.1", <port_xml>]]``."""
    return (
        "<?xml version='1.0'?><methodResponse><params><param><value><array><data>"
        "<value><int>1</int></value><value><string></string></value>"
        "<value><array><data><value><string>TCPROS</string></value>"
        f"<value><string>127.0.0.1</string></value><value>{port_xml}</value>"
        "</data></array></value></data></array></value></param></params></methodResponse>"
    ).encode()


def _read_request(handler: BaseHTTPRequestHandler) -> tuple[str | None, bytes]:
    length = int(handler.headers.get("Content-Length", "0") or 0)
    body = handler.rfile.read(min(length, 4 << 20))
    try:
        _, method = xmlrpc.client.loads(body)
    except Exception:
        method = None
    return method, body


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True


class _Base:
    def __init__(self, handler: type[BaseHTTPRequestHandler]) -> None:
        self.server = _Server(("127.0.0.1", 0), handler)
        self.server.owner = self  # type: ignore[attr-defined]
        self.port = int(self.server.server_address[1])
        self.uri = f"http://127.0.0.1:{self.port}/"
        self.stop = threading.Event()
        self._thread = threading.Thread(
            target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
        )

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self.stop.set()
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> Any:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _MasterHandler(BaseHTTPRequestHandler):
    def log_message(self, format: str, *args: Any) -> None:
        pass

    def do_POST(self) -> None:
        master: FakeMaster = self.server.owner  # type: ignore[attr-defined]
        method, body = _read_request(self)
        master.calls.append(method or "?")
        raw = master.raw.get(method or "")
        if raw is not None:
            self.wfile.write(raw)
            return
        params = xmlrpc.client.loads(body)[0]
        result = master.dispatch(method or "", params)
        data = xmlrpc.client.dumps((result,), methodresponse=True, allow_none=True).encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/xml")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)


class FakeMaster(_Base):
    """A ROS master (ROS wiki "ROS/Master_API": register*/unregister*, lookupNode) that
    notifies subscribers with ``publisherUpdate``, as rosmaster does.

    ``extra_publishers`` are listed first to every subscriber of /tf (hostile URIs);
    ``raw[method]`` replaces that method's whole HTTP answer by raw bytes.
    """

    def __init__(self) -> None:
        super().__init__(_MasterHandler)
        self.lock = threading.Lock()
        self.pubs: dict[str, dict[str, str]] = {}
        self.subs: dict[str, dict[str, str]] = {}
        self.nodes: dict[str, str] = {}
        self.extra_publishers: list[str] = []
        self.raw: dict[str, bytes] = {}
        self.calls: list[str] = []

    def publishers(self, topic: str) -> list[str]:
        extra = self.extra_publishers if topic == "/tf" else []
        return [*extra, *self.pubs.get(topic, {}).values()]

    def dispatch(self, method: str, p: tuple[Any, ...]) -> list[Any]:
        with self.lock:
            if method == "registerPublisher":
                caller, topic, _type, uri = p
                self.nodes[caller] = uri
                self.pubs.setdefault(topic, {})[caller] = uri
                self._notify(topic)
                return [1, "", list(self.subs.get(topic, {}).values())]
            if method == "registerSubscriber":
                caller, topic, _type, uri = p
                self.nodes[caller] = uri
                self.subs.setdefault(topic, {})[caller] = uri
                return [1, "", self.publishers(topic)]
            if method in ("unregisterPublisher", "unregisterSubscriber"):
                caller, topic, _uri = p
                table = self.pubs if method == "unregisterPublisher" else self.subs
                table.get(topic, {}).pop(caller, None)
                if method == "unregisterPublisher":
                    self._notify(topic)
                return [1, "", 1]
            if method == "lookupNode":
                uri = self.nodes.get(p[1])
                return [1, "", uri] if uri else [-1, "unknown node", ""]
            return [-1, f"unsupported {method}", 0]

    def _notify(self, topic: str) -> None:
        publishers = self.publishers(topic)
        for uri in list(self.subs.get(topic, {}).values()):
            threading.Thread(
                target=self._update, args=(uri, topic, publishers), daemon=True
            ).start()

    @staticmethod
    def _update(uri: str, topic: str, publishers: list[str]) -> None:
        with contextlib.suppress(OSError, xmlrpc.client.Error):
            xmlrpc_call(uri, "publisherUpdate", "/master", topic, publishers, timeout=5.0)

    def announce(self, topic: str = "/tf") -> None:
        """Send every subscriber of ``topic`` the current list (``publisherUpdate``)."""
        with self.lock:
            self._notify(topic)


class _PeerHandler(BaseHTTPRequestHandler):
    def log_message(self, format: str, *args: Any) -> None:
        pass

    def do_POST(self) -> None:
        peer: HostilePeer = self.server.owner  # type: ignore[attr-defined]
        _read_request(self)
        peer.requests += 1
        peer.behave(self.path, self.connection, peer.stop)


class HostilePeer(_Base):
    """An XML-RPC server (a would-be publisher's slave API) whose every answer is made by
    ``behave(path, socket, stop)``: raw bytes, a trickle, or silence."""

    def __init__(self, behave: Callable[[str, socket.socket, threading.Event], None]) -> None:
        super().__init__(_PeerHandler)
        self.behave = behave
        self.requests = 0

    def uris(self, n: int) -> list[str]:
        """``n`` distinct publisher URIs, all served here."""
        return [f"{self.uri}p{i}" for i in range(n)]


def send_raw(data: bytes) -> Callable[[str, socket.socket, threading.Event], None]:
    """Answer every request with ``data`` (then close)."""

    def behave(path: str, sock: socket.socket, stop: threading.Event) -> None:
        with contextlib.suppress(OSError):
            sock.sendall(data)

    return behave


def trickle(data: bytes, period: float) -> Callable[[str, socket.socket, threading.Event], None]:
    """Send ``data`` one byte per ``period`` s, until the peer leaves or ``stop``."""

    def behave(path: str, sock: socket.socket, stop: threading.Event) -> None:
        deadline = time.monotonic() + _MAX_WAIT
        for i in range(len(data)):
            if stop.wait(period) or time.monotonic() > deadline:
                return
            try:
                sock.sendall(data[i : i + 1])
            except OSError:
                return

    return behave
