"""ROS 1's XML-RPC side: calls to the master and to other nodes, and the slave API this
node serves (ROS wiki "ROS/Master_API", "ROS/Slave_API"), with the standard library's
:mod:`xmlrpc`."""

from __future__ import annotations

import logging
import os
import threading
import xmlrpc.client
from collections.abc import Sequence
from typing import Any, Protocol
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from tfbus.errors import TransportError

from .tcpros import TF_TYPE

__all__ = ["SlaveNode", "SlaveServer", "call"]

_log = logging.getLogger("tfbus.transports.ros1")


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float) -> None:
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host: Any) -> Any:
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def call(uri: str, method: str, *args: object, timeout: float) -> Any:
    """One XML-RPC call returning ROS's ``[code, statusMessage, value]`` value.

    Raises:
        TransportError: the peer is unreachable, answers junk, or returns code != 1.
    """
    proxy = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout), allow_none=True)
    try:
        reply = getattr(proxy, method)(*args)
    except (OSError, xmlrpc.client.Error, ValueError) as exc:
        raise TransportError(f"{method} at {uri}: {exc}") from exc
    if not (isinstance(reply, list) and len(reply) == 3):
        raise TransportError(f"{method} at {uri}: malformed reply {reply!r:.200}")
    code, status, value = reply
    if code != 1:
        raise TransportError(f"{method} at {uri}: {status}")
    return value


class _SlaveHandler(SimpleXMLRPCRequestHandler):
    rpc_paths = ("/", "/RPC2")

    def log_message(self, format: str, *args: Any) -> None:
        _log.debug("slave api: " + format, *args)


class _Server(SimpleXMLRPCServer):
    daemon_threads = True
    allow_reuse_address = True


class SlaveNode(Protocol):
    """What the slave API asks of the node it serves (each called from a server thread,
    so each must be thread-safe: read snapshots, hand work to the event loop)."""

    @property
    def master_uri(self) -> str: ...

    def bus_info(self) -> list[list[Any]]: ...

    def subscriptions(self) -> Sequence[str]: ...

    def publications(self) -> Sequence[str]: ...

    def tcpros_endpoint(self, topic: str) -> tuple[str, int] | None: ...

    def on_publisher_update(self, topic: str, publishers: list[str]) -> None: ...

    def on_shutdown(self, caller_id: str, message: str) -> None: ...


class SlaveServer:
    """The slave API of one node, served by :class:`xmlrpc.server.SimpleXMLRPCServer` in a
    thread on ``host`` (an ephemeral port). Answers are ROS's ``[code, status, value]``.

    Raises:
        TransportError: the server cannot bind ``host``.
    """

    def __init__(self, host: str, node: SlaveNode) -> None:
        try:
            self._server = _Server(
                (host, 0), requestHandler=_SlaveHandler, logRequests=False, allow_none=True
            )
        except OSError as exc:
            raise TransportError(f"cannot serve the slave API on {host}: {exc}") from exc
        self._node = node
        self.uri = f"http://{host}:{self._server.server_address[1]}/"
        """This node's slave API URI, as registered with the master."""
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
        ):
            self._server.register_function(getattr(self, name), name)
        self._thread = threading.Thread(
            target=self._server.serve_forever,
            kwargs={"poll_interval": 0.05},
            name=f"ros1-slave-api-{self.uri}",
            daemon=True,
        )

    def start(self) -> None:
        """Serve in a daemon thread."""
        self._thread.start()

    def close(self) -> None:
        """Stop serving and close the socket (blocks up to the server's poll interval)."""
        if self._thread.is_alive():
            self._server.shutdown()
            self._thread.join(timeout=1.0)
        self._server.server_close()

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
        self._node.on_shutdown(str(caller_id), str(msg))
        return [1, "", 0]

    def getPid(self, caller_id: str) -> list[object]:
        """This process id."""
        return [1, "", os.getpid()]

    def getSubscriptions(self, caller_id: str) -> list[object]:
        """[[topic, type], ...] subscribed."""
        return [1, "", [[t, TF_TYPE] for t in self._node.subscriptions()]]

    def getPublications(self, caller_id: str) -> list[object]:
        """[[topic, type], ...] published."""
        return [1, "", [[t, TF_TYPE] for t in self._node.publications()]]

    def paramUpdate(self, caller_id: str, key: str, value: object) -> list[object]:
        """Accepted and ignored (this node has no parameters)."""
        return [1, "", 0]

    def publisherUpdate(self, caller_id: str, topic: str, publishers: list[str]) -> list[object]:
        """The master's new list of publishers of ``topic``."""
        if isinstance(publishers, list):
            self._node.on_publisher_update(str(topic), [str(p) for p in publishers])
        return [1, "", 0]

    def requestTopic(self, caller_id: str, topic: str, protocols: list[Any]) -> list[object]:
        """Where to connect for ``topic``: ``["TCPROS", host, port]``."""
        endpoint = self._node.tcpros_endpoint(str(topic))
        if endpoint is None:
            return [-1, f"not a publisher of {topic}", []]
        for proto in protocols if isinstance(protocols, list) else ():
            if isinstance(proto, list) and proto and proto[0] == "TCPROS":
                return [1, "ready", ["TCPROS", endpoint[0], endpoint[1]]]
        return [0, "no supported protocol (TCPROS only)", []]
