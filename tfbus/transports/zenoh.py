"""Carry a :class:`~tfbus.bus.Bus` across processes and machines over Zenoh.

::

    from tfbus.bus import Bus
    from tfbus.transports.zenoh import ZenohTransport

    async with Bus(transport=ZenohTransport()) as bus:   # one machine, no configuration
        ...

Every local publish goes to the other processes on the same *prefix/namespace*; their
publishes are delivered to this bus's subscribers as if published here. In-process
subscribers work exactly as without a transport.

Key expressions (``base`` is ``prefix`` or ``prefix/namespace``)::

    {base}/{topic}                        data: "/tf" -> "tfbus/tf", "/a/b" -> "tfbus/a/b"
    {base}/@latch/{node_id}/{topic}       queryable: the node's latched topics (/tf_static)
    {base}/@alive/{node_id}/{name}        liveliness token of every running transport
    {base}/@alive/{node_id}/{name}/{topic}  ... and one per topic it has published

Topic chunks are percent-encoded where Zenoh would not accept them (``*$#?@%``, spaces,
non-ASCII, empty chunks), so any topic name maps to a valid key and back.

Networking defaults (no arguments): mode ``peer``, **multicast scouting off**, listen on
``tcp/127.0.0.1:7448`` (the rendezvous port, :data:`DEFAULT_PORT`) and connect to it. The
first tfbus process on the machine takes the port; later ones listen on an ephemeral
127.0.0.1 port, connect to the first and learn about each other through Zenoh's gossip,
so every process reaches every other one and the mesh survives the first one exiting.
Nothing leaves 127.0.0.1.

Multi-host: pass ``listen=["tcp/0.0.0.0:7448"]`` on one host and
``connect=["tcp/<that host>:7448"]`` on the others, or a Zenoh JSON5 configuration
file (``config="zenoh.json5"``) -- then the file rules (the defaults above are not
applied; explicit ``connect=``/``listen=`` still override it). TLS (``tls/...`` endpoints
plus ``transport/link/tls`` certificates) and access control (``access_control``) are
plain Zenoh configuration: see ``docs/zenoh.md``.

Threads: Zenoh calls back on its own threads. The callbacks only append
``(kind, key, bytes)`` to a bounded deque and, if no wake-up is pending, write one byte to
a socket pair; the event loop waits on that socket (``anyio.wait_readable``, which works
on asyncio and trio), then decodes and delivers everything queued -- one wake-up per
batch, never a blocked Zenoh thread, and per-publisher order kept (one FIFO). When the
deque is full (``max_pending``), the oldest entries are dropped and counted.

Late joiners: each transport serves the latched topics it has *itself* published
(``/tf_static`` merged per child frame) on a queryable; when a node appears (liveliness),
the others query it, so a listener started after a static broadcaster -- or a broadcaster
whose first publish raced the connection -- still gets its static transforms.

Liveliness: :meth:`ZenohTransport.alive` lists the other live nodes and the topics they
publish; joins and leaves (including a SIGKILLed process: its TCP link closes and Zenoh
drops its tokens) are also delivered on the bus as :class:`PeerEvent` on
:data:`PEERS_TOPIC`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import sys
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple, Protocol
from urllib.parse import parse_qsl, quote, unquote

import anyio
import anyio.abc
import anyio.lowlevel
import zenoh

from tfbus.messages import TFMessage, TransformStamped
from tfbus.transports.wire import (
    WireCodec,
    WireEncodeError,
    WireLimitError,
    WireLimits,
    WireVersionError,
    new_sender_id,
)

if TYPE_CHECKING:
    from tfbus.bus import Bus

__all__ = [
    "DEFAULT_PORT",
    "DEFAULT_PREFIX",
    "PEERS_TOPIC",
    "PeerEvent",
    "PeerInfo",
    "ZenohOptions",
    "ZenohStatistics",
    "ZenohTransport",
    "parse_bus_spec",
    "zenoh_bus_from_options",
    "zenoh_config",
]

log = logging.getLogger("tfbus.transports.zenoh")

DEFAULT_PORT: Final = 7448
"""The local rendezvous port of the no-configuration defaults (``tcp/127.0.0.1:7448``)."""
DEFAULT_PREFIX: Final = "tfbus"
"""The default first part of every key expression."""
PEERS_TOPIC: Final = "/tfbus/peers"
"""Local bus topic on which the transport delivers :class:`PeerEvent` (never sent out)."""

_LATCHED_DEFAULT: Final = ("/tf_static",)
_SAMPLE: Final = 0
_REPLY: Final = 1
_ALIVE_PUT: Final = 2
_ALIVE_DEL: Final = 3
_KEY_SAFE: Final = "-_.~+=,:!"  # besides ASCII letters and digits


class _BusLike(Protocol):
    def deliver_nowait(self, topic: str, message: object) -> None: ...
    def deliver_many_nowait(self, topic: str, messages: Iterable[object]) -> None: ...


class PeerEvent(NamedTuple):
    """A remote node or one of its published topics appeared or disappeared.

    Attributes:
        alive: True when it appeared, False when it went away (closed or died).
        node_id: the remote Zenoh session id (hex), unique per process run.
        name: the node's name (``ZenohTransport(name=...)``, default ``prog-pid``).
        topic: the topic the remote started/stopped publishing, or ``""`` for the node.
    """

    alive: bool
    node_id: str
    name: str
    topic: str = ""


@dataclass(frozen=True, slots=True)
class PeerInfo:
    """A live remote node (:meth:`ZenohTransport.alive`).

    Attributes:
        node_id: the remote Zenoh session id (hex).
        name: its name.
        topics: the topics it has published so far (a broadcaster has ``/tf`` and/or
            ``/tf_static``).
    """

    node_id: str
    name: str
    topics: frozenset[str] = frozenset()

    @property
    def is_broadcaster(self) -> bool:
        """True if it has published ``/tf`` or ``/tf_static``."""
        return bool(self.topics & {"/tf", "/tf_static"})


@dataclass(slots=True)
class ZenohStatistics:
    """Counters of one :class:`ZenohTransport` (:meth:`ZenohTransport.statistics`).

    Attributes:
        sent: messages put on the network.
        send_errors: local messages that could not be sent (not encodable, Zenoh error).
        not_connected: local messages published while the transport was not running.
        received: payloads received (samples and latched replies).
        delivered: messages delivered into the bus.
        latched_replies: of ``received``, those that answered a late-joiner query.
        malformed: payloads dropped because they were not well-formed tfbus messages.
        wrong_version: payloads dropped because of another wire format version.
        over_limit: payloads dropped because they broke a :class:`WireLimits` bound.
        overflow: entries dropped (oldest first) because the inbound queue was full.
        lost: gaps in publishers' sequence numbers (messages the network dropped).
        batches: event-loop wake-ups that delivered queued entries.
    """

    sent: int = 0
    send_errors: int = 0
    not_connected: int = 0
    received: int = 0
    delivered: int = 0
    latched_replies: int = 0
    malformed: int = 0
    wrong_version: int = 0
    over_limit: int = 0
    overflow: int = 0
    lost: int = 0
    batches: int = 0

    @property
    def dropped(self) -> int:
        """All inbound payloads dropped: malformed + wrong_version + over_limit + overflow."""
        return self.malformed + self.wrong_version + self.over_limit + self.overflow


# -- key expressions ------------------------------------------------------------------


def _encode_chunk(chunk: str) -> str:
    return quote(chunk, safe=_KEY_SAFE) if chunk else "%"


def _decode_chunk(chunk: str) -> str:
    return "" if chunk == "%" else unquote(chunk)


def _topic_key(topic: str) -> str:
    """``"/tf"`` -> ``"tf"``; ``"/a/b"`` -> ``"a/b"`` (chunks percent-encoded)."""
    return "/".join(_encode_chunk(c) for c in topic.removeprefix("/").split("/"))


def _key_topic(key: str) -> str:
    return "/" + "/".join(_decode_chunk(c) for c in key.split("/"))


def _check_base_chunk(what: str, value: str) -> None:
    for chunk in value.split("/"):
        if not chunk or any(c in chunk for c in "*$#?@% "):
            raise ValueError(
                f"{what} {value!r} must be '/'-separated non-empty chunks "
                "without '*', '$', '#', '?', '@', '%' or spaces"
            )


# -- configuration --------------------------------------------------------------------


def _endpoint_list(value: str | Sequence[str]) -> list[str]:
    return [value] if isinstance(value, str) else list(value)


def zenoh_config(
    *,
    connect: str | Sequence[str] | None = None,
    listen: str | Sequence[str] | None = None,
    config: str | os.PathLike[str] | Mapping[str, Any] | zenoh.Config | None = None,
    port: int = DEFAULT_PORT,
) -> tuple[zenoh.Config, zenoh.Config | None]:
    """Build the Zenoh configuration of a transport: ``(config, fallback)``.

    Without ``connect``, ``listen`` and ``config`` this is the one-machine default: peer
    mode, multicast scouting off, listen on and connect to ``tcp/127.0.0.1:{port}``;
    ``fallback`` (used when that port is taken by another tfbus process) listens on
    ``tcp/127.0.0.1:0`` instead. Otherwise ``fallback`` is None.

    Args:
        connect: Zenoh endpoints to connect to (``"tcp/10.0.0.2:7448"``); retried in the
            background until they answer.
        listen: endpoints to listen on (default with ``connect`` alone:
            ``tcp/127.0.0.1:0``).
        config: a Zenoh JSON5 file path, a ``zenoh.Config``, or a mapping of config
            paths to JSON values (``{"transport/link/tx/lease": 3000}``) applied on top
            of the defaults. With a file or ``zenoh.Config``, the tfbus defaults are not
            applied (only explicit ``connect``/``listen``).
        port: the rendezvous port of the default configuration.

    Raises:
        zenoh.ZError: if the file cannot be read or a value is rejected by Zenoh.
        ValueError: if an endpoint list is empty where one is required.
    """
    base_given = config is not None and not isinstance(config, Mapping)

    def build(listen_eps: list[str] | None, connect_eps: list[str] | None) -> zenoh.Config:
        if isinstance(config, zenoh.Config):
            cfg = zenoh.Config.from_json5(str(config))
        elif config is not None and not isinstance(config, Mapping):
            cfg = zenoh.Config.from_file(os.fspath(config))
        else:
            cfg = zenoh.Config()
        if not base_given:
            cfg.insert_json5("mode", '"peer"')
            cfg.insert_json5("scouting/multicast/enabled", "false")
            # Return from open() at once; links come up (and are retried) in background.
            cfg.insert_json5("open/return_conditions/connect_scouted", "false")
            cfg.insert_json5(
                "connect/retry",
                '{"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}',
            )
        if listen_eps is not None:
            cfg.insert_json5("listen/endpoints", json.dumps(listen_eps))
        if connect_eps is not None:
            cfg.insert_json5("connect/endpoints", json.dumps(connect_eps))
        if isinstance(config, Mapping):
            for key, value in config.items():
                cfg.insert_json5(key, json.dumps(value))
        return cfg

    if connect is None and listen is None and not base_given:
        hub = f"tcp/127.0.0.1:{port}"
        return build([hub], [hub]), build(["tcp/127.0.0.1:0"], [hub])
    listen_eps = _endpoint_list(listen) if listen is not None else None
    connect_eps = _endpoint_list(connect) if connect is not None else None
    if listen_eps is None and not base_given:
        listen_eps = ["tcp/127.0.0.1:0"]
    if connect_eps is None and not base_given:
        connect_eps = []
    return build(listen_eps, connect_eps), None


def _default_name() -> str:
    prog = Path(sys.argv[0]).stem if sys.argv and sys.argv[0] else "python"
    return f"{prog or 'python'}-{os.getpid()}"


# -- the transport --------------------------------------------------------------------


@dataclass(slots=True)
class _Outlet:
    topic: str
    key: str
    latched: bool
    seq: int = 0
    publisher: zenoh.Publisher | None = None
    token: zenoh.LivelinessToken | None = None
    statics: dict[str, TransformStamped] = field(default_factory=dict)
    latched_payload: bytes | None = None


class ZenohTransport:
    """A :class:`~tfbus.bus.Transport` over Zenoh (``Bus(transport=ZenohTransport())``).

    Args:
        connect: Zenoh endpoints to connect to, e.g. ``["tcp/192.168.1.10:7448"]``.
        listen: endpoints to listen on, e.g. ``["tcp/0.0.0.0:7448"]``.
        config: a Zenoh JSON5 config file path, a ``zenoh.Config`` or a mapping of config
            paths to values (see :func:`zenoh_config`).
        prefix: first key-expression chunk(s) (default ``"tfbus"``).
        namespace: optional chunk(s) after the prefix (``"robot1"``): buses only see
            buses with the same prefix and namespace.
        name: this node's name as others see it (default ``"<program>-<pid>"``).
        topics: the remote topics to receive (default: all under the namespace).
        latched_topics: topics whose last message (``TFMessage``: last transform per
            child frame) is served to late joiners (default ``("/tf_static",)``).
        limits: wire-format bounds applied to received payloads.
        max_pending: capacity of the inbound queue between Zenoh threads and the event
            loop, entries; when full the oldest are dropped and counted.
        max_batch: most entries delivered per event-loop turn before yielding.
        port: the rendezvous port of the no-configuration default.
        express: send each message at once instead of letting Zenoh batch small
            messages (lower latency under load, lower peak throughput).

    Raises:
        ValueError: if ``prefix`` / ``namespace`` / ``name`` are not valid.
    """

    def __init__(
        self,
        *,
        connect: str | Sequence[str] | None = None,
        listen: str | Sequence[str] | None = None,
        config: str | os.PathLike[str] | Mapping[str, Any] | zenoh.Config | None = None,
        prefix: str = DEFAULT_PREFIX,
        namespace: str = "",
        name: str | None = None,
        topics: Iterable[str] | None = None,
        latched_topics: Iterable[str] = _LATCHED_DEFAULT,
        limits: WireLimits | None = None,
        max_pending: int = 50_000,
        max_batch: int = 64,
        port: int = DEFAULT_PORT,
        express: bool = False,
    ) -> None:
        _check_base_chunk("prefix", prefix)
        if namespace:
            _check_base_chunk("namespace", namespace)
        if max_pending < 1 or max_batch < 1:
            raise ValueError("max_pending and max_batch must be at least 1")
        self._base = f"{prefix}/{namespace}" if namespace else prefix
        self._name = name if name is not None else _default_name()
        if not self._name:
            raise ValueError("name must not be empty")
        self._config, self._fallback = zenoh_config(
            connect=connect, listen=listen, config=config, port=port
        )
        self._topics = None if topics is None else tuple(topics)
        self._latched = frozenset(latched_topics)
        self._codec = WireCodec(limits)
        self._sender = new_sender_id()
        self._express = express
        self._max_pending = max_pending
        self._max_batch = max_batch
        self._stats = ZenohStatistics()
        self._outlets: dict[str, _Outlet] = {}
        self._topic_of_key: dict[str, str | None] = {}
        self._seqs: dict[tuple[int, str], int] = {}
        self._peers: dict[str, PeerInfo] = {}
        self._inbox: deque[tuple[int, str, bytes]] = deque(maxlen=max_pending)
        self._wake_pending = False
        self._wake_w: socket.socket | None = None
        self._wake_r: socket.socket | None = None
        self._session: zenoh.Session | None = None
        self._node_id = ""
        self._running = False
        self._warned: set[str] = set()

    # -- public information -----------------------------------------------------------

    @property
    def key_prefix(self) -> str:
        """The key-expression base: ``prefix`` or ``prefix/namespace``."""
        return self._base

    @property
    def name(self) -> str:
        """This node's name."""
        return self._name

    @property
    def node_id(self) -> str:
        """This node's Zenoh session id (hex) while running, else ``""``."""
        return self._node_id

    @property
    def running(self) -> bool:
        """True between ``run``'s ``started()`` and its end."""
        return self._running

    def alive(self) -> dict[str, PeerInfo]:
        """The other live nodes on this prefix/namespace, by node id (a snapshot).

        A node appears once Zenoh links to it and disappears when it closes, crashes or
        is killed (its link drops; a silent network partition is detected after Zenoh's
        lease, ``transport/link/tx/lease``, 10 s by default).
        """
        return dict(self._peers)

    def broadcasters(self) -> dict[str, PeerInfo]:
        """The live nodes that have published ``/tf`` or ``/tf_static``."""
        return {k: v for k, v in self._peers.items() if v.is_broadcaster}

    def statistics(self) -> ZenohStatistics:
        """A copy of the counters (see :class:`ZenohStatistics`)."""
        s = self._stats
        return ZenohStatistics(**{f: getattr(s, f) for f in ZenohStatistics.__slots__})

    def __repr__(self) -> str:
        state = "running" if self._running else "stopped"
        return (
            f"<ZenohTransport {state} base={self._base!r} name={self._name!r} "
            f"peers={len(self._peers)}>"
        )

    # -- Transport contract ------------------------------------------------------------

    async def run(
        self,
        bus: Bus | _BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Open the Zenoh session, report started, deliver remote messages until cancelled.

        Closes the session (undeclaring this node's liveliness tokens) on the way out.

        Raises:
            RuntimeError: if this transport is already running.
            zenoh.ZError: if the session cannot be opened (e.g. a listen endpoint is in
                use, a config file is invalid).
        """
        if self._running or self._session is not None:
            raise RuntimeError("this ZenohTransport is already running")
        session = await anyio.to_thread.run_sync(self._open_session)
        wake_r, wake_w = socket.socketpair()
        wake_r.setblocking(False)
        wake_w.setblocking(False)
        declared: list[Any] = []
        try:
            self._node_id = str(session.zid())
            self._session = session
            self._wake_w = wake_w
            self._wake_r = wake_r
            data_keys = (
                [f"{self._base}/**"]
                if self._topics is None
                else [f"{self._base}/{_topic_key(t)}" for t in self._topics]
            )
            for key in data_keys:
                declared.append(
                    session.declare_subscriber(
                        key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE
                    )
                )
            declared.append(
                session.declare_queryable(
                    f"{self._base}/@latch/{self._node_id}/**",
                    self._on_query,
                    allowed_origin=zenoh.Locality.REMOTE,
                )
            )
            liveliness = session.liveliness()
            declared.append(
                liveliness.declare_token(
                    f"{self._base}/@alive/{self._node_id}/{_encode_chunk(self._name)}"
                )
            )
            for outlet in self._outlets.values():
                self._declare_outlet(outlet)
            declared.append(
                liveliness.declare_subscriber(
                    f"{self._base}/@alive/**", self._on_alive, history=True
                )
            )
            self._running = True
            task_status.started()
            await self._pump(bus)
        finally:
            self._running = False
            self._session = None
            self._wake_w = None
            self._wake_r = None
            outlets = list(self._outlets.values())
            for outlet in outlets:
                outlet.publisher = None
                outlet.token = None
            self._node_id = ""
            self._peers.clear()
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(_close_session, session, declared)
            wake_r.close()
            wake_w.close()
            self._inbox.clear()
            self._wake_pending = False

    def send_nowait(self, topic: str, message: object) -> None:
        """Put a locally published message on the network; never blocks, never raises.

        A message that cannot be encoded is dropped and counted in ``send_errors``
        (logged once per type); a message published while not running is counted in
        ``not_connected`` (latched topics still remember it for later late joiners).
        """
        outlet = self._outlets.get(topic)
        if outlet is None:
            outlet = self._outlets[topic] = _Outlet(
                topic, f"{self._base}/{_topic_key(topic)}", topic in self._latched
            )
            if self._session is not None:
                self._declare_outlet(outlet)
        outlet.seq += 1
        try:
            payload = self._codec.encode(message, sender=self._sender, seq=outlet.seq)
        except WireEncodeError as exc:
            outlet.seq -= 1
            self._stats.send_errors += 1
            self._warn_once(type(message).__qualname__, "dropping a message on %s: %s", topic, exc)
            return
        if outlet.latched:
            self._latch(outlet, message, payload)
        publisher = outlet.publisher
        if publisher is None:
            self._stats.not_connected += 1
            return
        try:
            publisher.put(payload)
        except zenoh.ZError as exc:
            self._stats.send_errors += 1
            self._warn_once("put", "zenoh put on %s failed: %s", outlet.key, exc)
            return
        self._stats.sent += 1

    # -- internals: session -----------------------------------------------------------

    def _open_session(self) -> zenoh.Session:
        try:
            return zenoh.open(self._config)
        except zenoh.ZError:
            if self._fallback is None:
                raise
            log.debug("rendezvous port taken: listening on an ephemeral port")
            return zenoh.open(self._fallback)

    def _declare_outlet(self, outlet: _Outlet) -> None:
        session = self._session
        assert session is not None
        outlet.publisher = session.declare_publisher(
            outlet.key,
            congestion_control=zenoh.CongestionControl.DROP,
            allowed_destination=zenoh.Locality.REMOTE,
            express=self._express,
        )
        outlet.token = session.liveliness().declare_token(
            f"{self._base}/@alive/{self._node_id}/{_encode_chunk(self._name)}/"
            f"{_topic_key(outlet.topic)}"
        )

    def _latch(self, outlet: _Outlet, message: object, payload: bytes) -> None:
        if isinstance(message, TFMessage):
            for ts in message.transforms:
                if isinstance(ts, TransformStamped):
                    outlet.statics[ts.child_frame_id] = ts
            snapshot = TFMessage(tuple(outlet.statics.values()))
            payload = self._codec.encode(snapshot, sender=self._sender, seq=outlet.seq)
        # One reference assignment: the queryable thread reads either old or new bytes.
        outlet.latched_payload = payload

    def _warn_once(self, what: str, fmt: str, *args: object) -> None:
        if what not in self._warned:
            self._warned.add(what)
            log.warning(fmt, *args)

    # -- internals: Zenoh threads (keep short, never block) ---------------------------

    def _push(self, item: tuple[int, str, bytes]) -> None:
        inbox = self._inbox
        if len(inbox) >= self._max_pending:
            self._stats.overflow += 1  # deque(maxlen) drops the oldest entry
        inbox.append(item)
        if not self._wake_pending:
            self._wake_pending = True
            wake = self._wake_w
            if wake is not None:
                with contextlib.suppress(OSError):  # full buffer: a wake-up is queued
                    wake.send(b"\0")

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self._push((_SAMPLE, str(sample.key_expr), sample.payload.to_bytes()))

    def _on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is not None:
            self._push((_REPLY, str(sample.key_expr), sample.payload.to_bytes()))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        kind = _ALIVE_PUT if sample.kind == zenoh.SampleKind.PUT else _ALIVE_DEL
        self._push((kind, str(sample.key_expr), b""))

    def _on_query(self, query: zenoh.Query) -> None:
        with query:
            prefix = f"{self._base}/@latch/{self._node_id}/"
            for outlet in list(self._outlets.values()):
                payload = outlet.latched_payload
                if payload is not None:
                    key = prefix + _topic_key(outlet.topic)
                    if query.key_expr.intersects(key):
                        query.reply(key, payload)

    # -- internals: event loop ------------------------------------------------------------

    async def _pump(self, bus: Bus | _BusLike) -> None:
        reader = self._wake_r
        assert reader is not None
        while True:
            await anyio.wait_readable(reader)
            with contextlib.suppress(BlockingIOError):
                reader.recv(4096)
            self._wake_pending = False
            self._stats.batches += 1
            while self._drain(bus):
                await anyio.lowlevel.checkpoint()

    def _drain(self, bus: Bus | _BusLike) -> bool:
        """Decode and deliver up to ``max_batch`` queued entries; True if more remain."""
        inbox = self._inbox
        stats = self._stats
        codec = self._codec
        run_topic: str | None = None
        run: list[object] = []
        for _ in range(min(len(inbox), self._max_batch)):
            kind, key, payload = inbox.popleft()
            if kind >= _ALIVE_PUT:
                event = self._on_liveliness(kind == _ALIVE_PUT, key)
                if event is None:
                    continue
                topic: str | None = PEERS_TOPIC
                message: object = event
            else:
                stats.received += 1
                topic = self._topic_for(key, kind)
                if topic is None:
                    stats.malformed += 1
                    continue
                try:
                    decoded = codec.decode(payload)
                except WireVersionError:
                    stats.wrong_version += 1
                    continue
                except WireLimitError:
                    stats.over_limit += 1
                    continue
                except ValueError:  # WireDecodeError and anything msgspec let through
                    stats.malformed += 1
                    continue
                if kind == _SAMPLE:
                    seq_key = (decoded.sender, topic)
                    last = self._seqs.get(seq_key)
                    if last is not None and decoded.seq > last + 1:
                        stats.lost += decoded.seq - last - 1
                    if last is None or decoded.seq > last:
                        if last is None and len(self._seqs) >= 4096:
                            self._seqs.clear()
                        self._seqs[seq_key] = decoded.seq
                else:
                    stats.latched_replies += 1
                message = decoded.message
            if topic != run_topic:
                if run:
                    self._deliver(bus, run_topic, run)
                    run = []
                run_topic = topic
            run.append(message)
        if run:
            self._deliver(bus, run_topic, run)
        return bool(inbox)

    def _deliver(self, bus: Bus | _BusLike, topic: str | None, run: list[object]) -> None:
        assert topic is not None
        if len(run) == 1:
            bus.deliver_nowait(topic, run[0])
        else:
            bus.deliver_many_nowait(topic, run)
        self._stats.delivered += len(run)

    def _topic_for(self, key: str, kind: int) -> str | None:
        cache_key = key if kind == _SAMPLE else "@" + key
        topic = self._topic_of_key.get(cache_key, "")
        if topic != "":
            return topic
        base = self._base + "/"
        rest: str | None = None
        if key.startswith(base):
            rest = key[len(base) :]
            if kind == _REPLY:
                parts = rest.split("/", 2)
                rest = parts[2] if len(parts) == 3 and parts[0] == "@latch" else None
        topic = None if not rest else _key_topic(rest)
        if len(self._topic_of_key) < 10_000:
            self._topic_of_key[cache_key] = topic
        return topic

    def _on_liveliness(self, alive: bool, key: str) -> PeerEvent | None:
        base = f"{self._base}/@alive/"
        if not key.startswith(base):
            return None
        parts = key[len(base) :].split("/", 2)
        if len(parts) < 2:
            return None
        node_id, name = parts[0], _decode_chunk(parts[1])
        if node_id == self._node_id:
            return None
        topic = _key_topic(parts[2]) if len(parts) == 3 else ""
        info = self._peers.get(node_id)
        if alive:
            if info is None:
                info = PeerInfo(node_id, name)
            if topic:
                info = PeerInfo(node_id, name, info.topics | {topic})
            self._peers[node_id] = info
            if not topic or topic in self._latched:
                self._query_latched(node_id)
        elif not topic:
            self._peers.pop(node_id, None)
            # forget the dead node's sequence numbers lazily (cleared when the table fills)
        elif info is not None:
            self._peers[node_id] = PeerInfo(node_id, info.name, info.topics - {topic})
        return PeerEvent(alive, node_id, name, topic)

    def _query_latched(self, node_id: str) -> None:
        session = self._session
        if session is None:
            return
        try:
            session.get(
                f"{self._base}/@latch/{node_id}/**",
                self._on_reply,
                target=zenoh.QueryTarget.ALL,
                timeout=5.0,
            )
        except zenoh.ZError as exc:
            self._warn_once("query", "late-joiner query to %s failed: %s", node_id, exc)


def _close_session(session: zenoh.Session, declared: list[Any]) -> None:
    for entity in reversed(declared):
        with contextlib.suppress(Exception):
            entity.undeclare()
    with contextlib.suppress(Exception):
        session.close()  # type: ignore[no-untyped-call]


# -- process-side helpers (for the CLI and scripts) ----------------------------------


@dataclass(frozen=True, slots=True)
class ZenohOptions:
    """Everything a command line needs to build a Zenoh-backed bus (see :func:`parse_bus_spec`).

    Attributes mirror :class:`ZenohTransport`'s arguments of the same names.
    """

    connect: tuple[str, ...] | None = None
    listen: tuple[str, ...] | None = None
    config: str | None = None
    prefix: str = DEFAULT_PREFIX
    namespace: str = ""
    name: str | None = None
    port: int = DEFAULT_PORT
    express: bool = False

    def transport(self, **overrides: Any) -> ZenohTransport:
        """A new :class:`ZenohTransport` from these options (``overrides`` win).

        Raises:
            ValueError: for an invalid prefix, namespace or name.
            zenoh.ZError: for an unreadable or invalid config file.
        """
        kwargs: dict[str, Any] = {
            "connect": self.connect,
            "listen": self.listen,
            "config": self.config,
            "prefix": self.prefix,
            "namespace": self.namespace,
            "name": self.name,
            "port": self.port,
            "express": self.express,
        }
        kwargs.update(overrides)
        return ZenohTransport(**kwargs)


_SPEC_KEYS: Final = frozenset(
    {"connect", "listen", "config", "prefix", "namespace", "name", "port", "express"}
)


def parse_bus_spec(spec: str) -> ZenohOptions:
    """Parse a ``--bus`` value into :class:`ZenohOptions`.

    Forms::

        zenoh                                   one machine, no configuration
        zenoh?connect=tcp/10.0.0.2:7448         query-string options; repeat a key or
        zenoh?listen=tcp/0.0.0.0:7448&namespace=robot1      separate values with ','
        zenoh?config=/etc/tfbus/zenoh.json5&name=planner
        zenoh:tcp/10.0.0.2:7448                 shorthand for connect=...

    Keys: ``connect``, ``listen`` (endpoint lists), ``config`` (JSON5 file), ``prefix``,
    ``namespace``, ``name``, ``port`` (rendezvous port), ``express`` (``1``/``true``).

    Raises:
        ValueError: if the scheme is not ``zenoh`` or a key/value is not understood.
    """
    text = spec.strip()
    scheme, sep, rest = text.partition("?")
    options: dict[str, list[str]] = {}
    if scheme.startswith("zenoh:"):
        shorthand = scheme[len("zenoh:") :]
        scheme = "zenoh"
        if shorthand:
            options.setdefault("connect", []).extend(shorthand.split(","))
    if scheme != "zenoh":
        raise ValueError(f"unsupported bus {spec!r}: expected 'zenoh' or 'zenoh?key=value&...'")
    for key, value in parse_qsl(rest, keep_blank_values=True) if sep else ():
        if key not in _SPEC_KEYS:
            raise ValueError(f"unknown bus option {key!r} (known: {', '.join(sorted(_SPEC_KEYS))})")
        options.setdefault(key, []).extend(v for v in value.split(",") if v or key != "connect")

    def one(key: str) -> str | None:
        values = options.get(key)
        if not values:
            return None
        if len(values) > 1:
            raise ValueError(f"bus option {key!r} given more than once")
        return values[0]

    port_text = one("port")
    try:
        port = int(port_text) if port_text is not None else DEFAULT_PORT
    except ValueError:
        raise ValueError(f"bus option 'port' must be an integer, got {port_text!r}") from None
    express_text = (one("express") or "0").lower()
    if express_text not in ("0", "1", "true", "false", "yes", "no", ""):
        raise ValueError(f"bus option 'express' must be a boolean, got {express_text!r}")
    connect = options.get("connect")
    listen = options.get("listen")
    return ZenohOptions(
        connect=tuple(connect) if connect is not None else None,
        listen=tuple(v for v in listen if v) if listen is not None else None,
        config=one("config"),
        prefix=one("prefix") or DEFAULT_PREFIX,
        namespace=one("namespace") or "",
        name=one("name"),
        port=port,
        express=express_text in ("1", "true", "yes"),
    )


def zenoh_bus_from_options(
    options: ZenohOptions | str | None = None, *, queue_size: int = 100, **overrides: Any
) -> Bus:
    """A new (not yet opened) :class:`~tfbus.bus.Bus` carried over Zenoh.

    ``options`` is a :class:`ZenohOptions`, a ``--bus`` string (:func:`parse_bus_spec`)
    or None for the one-machine defaults; ``overrides`` are passed to
    :class:`ZenohTransport` (e.g. ``name="tfbus-monitor"``). Use it with
    ``async with zenoh_bus_from_options(spec) as bus:``; the transport is
    ``bus.transport``.

    Raises:
        ValueError: for an invalid spec, prefix, namespace, name or ``queue_size``.
        zenoh.ZError: for an unreadable or invalid config file.
    """
    from tfbus.bus import Bus

    if options is None:
        options = ZenohOptions()
    elif isinstance(options, str):
        options = parse_bus_spec(options)
    return Bus(transport=options.transport(**overrides), queue_size=queue_size)
