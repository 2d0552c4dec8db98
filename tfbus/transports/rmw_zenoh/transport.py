"""RmwZenohTransport: a :class:`~tfbus.bus.Transport` speaking rmw_zenoh's wire for ``/tf``
and ``/tf_static`` (the wire itself: :mod:`tfbus.transports.rmw_zenoh.wire`).

::

    from tfbus.bus import Bus
    from tfbus.transports.rmw_zenoh import RmwZenohTransport

    async with Bus(transport=RmwZenohTransport(connect="tcp/127.0.0.1:7447")) as bus:
        ...

**Topology.** By default a Zenoh *client* of the router at ``tcp/127.0.0.1:7447``
(``rmw_zenohd``'s port, or ``tfbus router``), multicast scouting off, timestamping on as
in rmw_zenoh's ``DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5``; ``mode="peer"`` makes a
gossiping peer that listens on ``tcp/127.0.0.1:0``, rmw_zenoh's own default topology
(``rmw_zenohd`` does not forward between peers, it introduces them). A client whose router
is not up yet waits for it (``connect_timeout``), as rmw_zenoh waits for its router.

**What goes on the wire** (rmw_zenoh's ``rmw_publisher_data.cpp`` and
``rmw_subscription_data.cpp`` for the tf2_ros QoS profiles):

* ``/tf``: a publisher on :func:`~.wire.data_key` with ``Reliability.RELIABLE`` and
  ``CongestionControl.DROP`` (keep-last history); a subscriber on the same key;
* ``/tf_static``: an ``AdvancedPublisher`` with a cache of depth 1, publisher detection
  and sporadic heartbeats every 0.5 s (``SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD``), and an
  ``AdvancedSubscriber`` with history (late-publisher detection, 100 samples per
  publisher), heartbeat recovery and subscriber detection. As tf2_ros'
  ``StaticTransformBroadcaster``, each ``/tf_static`` put carries every static transform
  this node has sent (latest per child frame, :class:`~tfbus.latch.StaticLatch`), so the
  cache of one sample is the whole set;
* every put carries the attachment (sequence number from 1, source timestamp, a 16-byte
  GID per publisher; the 33-byte form, or the older labelled form with
  ``attachment="labelled"``);
* liveliness tokens for the node, its publishers (declared with the first message of a
  topic) and its subscriptions, so a ROS 2 graph lists this node (``ros2 node list``,
  ``ros2 topic info``).

**Receiving.** Zenoh calls back on its own threads; the callbacks only append the raw
sample to a bounded deque and wake the event loop once per burst
(:class:`~tfbus.transports._base.ThreadWakeup`). The loop decodes and delivers. A sample
without an attachment (rmw_zenoh's subscription drops it too), with an attachment in
neither form, or whose CDR does not decode (:func:`tfbus.codecs.cdr.decode_tf`) is counted
(``no_attachment``, ``bad_attachment``, ``malformed``) and dropped; the valid ones beside it
are delivered. Liveliness tokens of the domain are read into a bounded graph
(:class:`PeerAware`: ``broadcasters()``, :class:`~tfbus.transports._base.PeerEvent` on
:data:`~tfbus.topics.PEERS_TOPIC`); one rmw_zenoh would refuse is counted in
``refused_tokens`` and ignored, and more than ``max_tokens`` tracked tokens are counted in
``tokens_over_limit`` and ignored.

**Namespaces.** ``namespace="robot1"`` makes the node ``/robot1/<name>`` and maps the bus
topics ``/tf`` and ``/tf_static`` to the ROS 2 topics ``/robot1/tf`` and
``/robot1/tf_static`` (keys ``<domain>/robot1/tf/...``), as a namespaced ROS 2 robot whose
tf topics are remapped to relative names. ``namespace="*"`` is the fleet listener: it
receives every ``/<robot>/tf`` and ``/<robot>/tf_static`` (one namespace chunk) as those
bus topics, and its peers' names are ``<robot>/<node name>`` (:class:`tfbus.fleet.FleetBuffer`).
A robot's statics that arrive before anyone subscribed to its ``/<robot>/tf_static`` (the
AdvancedSubscriber's history comes at once; a fleet subscribes when the robot's node
appears) are kept (:data:`MAX_UNHEARD_TOPICS`) and delivered once a subscriber is there.

Spec-tested: no real rmw_zenoh installs from the package registries here; the wire is
checked against golden vectors from rmw_zenoh's source and against ROBOTIS'
``zenoh-ros2-sdk`` and eclipse-zenoh's ``AdvancedPublisher``/``AdvancedSubscriber``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Final

import anyio
import anyio.abc
import zenoh
import zenoh.ext

from tfbus.codecs.cdr import MAX_TRANSFORMS, decode_tf, encode_tf
from tfbus.errors import TransportError, WireDecodeError, WireEncodeError
from tfbus.latch import StaticLatch
from tfbus.messages import TFMessage
from tfbus.ratelimit import CountLimitedLog
from tfbus.topics import PEERS_TOPIC, TF_STATIC_TOPIC, TF_TOPICS
from tfbus.transports._base import (
    BusLike,
    PeerEvent,
    PeerInfo,
    ThreadWakeup,
    TransportStatistics,
    ros_domain_id,
)
from tfbus.transports.rmw_zenoh.wire import (
    ATTACHMENT_LABELLED,
    ATTACHMENT_POSITIONAL,
    GID_SIZE,
    TF_DDS_TYPE,
    TF_LISTENER_QOS,
    TF_QOS,
    TF_STATIC_LISTENER_QOS,
    TF_STATIC_QOS,
    TF_TYPE_HASH,
    Attachment,
    EndpointToken,
    check_namespace,
    check_node_name,
    data_key,
    decode_attachment,
    encode_attachment,
    endpoint_token,
    node_token,
    parse_token,
)
from tfbus.transports.zenoh.config import open_waiting

__all__ = ["DEFAULT_ROUTER", "RmwZenohStatistics", "RmwZenohTransport", "rmw_zenoh_config"]

log = logging.getLogger("tfbus.transports.rmw_zenoh")

DEFAULT_ROUTER: Final = "tcp/127.0.0.1:7447"
"""The router a transport connects to by default (``rmw_zenohd``'s port on this machine)."""
FLEET_NAMESPACE: Final = "*"
"""The namespace of a fleet listener (every robot's ``/<robot>/tf``)."""
HEARTBEAT_PERIOD: Final = 0.5
"""Seconds between the sporadic heartbeats of the ``/tf_static`` AdvancedPublisher
(rmw_zenoh ``SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD``, 500 ms)."""
MAX_UNHEARD_TOPICS: Final = 256
"""A fleet listener keeps the statics of at most this many ``/<robot>/tf_static`` topics
that nobody subscribed to yet (each at most ``max_transforms`` transforms), for the
:class:`~tfbus.fleet.FleetBuffer` that subscribes once the robot's node appears."""
_SAMPLE: Final = 0
_ALIVE_PUT: Final = 1
_ALIVE_DEL: Final = 2
_FORMS: Final = (ATTACHMENT_POSITIONAL, ATTACHMENT_LABELLED)


@dataclass(slots=True)
class RmwZenohStatistics(TransportStatistics):
    """Counters of one :class:`RmwZenohTransport` (:meth:`RmwZenohTransport.statistics`);
    the first five are :class:`~tfbus.transports._base.TransportStatistics`'s.

    Attributes:
        no_attachment: received samples dropped because they had no attachment.
        bad_attachment: received samples dropped because their attachment was in neither
            rmw_zenoh form.
        overflow: received samples dropped because the inbound queue was full.
        not_connected: ``/tf`` messages published while not running (``/tf_static`` ones
            are latched and put once running).
        not_mapped: messages on bus topics this transport does not carry (not sent).
        refused_tokens: liveliness tokens rmw_zenoh would refuse (ignored).
        tokens_over_limit: liveliness tokens ignored because ``max_tokens`` were tracked.
        batches: event-loop wake-ups that took samples or tokens.
    """

    no_attachment: int = 0
    bad_attachment: int = 0
    overflow: int = 0
    not_connected: int = 0
    not_mapped: int = 0
    refused_tokens: int = 0
    tokens_over_limit: int = 0
    batches: int = 0


def rmw_zenoh_config(
    *,
    mode: str = "client",
    connect: str | Sequence[str] | None = None,
    listen: str | Sequence[str] | None = None,
    config: Mapping[str, Any] | None = None,
) -> zenoh.Config:
    """The Zenoh configuration of a transport: ``mode`` (``"client"`` or ``"peer"``),
    multicast scouting off, gossip on for peers (how ``rmw_zenohd`` introduces peers),
    timestamping on, ``connect`` endpoints (default :data:`DEFAULT_ROUTER`), and for a
    peer ``listen`` endpoints (default ``tcp/127.0.0.1:0``); then ``config``, a mapping of
    Zenoh config paths to JSON values, on top.

    Raises:
        ValueError: ``mode`` is not ``"client"`` or ``"peer"``, or an endpoint list is empty.
        TransportError: Zenoh rejects a value (the ``ZError`` is the cause).
    """
    if mode not in ("client", "peer"):
        raise ValueError(f"mode must be 'client' or 'peer', got {mode!r}")
    connect_eps = [connect] if isinstance(connect, str) else list(connect or [DEFAULT_ROUTER])
    if not connect_eps:
        raise ValueError("connect must name at least one endpoint")
    try:
        cfg: zenoh.Config = zenoh.Config()
        cfg.insert_json5("mode", json.dumps(mode))
        cfg.insert_json5("scouting/multicast/enabled", "false")
        cfg.insert_json5("timestamping/enabled", "true")
        cfg.insert_json5("connect/endpoints", json.dumps(connect_eps))
        if mode == "peer":
            listen_eps = ([listen] if isinstance(listen, str)
                          else list(listen or ["tcp/127.0.0.1:0"]))
            cfg.insert_json5("listen/endpoints", json.dumps(listen_eps))
            cfg.insert_json5("scouting/gossip/enabled", "true")
        elif listen:
            raise ValueError("listen endpoints need mode='peer' (a client does not listen)")
        for key, value in (config or {}).items():
            cfg.insert_json5(key, json.dumps(value))
        return cfg
    except zenoh.ZError as err:
        raise TransportError(f"invalid Zenoh configuration: {err}") from err


def default_node_name() -> str:
    """``tfbus_<pid>``: the node name used when none is given (a valid ROS 2 name)."""
    return f"tfbus_{os.getpid()}"


def ros_node_name(name: str) -> str:
    """``name`` as a ROS 2 node name: every character other than a letter, digit or ``_``
    becomes ``_``, and a leading digit gets a ``_`` before it (``"tfbus-echo"`` ->
    ``"tfbus_echo"``): command-line node names are ``prog-pid``."""
    text = "".join(c if c.isascii() and (c.isalnum() or c == "_") else "_" for c in name)
    return f"_{text}" if text[:1].isdigit() else text


@dataclass(slots=True)
class _Outlet:
    """One published topic: its key, publisher, token and counters."""

    topic: str  # the bus topic
    ros_topic: str
    key: str
    latched: bool
    gid: bytes
    entity_id: int
    seq: int = 0
    publisher: Any = None  # zenoh.Publisher or zenoh.ext.AdvancedPublisher
    token: Any = None
    latch: StaticLatch = field(default_factory=StaticLatch)


@dataclass(slots=True)
class _Node:
    """A remote node of the graph, from its liveliness tokens."""

    name: str
    tokens: set[str] = field(default_factory=set)  # its tokens we track
    topics: dict[str, int] = field(default_factory=dict)  # bus topic -> publisher tokens


class RmwZenohTransport:
    """A :class:`~tfbus.bus.Transport` over rmw_zenoh's wire (module doc).

    Args:
        connect: Zenoh endpoints to connect to (default :data:`DEFAULT_ROUTER`).
        listen: endpoints to listen on (``mode="peer"`` only; default ``tcp/127.0.0.1:0``).
        mode: ``"client"`` (default: a client of the router) or ``"peer"``.
        domain_id: the ROS 2 domain (first chunk of every key); default the
            ``ROS_DOMAIN_ID`` environment variable, else 0.
        namespace: the node's ROS 2 namespace (``"robot1"``); ``"*"``: a fleet listener.
        name: the node's name (made a valid ROS 2 name: :func:`ros_node_name`; default
            ``tfbus_<pid>``).
        attachment: ``"positional"`` (the 33-byte attachment of Kilted, Jazzy >= 0.2.4,
            Humble >= 0.1.2) or ``"labelled"`` (Jazzy before 0.2.4). Received samples
            are read in either form.
        config: Zenoh config paths -> JSON values, applied on top
            (:func:`rmw_zenoh_config`).
        topics: which of ``/tf`` and ``/tf_static`` to receive (both by default).
        max_pending: capacity of the inbound queue, samples and tokens; when full the
            oldest are dropped and counted in ``overflow``.
        max_batch: most entries delivered per event-loop turn.
        max_transforms: received messages with more transforms are malformed.
        max_tokens: most remote liveliness tokens tracked (nodes and endpoints).
        connect_timeout: seconds to keep trying while no ``connect`` endpoint answers
            (``None``: as long as it takes, as rmw_zenoh waits for its router).

    Raises:
        ValueError: a value out of range or not a ROS 2 name (named).
        TransportError: Zenoh rejects the configuration.
    """

    peers_topic: str = PEERS_TOPIC
    """The local bus topic of :class:`~tfbus.transports._base.PeerEvent` messages."""

    def __init__(
        self,
        *,
        connect: str | Sequence[str] | None = None,
        listen: str | Sequence[str] | None = None,
        mode: str = "client",
        domain_id: int | None = None,
        namespace: str = "",
        name: str | None = None,
        attachment: str = ATTACHMENT_POSITIONAL,
        config: Mapping[str, Any] | None = None,
        topics: Iterable[str] = TF_TOPICS,
        max_pending: int = 50_000,
        max_batch: int = 256,
        max_transforms: int = MAX_TRANSFORMS,
        max_tokens: int = 4096,
        connect_timeout: float | None = None,
    ) -> None:
        self._domain = ros_domain_id(domain_id)
        self._fleet = namespace == FLEET_NAMESPACE
        self._namespace = "/" if self._fleet else check_namespace(namespace)
        self._name = ros_node_name(name) if name is not None else default_node_name()
        check_node_name(self._name)
        if attachment not in _FORMS:
            raise ValueError(f"attachment must be one of {_FORMS}, got {attachment!r}")
        self._form = attachment
        self._topics = tuple(topics)
        for topic in self._topics:
            if topic not in TF_TOPICS:
                raise ValueError(f"topics: {topic!r} is not '/tf' or '/tf_static'")
        for label, bound in (("max_pending", max_pending), ("max_batch", max_batch),
                             ("max_transforms", max_transforms), ("max_tokens", max_tokens)):
            if bound < 1:
                raise ValueError(f"{label} must be at least 1, got {bound!r}")
        if connect_timeout is not None and not 0 <= connect_timeout < math.inf:
            raise ValueError(
                f"connect_timeout must be None or finite seconds >= 0, got {connect_timeout!r}")
        self._connect_timeout = connect_timeout
        self._config = rmw_zenoh_config(mode=mode, connect=connect, listen=listen,
                                        config=config)
        self._max_pending = max_pending
        self._max_batch = max_batch
        self._max_transforms = max_transforms
        self._max_tokens = max_tokens
        self._stats = RmwZenohStatistics()
        self._inbox: deque[tuple[int, str, bytes | None, bytes | None]] = deque(
            maxlen=max_pending)
        self._outlets: dict[str, _Outlet] = {}
        self._next_entity = 1  # 0 is the node's id
        self._session: zenoh.Session | None = None
        self._wakeup: ThreadWakeup | None = None
        self._zid = ""
        self._running = False
        self._graph: dict[str, _Node] = {}  # node key -> node
        self._graph_version = 0  # counts the graph's changes of nodes and their topics
        self._token_node: dict[str, tuple[str, str]] = {}  # token -> (node key, bus topic)
        # fleet: statics of /<robot>/tf_static received before anyone subscribed to it
        self._unheard: dict[str, StaticLatch] = {}
        self._recheck_unheard = False  # deliver_kept_statics: look again on the next drain
        self._log = CountLimitedLog(log, 1000, clock=time.monotonic)

    # -- public information ---------------------------------------------------------------

    @property
    def domain_id(self) -> int:
        """The ROS 2 domain."""
        return self._domain

    @property
    def namespace(self) -> str:
        """The node's ROS 2 namespace (``"/"`` at the root and for a fleet listener)."""
        return self._namespace

    @property
    def name(self) -> str:
        """The node's ROS 2 name."""
        return self._name

    @property
    def node_id(self) -> str:
        """``<zid>/0`` (this node on the graph) while running, else ``""``."""
        return f"{self._zid}/0" if self._zid else ""

    @property
    def running(self) -> bool:
        """True between ``run``'s ``started()`` and its end."""
        return self._running

    @property
    def pending(self) -> int:
        """Entries received by Zenoh's threads and not yet delivered
        (:class:`~tfbus.transports._base.Backlogged`)."""
        return len(self._inbox)

    def node_label(self) -> tuple[str, str]:
        """(the node's fully qualified name, its graph id; ``""`` while not running)."""
        ns = "" if self._namespace == "/" else self._namespace
        return f"{ns}/{self._name}", self.node_id

    def data_key(self, topic: str) -> str:
        """The key expression the bus topic ``topic`` is put on.

        Raises:
            ValueError: ``topic`` is not carried (not ``/tf``/``/tf_static``, or on a
                fleet listener not ``/<robot>/tf``/``/<robot>/tf_static``).
        """
        ros_topic = self._ros_topic(topic)
        if ros_topic is None:
            raise ValueError(f"topic {topic!r} is not carried by this rmw_zenoh transport")
        return data_key(self._domain, ros_topic)

    def statistics(self) -> RmwZenohStatistics:
        """A copy of the counters (:class:`RmwZenohStatistics`)."""
        return replace(self._stats)

    @property
    def peers_version(self) -> int:
        """A number that changes whenever the live nodes or the topics they publish may
        have changed (:meth:`alive`, :meth:`broadcasters`): what a reader derived from
        them holds while it is the same."""
        return self._graph_version

    def broadcasters(self) -> dict[str, PeerInfo]:
        """The live remote nodes that publish ``/tf`` or ``/tf_static`` (as this bus
        hears them), by ``<zid>/<node id>`` (:class:`~tfbus.transports._base.PeerAware`)."""
        return {key: info for key, info in self.alive().items() if info.is_broadcaster}

    def alive(self) -> dict[str, PeerInfo]:
        """Every live remote node of the domain, by ``<zid>/<node id>``, with the bus
        topics it publishes."""
        return {key: PeerInfo(key, node.name, frozenset(node.topics))
                for key, node in self._graph.items()}

    def deliver_kept_statics(self) -> None:
        """Deliver, on this transport's next pass in the event loop, the statics it kept
        for fleet topics nobody subscribed to when they came (see the module docstring)
        to those of the topics that have a subscriber now.

        A robot's kept statics are otherwise delivered when a graph event comes (the
        robot's node appearing, on which a :class:`~tfbus.fleet.FleetBuffer` subscribes
        to its topics); a FleetBuffer that subscribes to the robots already alive calls
        this, since every token of those robots may have come before it subscribed.
        Never blocks, never raises; nothing happens when not running or nothing is kept."""
        wakeup = self._wakeup
        if self._unheard and wakeup is not None:
            self._recheck_unheard = True
            wakeup.wake()

    def __repr__(self) -> str:
        state = "running" if self._running else "stopped"
        return (f"<RmwZenohTransport {state} domain={self._domain} "
                f"node={self.node_label()[0]!r} peers={len(self._graph)}>")

    # -- topic mapping --------------------------------------------------------------------

    def _ros_topic(self, topic: str) -> str | None:
        """The ROS 2 topic of bus topic ``topic``, or None if it is not carried."""
        if self._fleet:
            parts = topic.split("/")
            if len(parts) == 3 and parts[0] == "" and parts[1] and f"/{parts[2]}" in TF_TOPICS:
                try:
                    check_namespace(parts[1])
                except ValueError:
                    return None
                return topic
            return topic if topic in TF_TOPICS else None
        if topic not in TF_TOPICS:
            return None
        return topic if self._namespace == "/" else self._namespace + topic

    def _bus_topic(self, ros_topic: str) -> str | None:
        """The bus topic of ROS 2 topic ``ros_topic``, or None if it is not carried."""
        if self._fleet:
            parts = ros_topic.split("/")
            if len(parts) == 3 and parts[0] == "" and f"/{parts[2]}" in self._topics:
                try:
                    check_namespace(parts[1])
                except ValueError:
                    return None
                return ros_topic
            return None
        ns = "" if self._namespace == "/" else self._namespace
        if ros_topic.startswith(ns) and ros_topic[len(ns):] in self._topics:
            return ros_topic[len(ns):]
        return None

    def _topic_of_key(self, key: str) -> str | None:
        """The bus topic of a received data key (None: not one this transport carries)."""
        parts = key.split("/")
        if (len(parts) < 4 or parts[0] != str(self._domain) or parts[-2] != TF_DDS_TYPE
                or parts[-1] != TF_TYPE_HASH):
            return None
        return self._bus_topic("/" + "/".join(parts[1:-2]))

    # -- Transport contract ------------------------------------------------------------------

    async def run(
        self,
        bus: BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Open the Zenoh session, declare the subscriptions and tokens, report started,
        deliver remote messages until cancelled; undeclare and close on the way out.

        Raises:
            RuntimeError: if this transport is already running.
            TransportError: the session cannot be opened (or, with ``connect_timeout``,
                no endpoint answered in time) or declared; the ``ZError`` is the cause.
        """
        if self._running or self._session is not None:
            raise RuntimeError("this RmwZenohTransport is already running")
        session = await self._open_waiting()
        wakeup = ThreadWakeup()
        declared: list[Any] = []
        try:
            self._session = session
            self._wakeup = wakeup
            self._zid = str(session.zid())
            try:
                self._declare(session, declared)
                for outlet in self._outlets.values():
                    self._declare_outlet(outlet)
                    if outlet.latched and outlet.latch:
                        self._put(outlet, encode_tf(outlet.latch.message()))
            except zenoh.ZError as err:
                raise TransportError(f"cannot declare on the Zenoh session: {err}") from err
            self._running = True
            task_status.started()
            await wakeup.serve(lambda woken: self._drain(bus, woken))
        finally:
            self._running = False
            for outlet in self._outlets.values():
                declared.extend(x for x in (outlet.token, outlet.publisher) if x is not None)
                outlet.publisher = outlet.token = None
            self._session = None
            self._wakeup = None
            self._zid = ""
            self._graph.clear()
            self._graph_version += 1
            self._token_node.clear()
            self._unheard.clear()
            self._recheck_unheard = False
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(_close_session, session, declared)
            wakeup.close()
            self._inbox.clear()

    def send_nowait(self, topic: str, message: object) -> None:
        """Put a locally published ``TFMessage`` on its key; never blocks, never raises.

        ``/tf_static`` messages are merged into this node's latched set, and the whole
        set is put (the AdvancedPublisher's cache of one sample then holds every static
        transform). Counted: a message not encodable (not a TFMessage, a stamp outside
        int32 seconds) in ``send_errors``, a topic not carried in ``not_mapped``, a
        ``/tf`` message while not running in ``not_connected``.
        """
        outlet = self._outlets.get(topic)
        if outlet is None:
            ros_topic = self._ros_topic(topic)
            if ros_topic is None:
                self._stats.not_mapped += 1
                return
            latched = topic.endswith(TF_STATIC_TOPIC)
            outlet = self._outlets[topic] = _Outlet(
                topic, ros_topic, data_key(self._domain, ros_topic), latched,
                os.urandom(GID_SIZE), self._next_entity)
            self._next_entity += 1
            if self._session is not None:
                try:
                    self._declare_outlet(outlet)
                except zenoh.ZError as exc:
                    self._log.log(logging.WARNING, "cannot publish on %s: %s", outlet.key, exc)
        try:
            if not isinstance(message, TFMessage):
                raise WireEncodeError(f"not a TFMessage: {type(message).__name__}")
            payload = encode_tf(message)
            if outlet.latched:
                outlet.latch.add(message)
                payload = encode_tf(outlet.latch.message())
        except WireEncodeError as exc:
            self._stats.send_errors += 1
            self._log.log(logging.WARNING, "dropping a message on %s: %s", topic, exc)
            return
        if outlet.publisher is None:
            if not outlet.latched:
                self._stats.not_connected += 1
            return
        self._put(outlet, payload)

    # -- internals: session ------------------------------------------------------------------

    async def _open_waiting(self) -> zenoh.Session:
        """Open the session, waiting for a router while no ``connect`` endpoint answers
        (:func:`~tfbus.transports.zenoh.config.open_waiting`, bounded by
        ``connect_timeout``)."""
        return await open_waiting(self._open_session, self._config, self._connect_timeout, log)

    def _open_session(self) -> zenoh.Session:
        try:
            return zenoh.open(self._config)
        except zenoh.ZError as err:
            raise TransportError(f"cannot open the Zenoh session: {err}") from err

    def _declare(self, session: zenoh.Session, declared: list[Any]) -> None:
        liveliness = session.liveliness()
        d = self._domain
        declared.append(liveliness.declare_token(
            node_token(d, self._zid, 0, self._namespace, self._name)))
        for topic in self._topics:
            static = topic == TF_STATIC_TOPIC
            if self._fleet:
                key = f"{d}/*/{topic.strip('/')}/{TF_DDS_TYPE}/{TF_TYPE_HASH}"
                ros_topic = topic
            else:
                ros_topic = self._ros_topic(topic) or topic
                key = data_key(d, ros_topic)
            if static:
                declared.append(zenoh.ext.declare_advanced_subscriber(
                    session, key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE,
                    history=zenoh.ext.HistoryConfig(
                        detect_late_publishers=True, max_samples=TF_STATIC_LISTENER_QOS.depth),
                    recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                    subscriber_detection=True))
            else:
                declared.append(session.declare_subscriber(
                    key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE))
            if not self._fleet:
                declared.append(liveliness.declare_token(endpoint_token(
                    d, self._zid, 0, self._next_entity, "MS", self._namespace, self._name,
                    ros_topic, TF_STATIC_LISTENER_QOS if static else TF_LISTENER_QOS)))
                self._next_entity += 1
        declared.append(liveliness.declare_subscriber(
            f"@ros2_lv/{d}/**", self._on_alive, history=True))

    def _declare_outlet(self, outlet: _Outlet) -> None:
        session = self._session
        assert session is not None
        if outlet.latched:
            outlet.publisher = zenoh.ext.declare_advanced_publisher(
                session, outlet.key,
                congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE,
                cache=zenoh.ext.CacheConfig(TF_STATIC_QOS.depth),
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=HEARTBEAT_PERIOD),
                publisher_detection=True)
        else:
            outlet.publisher = session.declare_publisher(
                outlet.key, congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE)
        outlet.token = session.liveliness().declare_token(endpoint_token(
            self._domain, self._zid, 0, outlet.entity_id, "MP", self._namespace, self._name,
            outlet.ros_topic, TF_STATIC_QOS if outlet.latched else TF_QOS))

    def _put(self, outlet: _Outlet, payload: bytes) -> None:
        outlet.seq += 1
        attachment = encode_attachment(
            Attachment(outlet.seq, time.time_ns(), outlet.gid), self._form)
        try:
            outlet.publisher.put(payload, attachment=attachment)
        except zenoh.ZError as exc:
            self._stats.send_errors += 1
            self._log.log(logging.WARNING, "zenoh put on %s failed: %s", outlet.key, exc)
            return
        self._stats.sent += 1

    # -- internals: Zenoh threads (short, never block) ------------------------------------

    def _push(self, item: tuple[int, str, bytes | None, bytes | None]) -> None:
        if len(self._inbox) >= self._max_pending:
            self._stats.overflow += 1  # deque(maxlen) drops the oldest entry
        self._inbox.append(item)
        wakeup = self._wakeup
        if wakeup is not None:
            wakeup.wake()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            attachment = sample.attachment
            self._push((_SAMPLE, str(sample.key_expr), sample.payload.to_bytes(),
                        None if attachment is None else attachment.to_bytes()))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        kind = _ALIVE_PUT if sample.kind == zenoh.SampleKind.PUT else _ALIVE_DEL
        self._push((kind, str(sample.key_expr), None, None))

    # -- internals: event loop ---------------------------------------------------------------

    def _drain(self, bus: BusLike, woken: bool) -> bool:
        """Decode and deliver up to ``max_batch`` queued entries; True if more remain."""
        if woken:
            self._stats.batches += 1
        inbox = self._inbox
        for _ in range(min(len(inbox), self._max_batch)):
            kind, key, payload, attachment = inbox.popleft()
            if kind == _SAMPLE:
                self._receive(bus, key, payload or b"", attachment)
            else:
                events = self._graph_update(kind == _ALIVE_PUT, key)
                if events:  # a node or one of its topics came or went
                    self._graph_version += 1
                for event in events:
                    bus.deliver_nowait(PEERS_TOPIC, event)
                if events and self._unheard:
                    self._deliver_unheard(bus)
        if self._recheck_unheard:
            self._recheck_unheard = False
            if self._unheard:
                self._deliver_unheard(bus)
        return bool(inbox)

    def _deliver_unheard(self, bus: BusLike) -> None:
        """Deliver the statics of fleet topics that had no subscriber when they came to
        the topics that have one now (a fleet subscribes to a robot's topics when its
        node appears, which may be after the AdvancedSubscriber's history came)."""
        for topic in [t for t in self._unheard if bus.reaches(t)]:
            bus.deliver_nowait(topic, self._unheard.pop(topic).message())

    def _receive(self, bus: BusLike, key: str, payload: bytes, attachment: bytes | None) -> None:
        stats = self._stats
        stats.received += 1
        topic = self._topic_of_key(key)
        if topic is None:
            stats.malformed += 1
            return
        if attachment is None:
            stats.no_attachment += 1
            return
        try:
            decode_attachment(attachment)
        except WireDecodeError:
            stats.bad_attachment += 1
            return
        try:
            message = decode_tf(payload, max_transforms=self._max_transforms)
        except WireDecodeError:
            stats.malformed += 1
            return
        if self._fleet and topic.endswith(TF_STATIC_TOPIC) and not bus.reaches(topic):
            latch = self._unheard.get(topic)
            if latch is None and len(self._unheard) < MAX_UNHEARD_TOPICS:
                latch = self._unheard[topic] = StaticLatch()
            if latch is not None and len(latch) < self._max_transforms:
                latch.add(message)
        bus.deliver_nowait(topic, message)
        stats.delivered += 1

    def _graph_update(self, alive: bool, key: str) -> list[PeerEvent]:
        """Update the graph with one token appearing or going; the events to deliver."""
        if not alive:
            return self._token_gone(key)
        if key in self._token_node:
            return []
        try:
            token = parse_token(key)
        except WireDecodeError:
            self._stats.refused_tokens += 1
            return []
        if token.zid == self._zid or token.domain_id != self._domain:
            return []
        if len(self._token_node) >= self._max_tokens:
            self._stats.tokens_over_limit += 1
            return []
        node_key = token.node_key
        name = self._peer_name(token)
        node = self._graph.get(node_key)
        events: list[PeerEvent] = []
        if node is None:
            node = self._graph[node_key] = _Node(name)
            events.append(PeerEvent(True, node_key, name))
        node.tokens.add(key)
        topic = ""
        if token.kind == "MP" and token.type_name == TF_DDS_TYPE:
            topic = self._bus_topic(token.topic) or ""
            if topic:
                count = node.topics.get(topic, 0)
                node.topics[topic] = count + 1
                if count == 0:
                    events.append(PeerEvent(True, node_key, name, topic))
        self._token_node[key] = (node_key, topic)
        return events

    def _token_gone(self, key: str) -> list[PeerEvent]:
        entry = self._token_node.pop(key, None)
        if entry is None:
            return []
        node_key, topic = entry
        node = self._graph.get(node_key)
        if node is None:
            return []
        node.tokens.discard(key)
        events: list[PeerEvent] = []
        if topic:
            left = node.topics.get(topic, 1) - 1
            if left <= 0:
                node.topics.pop(topic, None)
                events.append(PeerEvent(False, node_key, node.name, topic))
            else:
                node.topics[topic] = left
        if not node.tokens:
            del self._graph[node_key]
            events.append(PeerEvent(False, node_key, node.name))
        return events

    def _peer_name(self, token: EndpointToken) -> str:
        ns = token.namespace.strip("/")
        return f"{ns}/{token.name}" if ns else token.name


def _close_session(session: zenoh.Session, declared: list[Any]) -> None:
    for entity in reversed(declared):
        with contextlib.suppress(Exception):
            entity.undeclare()
    with contextlib.suppress(Exception):
        session.close()  # type: ignore[no-untyped-call]
