"""The ROS 1 node behind :class:`Ros1Transport`: registration with the master, TCPROS
connections to publishers and from subscribers, the latched ``/tf_static`` set."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import ipaddress
import logging
import os
import secrets
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Final, NoReturn, TypeVar
from urllib.parse import urlsplit

import anyio
import anyio.abc
from anyio.streams.buffered import BufferedByteReceiveStream
from anyio.streams.stapled import MultiListener

from tfbus._aio import open_pumped_connection, running_asyncio_loop
from tfbus.codecs import ros1 as ros1_codec
from tfbus.codecs.ros1 import (
    CLOCK_MD5SUM,
    CLOCK_MSGDEF,
    CLOCK_TYPE,
    SCAN_MD5SUM,
    SCAN_TYPE,
    TF_MD5SUM,
    TF_TYPE,
    TFCodec,
    decode_clock,
    decode_scan,
    scan_definition,
)
from tfbus.errors import TransportError
from tfbus.messages import TFMessage, TransformStamped
from tfbus.ratelimit import CountLimitedLog
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.transports._base import BusLike, ThreadWakeup, TransportStatistics
from tfbus.transports._newest import ClockFollower, NewestClock

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.transports.ros1.action import LookupActionClient, LookupActionServer

from .rpc import BadReply, CallFailed, SlaveServer, call, serve_listener
from .tcpros import (
    MAX_HEADER_BYTES,
    FrameQueue,
    FrameSplitter,
    decode_header,
    encode_header,
    frame,
    read_frame,
    serve_subscriber,
)

__all__ = ["RawHandler", "Ros1Statistics", "Ros1Transport", "tf_message_from"]

_log = logging.getLogger("tfbus.transports.ros1")
_peer_log = CountLimitedLog(_log, 1, period=5.0, clock=time.monotonic)
"""Warnings about what a peer sent (malformed frames and headers): at most one line per
5 s per kind, however fast a hostile peer sends; every one is counted in statistics()."""

_TOPICS: Final = (TF_TOPIC, TF_STATIC_TOPIC)
_LATCHED: Final = frozenset({TF_STATIC_TOPIC})
MAX_PUBLISHERS: Final = 1024
"""Publishers of one topic this node follows at most; further URIs in a master answer or a
``publisherUpdate`` are dropped (counted). Those already connected are kept first."""
MAX_CONCURRENT_REQUESTS: Final = 16
"""``requestTopic`` calls in flight at once, whatever the number of publishers; each has
the node's ``master_timeout`` as its deadline, so slow publishers delay a good one by
one deadline at most."""
_MASTER_RETRY_PERIOD: Final = 1.0
"""Seconds, at most, between attempts while the master is unreachable or answers badly."""
_UNREGISTER_DEADLINE: Final = 1.0


@dataclass(slots=True)
class Ros1Statistics(TransportStatistics):
    """Counters of one :class:`Ros1Transport` (monotonic since it was made); the first
    five are :class:`~tfbus.transports._base.TransportStatistics`'s.

    Attributes:
        sent: messages written to subscriber connections (one per connection).
        send_errors: messages that could not be serialised (e.g. a stamp before 1970).
        received: TFMessage frames read from publisher connections (valid or not).
        delivered: TFMessages decoded and delivered to the bus.
        malformed: frames or headers that could not be decoded (each closed its
            connection).
        send_dropped: messages dropped because a subscriber's queue was full (oldest first).
        connections_opened: TCPROS connections established, both directions.
        connections_closed: TCPROS connections closed, both directions.
        registrations: successful registrations with a master (more than one after a
            master restart).
        refused_hosts: publishers not contacted because they are outside loopback (their
            XML-RPC URI from the master or a ``publisherUpdate``, or the TCPROS endpoint
            they offer).
        bad_replies: XML-RPC answers from the master or a publisher that were not ROS
            XML-RPC (not HTTP 200, not XML, nested too deep, over 1 MiB, a fault, the
            wrong shape, a TCPROS port outside 1..65535); each call is retried with
            back-off.
        bad_requests: requests to this node's slave API that were refused (not XML-RPC,
            over 1 MiB, too slow, an unknown method or wrong arguments).
        accept_errors: ``accept`` calls that failed for lack of resources (e.g.
            ``EMFILE``: out of file descriptors); the listener backs off and goes on.
        publishers_dropped: publisher URIs not followed because a topic already had
            :data:`MAX_PUBLISHERS` of them.
        coalesced: ``clock_topic`` messages replaced by a newer one before the event
            loop saw them (followed newest-only by a :class:`~tfbus.clock.SimClock`:
            :meth:`Ros1Transport.keep_newest`), or dropped, oldest first, beyond
            :data:`~tfbus.transports._newest.NEWEST_MAX_QUEUED` waiting for it.
        kept: ``clock_topic`` messages held newest-only, not delivered (yet) when the
            copy was made: 0 or 1 (the one whose stamp the follower reads as the time).
            Every clock message received is delivered, coalesced, kept or malformed.
    """

    send_dropped: int = 0
    connections_opened: int = 0
    connections_closed: int = 0
    registrations: int = 0
    refused_hosts: int = 0
    bad_replies: int = 0
    bad_requests: int = 0
    accept_errors: int = 0
    publishers_dropped: int = 0
    coalesced: int = 0
    kept: int = 0


def _default_name() -> str:
    return f"/tfbus_{os.getpid()}_{secrets.token_hex(3)}"


def _resolve_host(host: str | None) -> str:
    if host:
        return host
    return os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME") or "127.0.0.1"


def _uri_host(uri: str) -> str | None:
    """The host of an ``http://host:port/`` URI, or None when there is none to contact
    (the call then fails as a bad URI, without a connection)."""
    try:
        return urlsplit(uri).hostname
    except ValueError:
        return None


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Outgoing:
    """One subscriber connected to us: its bounded queue of frames (drop oldest)."""

    def __init__(self, topic: str, peer: str, queue_size: int) -> None:
        self.topic = topic
        self.peer = peer
        self.frames = FrameQueue(queue_size)
        self.conn_id = 0


def _set_nodelay(sock: socket.socket | None) -> None:
    if sock is not None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


RawHandler = Callable[[bytes, str], None]
"""A raw topic's handler: ``handler(payload, callerid)`` (:meth:`Ros1Transport.subscribe_raw`)."""


def _compiled_tf_decoder() -> Callable[[bytes | memoryview], list[TransformStamped]] | None:
    """The codec's compiled ROS 1 ``TFMessage`` decoder (``TFCodec.decode`` without its
    Python wrappers; raises the decoder's own errors, not ``WireDecodeError``), or None
    where there is none (pure-Python core, big-endian host)."""
    compiled: Callable[[bytes | memoryview], list[TransformStamped]] | None
    compiled = ros1_codec._compiled_ros1
    return compiled


def tf_message_from(authority: str) -> type[TFMessage]:
    """A ``TFMessage`` subclass whose class attribute ``authority`` is ``authority``: the
    messages of one TCPROS connection are built with it, so that a
    :class:`~tfbus.listener.TransformListener` records each publisher's caller id
    (the connection header's ``callerid``) as the authority of its transforms, as
    tf2_ros's ROS 1 listener does (``TransformListener::subscription_callback_impl``:
    ``msg_evt.getPublisherName()``). One class per connection, made when its header
    arrives: a message costs nothing more than a plain ``TFMessage``."""
    return type("TFMessage", (TFMessage,), {"__slots__": (), "authority": authority})


_T = TypeVar("_T")


class _ClockConnection:
    """The socket of one clock-topic connection, read by a worker thread
    (:meth:`Ros1Transport._pump_clock`): :meth:`call` runs a blocking step in that thread,
    :meth:`end` (event loop) unblocks it and closes the socket -- at once when no step
    runs, else by the step as it returns, so a socket is never closed under a thread
    still reading it."""

    __slots__ = ("busy", "ended", "lock", "sock")

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.sock: socket.socket | None = None
        self.busy = False
        self.ended = False

    def call(self, step: Callable[..., _T], *args: Any) -> _T:
        """Run ``step(*args)`` (a worker thread).

        Raises:
            anyio.EndOfStream: the connection was ended before the step began.
            Exception: what ``step`` raises.
        """
        with self.lock:
            if self.ended:
                raise anyio.EndOfStream
            self.busy = True
        try:
            return step(*args)
        finally:
            with self.lock:
                self.busy = False
                if self.ended and self.sock is not None:
                    self.sock.close()

    def open(self, host: str, port: int, hello: bytes, timeout: float,
             splitter: FrameSplitter) -> list[bytes | memoryview]:
        """Connect, send our connection header, read until the publisher's header has
        arrived (each read bounded by ``timeout``); returns it and the frames read with
        it (a worker thread, through :meth:`call`)."""
        sock = socket.create_connection((host, port), timeout=timeout)
        with self.lock:
            self.sock = sock  # closed by call() as this step returns, if ended meanwhile
            if self.ended:
                raise anyio.EndOfStream
        _set_nodelay(sock)
        sock.sendall(hello)
        frames: list[bytes | memoryview] = []
        splitter.sink = lambda raw: frames.append(bytes(raw))
        while not frames:
            data = sock.recv(_CLOCK_READ_BYTES)
            if not data:
                raise anyio.EndOfStream
            splitter.feed(data)
        return frames

    def read(self, splitter: FrameSplitter) -> NoReturn:
        """Read the connection until it ends, each read's frames to ``splitter`` (a
        worker thread, through :meth:`call`).

        Raises:
            anyio.EndOfStream: the publisher closed the connection, or :meth:`end`.
            OSError: the connection failed.
            Exception: what the splitter's sink raises (a malformed message).
        """
        sock = self.sock
        assert sock is not None
        sock.settimeout(None)  # a publisher may be silent for long: only end() stops it
        while True:
            data = sock.recv(_CLOCK_READ_BYTES)
            if not data:
                raise anyio.EndOfStream
            splitter.feed(data)

    def end(self) -> None:
        """Unblock a step reading the socket and close it (event loop; idempotent)."""
        with self.lock:
            self.ended = True
            sock = self.sock
            if sock is None:
                return
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            if not self.busy:
                sock.close()


_CLOCK_READ_BYTES: Final = 65536
"""Bytes one read of a clock connection takes at most."""


class _Inbound:
    """What one connection to a publisher receives, frame by frame: the publisher's
    connection header, then messages, each decoded and delivered to the bus at once
    (``TransportPublisherLink::onHeaderReceived`` / ``handleMessage``).

    Frame handling raises ``ValueError`` (malformed header or message) or
    ``TransportError`` (the publisher refused); either ends the connection.
    """

    def __init__(self, node: Ros1Transport, bus: BusLike, topic: str, uri: str) -> None:
        self.node = node
        self.topic = topic
        self.uri = uri
        self.conn_id = 0
        self.header_or_end = anyio.Event()
        self._deliver = bus.deliver_nowait
        self._scan = topic in node._scan_topics
        self._raw = node._raw_handlers.get(topic)
        self._clock = topic == node._clock_topic
        self._md5 = node._topic_md5(topic)
        self.callerid = ""
        self._decode = node._codec.decode
        self._stats = node._stats
        self._message: type[TFMessage] = TFMessage  # per publisher: tf_message_from
        self.splitter = FrameSplitter(self._frame, MAX_HEADER_BYTES, node._max_bytes)

    def _frame(self, raw: bytes | memoryview) -> None:
        # ``raw`` may be a view of the pump's read buffer: decoded here, never kept.
        if self.conn_id:
            self._stats.received += 1
            if self._raw is not None:  # a raw topic: its handler decodes (and counts)
                self._raw(bytes(raw), self.callerid)
            elif self._scan:  # WireDecodeError: counted in malformed
                self._deliver(self.topic, decode_scan(raw))
            else:
                transforms = self._decode(raw)  # WireDecodeError: counted in malformed
                self._deliver(self.topic, self._message(tuple(transforms)))
            self._stats.delivered += 1
            return
        header = decode_header(bytes(raw))
        if "error" in header:
            raise TransportError(
                f"publisher {self.uri:.200} refused {self.topic}: {header['error']:.200}"
            )
        if header.get("md5sum") not in (self._md5, "*"):
            raise ValueError(
                f"publisher {self.uri:.200} sends md5sum {header.get('md5sum')!r:.80} "
                f"on {self.topic}"
            )
        callerid = header.get("callerid") or self.uri
        self.callerid = callerid
        self._message = tf_message_from(callerid)
        self.conn_id = self.node._open_conn(callerid, "i", self.topic)
        self.node._delivering.add((self.topic, self.uri))
        if self._clock:  # kept newest-only, delivered by the node (its _drain_clock)
            self.splitter.sink = self.node._clock_frame
        elif self._raw is None and not self._scan:
            self.splitter.sink = self._tf_sink()
        self.header_or_end.set()

    def _tf_sink(self) -> Callable[[bytes | memoryview], None]:
        """What handles each later frame of a ``TFMessage`` topic: :meth:`_frame`'s
        ``TFMessage`` branch with what it reads bound once, and the codec's compiled
        decoder called directly (``tfbus.codecs._cwire._tf_from_ros1``, where
        :meth:`TFCodec.decode <tfbus.codecs.ros1.TFCodec.decode>` goes through three
        Python calls to reach it). A frame it cannot decode is decoded again by
        ``TFCodec.decode``, which raises the ``WireDecodeError`` :meth:`_frame` would
        (counted in ``malformed``; the connection ends). Each message is built as
        ``tuple.__new__`` builds it, without the ``NamedTuple``'s Python ``__new__``."""
        stats = self._stats
        deliver = self._deliver
        topic = self.topic
        reference = self._decode
        decode = _compiled_tf_decoder() or reference
        make = tuple.__new__
        message = self._message

        def tf_frame(raw: bytes | memoryview) -> None:
            stats.received += 1
            try:
                transforms = decode(raw)
            except Exception:
                transforms = None
            if transforms is None:  # the reference raises the codec's WireDecodeError
                transforms = reference(raw)
            deliver(topic, make(message, (tuple(transforms),)))
            stats.delivered += 1

        return tf_frame


def _is_global_name(topic: str) -> bool:
    """Whether ``topic`` is a global ROS graph name (``/a/b_c``)."""
    return (
        topic.startswith("/")
        and all(c.isalnum() or c in "/_" for c in topic)
        and "//" not in topic
        and not topic.endswith("/")
    )


class Ros1Transport:
    """A :class:`~tfbus.bus.Transport` that is a ROS 1 node.

    Args:
        master_uri: the ROS master's XML-RPC URI; default ``ROS_MASTER_URI``, else
            ``http://127.0.0.1:11311``.
        node_name: this node's name (caller id); default ``/tfbus_<pid>_<random>``
            (a master shuts down an older node of the same name).
        host: the address this node's servers bind and advertise; default ``ROS_IP``,
            else ``ROS_HOSTNAME``, else ``127.0.0.1``.
        topics: the topics carried (default ``/tf`` and ``/tf_static``).
        scan_topics: ``sensor_msgs/LaserScan`` topics to subscribe to (e.g. ``/scan``):
            each message is delivered to the bus as a
            :class:`~tfbus.sensor_msgs.LaserScan` (:func:`~tfbus.codecs.ros1.decode_scan`;
            a malformed one closes its connection and is counted in ``malformed``).
            Receive only: a LaserScan published on the bus is not sent to ROS 1.
        clock_topic: a ``rosgraph_msgs/Clock`` topic to subscribe to (``"/clock"`` for
            simulated time, :data:`~tfbus.topics.CLOCK_TOPIC`): each message is delivered
            to the bus as a :class:`~tfbus.messages.Clock`
            (:func:`~tfbus.codecs.ros1.decode_clock`), what a
            :class:`~tfbus.clock.SimClock` on the bus follows (newest-only while one
            does: :meth:`keep_newest`; each connection of the topic is read by a thread
            of its own); default ``None``: not subscribed. Receive only.
        queue_size: frames queued per subscriber connection before the oldest is dropped.
        max_message_bytes: largest accepted TCPROS frame; a larger one closes the
            connection (counted as malformed).
        master_timeout: seconds an XML-RPC call (to the master or a publisher) may take
            in all: connect, send and the whole answer.
        master_check_period: seconds between checks that the master still knows this
            node (re-registration after a master restart; roscpp never checks). Each
            check is a new TCP connection and an XML-RPC call, about 2 ms of CPU here:
            every 5 s by default. A master that is unreachable or answers badly is
            retried every ``min(master_check_period, 1.0)`` s until it answers.
        allow_remote: contact publishers outside loopback even when ``host`` is loopback.

    Raises:
        ValueError: a ``master_uri`` that is not ``http://host:port``, a node name that
            is not a ROS graph name, or a scan topic or the clock topic that is also
            carried otherwise or is not a global ROS graph name.
    """

    def __init__(
        self,
        master_uri: str | None = None,
        node_name: str | None = None,
        host: str | None = None,
        *,
        topics: Sequence[str] = _TOPICS,
        scan_topics: Sequence[str] = (),
        clock_topic: str | None = None,
        queue_size: int = 100,
        max_message_bytes: int = 16 * 1024 * 1024,
        master_timeout: float = 2.0,
        master_check_period: float = 5.0,
        allow_remote: bool = False,
    ) -> None:
        uri = master_uri or os.environ.get("ROS_MASTER_URI") or "http://127.0.0.1:11311"
        parts = urlsplit(uri)
        if parts.scheme != "http" or not parts.hostname or parts.port is None:
            raise ValueError(f"master_uri must be http://host:port, got {uri!r}")
        name = node_name or _default_name()
        if not name.startswith("/"):
            name = "/" + name
        if not all(c.isalnum() or c in "/_" for c in name) or "//" in name:
            raise ValueError(f"node_name {name!r} is not a ROS graph name")
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1, got {queue_size!r}")
        self._master_uri = uri
        self._name = name
        self._host = _resolve_host(host)
        self._topics = tuple(topics)
        self._scan_topics = tuple(dict.fromkeys(scan_topics))
        for topic in self._scan_topics:
            if topic in self._topics:
                raise ValueError(f"scan topic {topic!r} is already carried as a tf topic")
            if not _is_global_name(topic):
                raise ValueError(f"scan topic {topic!r} is not a global ROS graph name")
        if clock_topic is not None:
            if clock_topic in self._topics or clock_topic in self._scan_topics:
                raise ValueError(f"clock topic {clock_topic!r} is already carried")
            if not _is_global_name(clock_topic):
                raise ValueError(f"clock topic {clock_topic!r} is not a global ROS graph name")
        self._clock_topic = clock_topic
        self._subscribed = self._topics + self._scan_topics + (
            () if clock_topic is None else (clock_topic,)
        )
        # topics of other ROS 1 types, carried as serialised bytes (subscribe_raw /
        # advertise_raw): topic -> (type, md5sum); the subscribed ones' handlers
        self._raw_types: dict[str, tuple[str, str]] = {}
        self._raw_handlers: dict[str, RawHandler] = {}
        self._registered_sub: set[str] = set()
        self._scan_definition = scan_definition() if self._scan_topics else ""
        self._queue_size = queue_size
        self._max_bytes = max_message_bytes
        self._timeout = master_timeout
        self._check_period = master_check_period
        self._remote_ok = allow_remote or not _is_loopback(self._host)
        self._codec = TFCodec()
        self._stats = Ros1Statistics()
        self._published: set[str] = set()
        self._registered_pub: set[str] = set()
        self._latched: dict[str, dict[str, TransformStamped]] = {}
        self._latched_frame: dict[str, bytes] = {}
        self._outgoing: dict[str, list[_Outgoing]] = {}
        self._incoming: dict[tuple[str, str], anyio.CancelScope] = {}
        # (topic, publisher URI) whose TCPROS header was accepted: kept first and asked
        # again without queueing behind new, unproven publishers
        self._delivering: set[tuple[str, str]] = set()
        self._bus_info: dict[int, list[Any]] = {}
        self._next_conn = 0
        self._tg: anyio.abc.TaskGroup | None = None
        self._request_limiter: anyio.CapacityLimiter | None = None
        self._update_seq: dict[str, int] = {}
        self._tcp_port = 0
        self._api_uri = ""
        self._registered = False
        self._need_register = anyio.Event()
        self._shutdown_reason: str | None = None
        self._running = False
        self._bus: BusLike | None = None
        # clock_topic: read by each connection's own thread, kept newest-only while a
        # SimClock follows it (keep_newest), handed to the loop through this wake-up
        self._newest = NewestClock()
        self._clock_wakeup: ThreadWakeup | None = None

    # -- public ------------------------------------------------------------------------

    def node_label(self) -> tuple[str, str]:
        """(the caller id, the caller id): a ROS 1 node is known by its name
        (:class:`~tfbus.transports._base.NodeLabelled`)."""
        return self.node_name, self.node_name

    @property
    def node_name(self) -> str:
        """This node's caller id, e.g. ``/tfbus_1234_a1b2c3``."""
        return self._name

    @property
    def master_uri(self) -> str:
        """The master this node registers with."""
        return self._master_uri

    @property
    def uri(self) -> str:
        """This node's slave API URI (empty until running)."""
        return self._api_uri

    @property
    def registered(self) -> bool:
        """Whether the master currently knows this node's topics."""
        return self._registered

    def statistics(self) -> Ros1Statistics:
        """A copy of the counters (see :class:`Ros1Statistics`)."""
        newest = self._newest
        with newest.lock:  # the clock threads count under it: one consistent copy
            return replace(self._stats, received=self._stats.received + newest.taken,
                           kept=int(newest.kept is not None))

    def keep_newest(self, topic: str, due: Callable[[int], bool]) -> ClockFollower:
        """Deliver ``clock_topic`` newest-only (as rclpy's ``TimeSource`` subscribes to
        ``/clock`` keep-last 1, ``time_source.py``; rospy delivers every message): the
        thread reading each clock connection decodes each message and keeps only the
        newest, waking the event loop when ``due(stamp_ns)`` (called in that thread,
        must not block) is true, when a stamp is earlier than the previous one (a jump
        back: the kept message and it are delivered in order), or
        :data:`~tfbus.transports._newest.NEWEST_MAX_DELAY` after the last wake-up while
        the bus has listeners on the topic besides the followers; every wake-up also
        delivers whatever is kept. The stamp of the newest message kept is the
        follower's :attr:`~tfbus.transports._newest.ClockFollower.newest_ns`, which a
        :class:`~tfbus.clock.SimClock` on a ROS 1 bus reads as its time: the loop runs
        when a sleeper's deadline is reached, not at every ``/clock``. Messages replaced
        before the loop saw them are counted in ``coalesced``. Several followers may
        keep the topic: a message is due when one says so.

        Args:
            topic: the topic; any other than ``clock_topic`` gets an inert follower.
            due: ``due(stamp_ns) -> bool``, whether a message must reach the loop now.

        Returns:
            the follower: ``poke()`` after filing a deadline, ``close()`` to end it.
        """
        if topic != self._clock_topic:
            return ClockFollower(None, self._wake_clock, due)
        self._newest.follow(due)
        return ClockFollower(self._newest, self._wake_clock, due)

    def serve_lookups(self, buffer: Buffer, bus: object, *, name: str = "/tf2_buffer_server",
                      max_pending: int = 1000, max_wait: float = 60.0) -> LookupActionServer:
        """tf2_ros ``buffer_server`` on this node: the ``tf2_msgs/LookupTransform``
        action ``name`` answering from ``buffer``
        (:class:`~tfbus.transports.ros1.action.LookupActionServer`; ``bus`` is the open
        bus this transport runs under); :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            ValueError: as :class:`~tfbus.transports.ros1.action.LookupActionServer`.
        """
        from tfbus.transports.ros1.action import LookupActionServer

        return LookupActionServer(self, buffer, name=name, max_pending=max_pending,
                                  max_wait=max_wait)

    def lookup_client(self, bus: object, *, name: str = "/tf2_buffer_server",
                      timeout_padding: float = 2.0,
                      max_wait: float = 3600.0) -> LookupActionClient:
        """tf2_ros ``BufferClient`` on this node: goals of the ``LookupTransform`` action
        ``name`` (:class:`~tfbus.transports.ros1.action.LookupActionClient`);
        :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            ValueError: as :class:`~tfbus.transports.ros1.action.LookupActionClient`.
        """
        from tfbus.transports.ros1.action import LookupActionClient

        return LookupActionClient(self, name=name, timeout_padding=timeout_padding,
                                  max_wait=max_wait)

    def __repr__(self) -> str:
        return f"Ros1Transport(master_uri={self._master_uri!r}, node_name={self._name!r})"

    async def run(
        self,
        bus: BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Serve TCPROS and the slave API, register with the master (retrying until it
        answers), report started, then deliver remote messages until cancelled.

        Unregisters from the master (best effort) and closes every connection on exit.

        Raises:
            RuntimeError: if this transport is already running.
            TransportError: if this node's servers cannot bind ``host``, or the master
                asked this node to shut down (another node took its name).
        """
        if self._running:
            raise RuntimeError("this Ros1Transport is already running")
        self._running = True
        self._bus = bus
        try:
            listener = await anyio.create_tcp_listener(local_host=self._host, local_port=0)
        except OSError as exc:
            self._running = False
            raise TransportError(f"cannot listen for TCPROS on {self._host}: {exc}") from exc
        api_listener: MultiListener[anyio.abc.SocketStream] | None = None
        try:
            try:
                api = await anyio.create_tcp_listener(local_host=self._host, local_port=0)
            except OSError as exc:
                raise TransportError(f"cannot serve the slave API on {self._host}: {exc}") from exc
            api_listener = api
            self._tcp_port = listener.extra(anyio.abc.SocketAttribute.local_port)
            api_port = api.extra(anyio.abc.SocketAttribute.local_port)
            self._api_uri = f"http://{self._host}:{api_port}/"
            server = SlaveServer(self)
            self._request_limiter = anyio.CapacityLimiter(MAX_CONCURRENT_REQUESTS)
            async with anyio.create_task_group() as tg:
                self._tg = tg
                clock_topic = self._clock_topic
                if clock_topic is not None:
                    wakeup = self._clock_wakeup = ThreadWakeup()
                    self._newest.bus, self._newest.topic = bus, clock_topic
                    tg.start_soon(wakeup.serve, self._drain_clock)
                tg.start_soon(
                    serve_listener, api_listener, server.handle, "slave API", self._on_accept_error
                )
                tg.start_soon(
                    serve_listener,
                    listener,
                    self._serve_subscriber,
                    "TCPROS",
                    self._on_accept_error,
                )
                tg.start_soon(self._master_loop, bus)
                task_status.started()
                await anyio.sleep_forever()
        finally:
            self._tg = None
            if self._clock_wakeup is not None:
                self._clock_wakeup.close()
                self._clock_wakeup = None
            self._newest.bus = None
            with anyio.CancelScope(shield=True):
                if self._registered:
                    with anyio.move_on_after(_UNREGISTER_DEADLINE):
                        await self._unregister_all()
                if api_listener is not None:
                    await api_listener.aclose()
                await listener.aclose()
            self._registered = False
            self._registered_pub.clear()
            self._incoming.clear()
            self._outgoing.clear()
            self._bus_info.clear()
            self._running = False
            if self._shutdown_reason is not None:
                reason, self._shutdown_reason = self._shutdown_reason, None
                raise TransportError(f"the ROS master asked {self._name} to shut down: {reason}")

    def advertise(self, topic: str) -> None:
        """Register as a publisher of ``topic`` now, before anything is sent, as a tf2_ros
        ``TransformBroadcaster`` advertises ``/tf`` when it is constructed
        (``ros::NodeHandle::advertise``): subscribers connect meanwhile, so the first
        messages reach them. Topics this transport does not carry are ignored."""
        if topic in self._topics and topic not in self._published:
            self._published.add(topic)
            self._need_register.set()

    def send_nowait(self, topic: str, message: object) -> None:
        """Send a locally published ``TFMessage`` to every subscriber; never blocks.

        ``/tf_static`` sends the full set of static transforms this transport has sent
        so far (tf2_ros's ``StaticTransformBroadcaster``), and that set is what a later
        subscriber receives on connecting. A message that cannot be serialised is dropped
        and counted in ``send_errors``; a full subscriber queue drops its oldest frame.
        """
        if topic not in self._topics or not isinstance(message, TFMessage):
            return
        if topic not in self._published:
            self.advertise(topic)
        transforms: Iterable[TransformStamped] = message.transforms
        latching = topic in _LATCHED
        if latching:
            latched = self._latched.setdefault(topic, {})
            new = dict(latched)
            for ts in message.transforms:
                if isinstance(ts, TransformStamped) and isinstance(ts.child_frame_id, str):
                    new[ts.child_frame_id.lstrip("/")] = ts
            transforms = new.values()
        try:
            framed = self._codec.encode_framed(transforms)  # the TCPROS frame, in one join
        except (ValueError, AttributeError, TypeError) as exc:
            self._stats.send_errors += 1
            _log.warning("ros1: dropping a message on %s: %s", topic, exc)
            return
        if latching:
            self._latched[topic] = new
            self._latched_frame[topic] = framed
        for out in self._outgoing.get(topic, ()):
            self._stats.send_dropped += out.frames.put(framed)

    # -- topics of other types, as serialised bytes ---------------------------------------

    def _check_raw(self, topic: str, msg_type: str, md5: str) -> None:
        if not topic.startswith("/") or not all(c.isalnum() or c in "/_" for c in topic) \
                or "//" in topic or topic.endswith("/"):
            raise ValueError(f"topic {topic!r} is not a global ROS graph name")
        if topic in self._topics or topic in self._scan_topics:
            raise ValueError(f"topic {topic!r} is already carried as a tf or scan topic")
        if self._raw_types.get(topic, (msg_type, md5)) != (msg_type, md5):
            raise ValueError(f"topic {topic!r} is carried as {self._raw_types[topic][0]} "
                             f"already, not {msg_type}")
        if not msg_type or "/" not in msg_type or len(md5) != 32:
            raise ValueError(f"msg_type {msg_type!r} / md5sum {md5!r} is not a ROS 1 "
                             "message type (package/Name) with its 32-digit md5sum")

    def subscribe_raw(self, topic: str, msg_type: str, md5: str, handler: RawHandler) -> None:
        """Subscribe to ``topic`` of ROS 1 type ``msg_type`` (md5sum ``md5``) on this
        node: each message's serialised bytes go to ``handler(payload, callerid)`` in
        the event loop, as they arrive (e.g. an actionlib client's ``result`` and
        ``status``: :class:`tfbus.compat.tf2_ros.BufferClient`). Registered with the
        master now if the node runs, else when it registers. One handler per topic;
        the handler decodes, and counts and drops what does not decode (an exception
        from it closes that connection, counted in ``malformed``).

        Raises:
            ValueError: ``topic`` is not a global graph name, is ``/tf``, ``/tf_static``
                or a scan topic, is subscribed already, or the type is not
                ``package/Name`` with a 32-digit md5sum.
        """
        self._check_raw(topic, msg_type, md5)
        if topic in self._raw_handlers:
            raise ValueError(f"topic {topic!r} is subscribed already")
        self._raw_types[topic] = (msg_type, md5)
        self._raw_handlers[topic] = handler
        self._subscribed = (*self._subscribed, topic)
        self._need_register.set()

    def advertise_raw(self, topic: str, msg_type: str, md5: str) -> None:
        """Register as a publisher of ``topic`` of ROS 1 type ``msg_type`` (md5sum
        ``md5``), sent with :meth:`send_raw_nowait` (e.g. an actionlib client's ``goal``
        and ``cancel``).

        Raises:
            ValueError: as :meth:`subscribe_raw`.
        """
        self._check_raw(topic, msg_type, md5)
        self._raw_types[topic] = (msg_type, md5)
        if topic not in self._published:
            self._published.add(topic)
            self._need_register.set()

    def send_raw_nowait(self, topic: str, payload: bytes) -> None:
        """Queue ``payload`` (one serialised message of the type :meth:`advertise_raw`
        gave) for every subscriber of ``topic`` connected now; never blocks (a full
        queue drops its oldest frame, counted in ``send_dropped``).

        Raises:
            ValueError: ``topic`` was not advertised with :meth:`advertise_raw`.
        """
        if topic not in self._raw_types or topic not in self._published:
            raise ValueError(f"topic {topic!r} is not advertised with advertise_raw")
        framed = frame(payload)
        for out in self._outgoing.get(topic, ()):
            self._stats.send_dropped += out.frames.put(framed)

    def connections(self, topic: str) -> tuple[int, int]:
        """``(publishers, subscribers)`` of ``topic`` connected to this node now: the
        publishers whose connection header was accepted and the subscribers connected
        to ours (actionlib's ``wait_for_server`` asks as much)."""
        publishers = sum(1 for t, _ in self._delivering if t == topic)
        return publishers, len(self._outgoing.get(topic, ()))

    # -- master ------------------------------------------------------------------------

    async def _master_loop(self, bus: BusLike) -> None:
        """Register, keep registered (a restarted master forgets us), follow publishers.

        Each master call has ``master_timeout`` as its deadline; a failed or junk answer
        is retried after ``min(master_check_period, 1.0)`` (junk is counted in
        ``bad_replies`` and logged once until the master answers properly again); a
        master that answers is asked again after ``master_check_period``."""
        warned = False
        while True:
            try:
                if not self._registered or not await self._still_known():
                    self._registered = False
                    self._registered_pub.clear()
                    self._registered_sub.clear()
                    await self._register_subscribers(bus)
                    self._registered = True
                    self._stats.registrations += 1
                    warned = False
                for topic in [t for t in self._subscribed if t not in self._registered_sub]:
                    await self._register_subscriber(bus, topic)
                for topic in sorted(self._published - self._registered_pub):
                    await self._register_publisher(topic)
            except TransportError as exc:
                self._registered = False
                if isinstance(exc, BadReply):
                    self._stats.bad_replies += 1
                if not warned:
                    _log.warning("ros1: master %s unusable (%s); retrying", self._master_uri, exc)
                    warned = True
            self._need_register = anyio.Event()
            # healthy: the next check after the period; else retried within a second
            wait = self._check_period if self._registered else min(self._check_period,
                                                                    _MASTER_RETRY_PERIOD)
            with anyio.move_on_after(wait):
                await self._need_register.wait()

    async def _still_known(self) -> bool:
        try:
            uri = await call(
                self._master_uri, "lookupNode", self._name, self._name, timeout=self._timeout
            )
        except CallFailed:  # the master does not know this node (restarted): register
            return False
        return bool(uri == self._api_uri)

    async def _register_subscribers(self, bus: BusLike) -> None:
        """``registerSubscriber`` per topic, following the publishers each answer lists,
        unless a ``publisherUpdate`` for that topic arrived during the call: the master
        sent it after its answer, so it is the newer list (as roscpp's
        ``TopicManager::registerSubscriber`` applies the answer under the subscription's
        lock, in order with ``pubUpdate``)."""
        for topic in self._subscribed:
            await self._register_subscriber(bus, topic)

    async def _register_subscriber(self, bus: BusLike, topic: str) -> None:
        seq = self._update_seq.get(topic, 0)
        value = await call(
            self._master_uri,
            "registerSubscriber",
            self._name,
            topic,
            self.topic_type(topic),
            self._api_uri,
            timeout=self._timeout,
        )
        if not isinstance(value, list):
            raise BadReply(f"registerSubscriber at {self._master_uri}: not a list of URIs")
        self._registered_sub.add(topic)
        if self._update_seq.get(topic, 0) == seq:
            self._update_publishers(bus, topic, [u for u in value if isinstance(u, str)])

    async def _register_publisher(self, topic: str) -> None:
        await call(
            self._master_uri,
            "registerPublisher",
            self._name,
            topic,
            self._raw_types[topic][0] if topic in self._raw_types else TF_TYPE,
            self._api_uri,
            timeout=self._timeout,
        )
        self._registered_pub.add(topic)

    async def _unregister_all(self) -> None:
        """Best effort, all at once (the caller bounds the whole in time)."""

        async def one(method: str, *args: object) -> None:
            with contextlib.suppress(TransportError):
                await call(self._master_uri, method, *args, timeout=_UNREGISTER_DEADLINE)

        async with anyio.create_task_group() as tg:
            for topic in self._subscribed:
                tg.start_soon(one, "unregisterSubscriber", self._name, topic, self._api_uri)
            for topic in list(self._registered_pub):
                tg.start_soon(one, "unregisterPublisher", self._name, topic, self._api_uri)

    # -- slave API callbacks (rpc.SlaveNode; called in the event loop) -------------------

    def bus_info(self) -> list[list[Any]]:
        """``getBusInfo``: [id, peer, direction, transport, topic, connected] per link."""
        return [list(v) for v in list(self._bus_info.values())]

    def subscriptions(self) -> Sequence[str]:
        """``getSubscriptions``: the topics this node subscribes to."""
        return self._subscribed

    def topic_type(self, topic: str) -> str:
        """The ROS 1 message type of ``topic`` (``sensor_msgs/LaserScan`` for a scan
        topic, ``rosgraph_msgs/Clock`` for the clock topic, a raw topic's own type, else
        ``tf2_msgs/TFMessage``), as ``getSubscriptions`` reports it."""
        if topic in self._raw_types:
            return self._raw_types[topic][0]
        if topic in self._scan_topics:
            return SCAN_TYPE
        return CLOCK_TYPE if topic == self._clock_topic else TF_TYPE

    def _topic_md5(self, topic: str) -> str:
        """The md5sum of :meth:`topic_type` (TCPROS connection header)."""
        if topic in self._raw_types:
            return self._raw_types[topic][1]
        if topic in self._scan_topics:
            return SCAN_MD5SUM
        return CLOCK_MD5SUM if topic == self._clock_topic else TF_MD5SUM

    def _topic_definition(self, topic: str) -> str:
        """The message definition of :meth:`topic_type` (TCPROS connection header; empty
        for a raw topic, whose definition tfbus does not know)."""
        if topic in self._raw_types:
            return ""
        if topic in self._scan_topics:
            return self._scan_definition
        return CLOCK_MSGDEF if topic == self._clock_topic else self._codec.definition

    def publications(self) -> Sequence[str]:
        """``getPublications``: the topics this node has published on so far."""
        return sorted(self._published)

    def tcpros_endpoint(self, topic: str) -> tuple[str, int] | None:
        """``requestTopic``: (host, port) of this node's TCPROS server, or None when it
        does not publish ``topic``."""
        return (self._host, self._tcp_port) if topic in self._published else None

    def on_publisher_update(self, topic: str, publishers: list[str]) -> None:
        """``publisherUpdate``: connect to new publishers of ``topic``, drop gone ones."""
        bus = self._bus
        if bus is not None and topic in self._subscribed:
            self._update_seq[topic] = self._update_seq.get(topic, 0) + 1
            self._update_publishers(bus, topic, publishers)

    def on_shutdown(self, caller_id: str, message: str) -> None:
        """``shutdown``: stop this node; :meth:`run` then raises TransportError."""
        if self._tg is not None:
            self._shutdown_reason = f"{message} (from {caller_id})"
            self._tg.cancel_scope.cancel()

    def on_bad_request(self, reason: str) -> None:
        """A refused slave API request: counted in ``bad_requests``, logged at debug."""
        self._stats.bad_requests += 1
        _log.debug("ros1: slave API: %s", reason)

    def _on_accept_error(self, exc: OSError) -> None:
        self._stats.accept_errors += 1

    # -- subscriber side: connect to publishers -------------------------------------------

    def _update_publishers(self, bus: BusLike, topic: str, uris: list[str]) -> None:
        """Follow exactly the publishers ``uris`` of ``topic`` (an answer of the master or
        a ``publisherUpdate``): at most :data:`MAX_PUBLISHERS`, those that delivered
        first, then those already followed, then new ones; none outside loopback unless
        allowed (``refused_hosts``). A publisher that delivered asks ``requestTopic``
        again outside the :data:`MAX_CONCURRENT_REQUESTS` queue, so thousands of new
        URIs that never answer cannot starve it."""
        wanted: dict[str, None] = {}
        current = {k[1] for k in self._incoming if k[0] == topic}
        listed = [uri for uri in dict.fromkeys(uris) if uri != self._api_uri]
        for uri in listed:
            if (topic, uri) in self._delivering and uri in current:
                wanted[uri] = None
        fresh = []
        for uri in listed:
            if uri in current:
                if len(wanted) < MAX_PUBLISHERS:
                    wanted[uri] = None
                elif uri not in wanted:
                    fresh.append(uri)  # (over the bound: dropped and counted below)
            else:
                fresh.append(uri)
        for uri in fresh:
            if len(wanted) >= MAX_PUBLISHERS:
                self._stats.publishers_dropped += len(fresh) - fresh.index(uri)
                _log.warning(
                    "ros1: %s: following %d publishers at most; %d more dropped",
                    topic,
                    MAX_PUBLISHERS,
                    len(fresh) - fresh.index(uri),
                )
                break
            if not self._remote_ok:
                host = _uri_host(uri)
                if host is not None and not _is_loopback(host):
                    self._stats.refused_hosts += 1
                    _log.debug("ros1: not contacting %s (outside loopback)", uri[:200])
                    continue
            wanted[uri] = None
        for key in [k for k in self._incoming if k[0] == topic and k[1] not in wanted]:
            self._incoming.pop(key).cancel()
        self._delivering = {k for k in self._delivering if k[0] != topic or k[1] in wanted}
        tg = self._tg
        if tg is None:
            return
        for uri in wanted:
            if (topic, uri) not in self._incoming:
                scope = anyio.CancelScope()
                self._incoming[(topic, uri)] = scope
                tg.start_soon(self._subscribe, bus, topic, uri, scope)

    async def _subscribe(
        self, bus: BusLike, topic: str, uri: str, scope: anyio.CancelScope
    ) -> None:
        """Keep one publisher connected: retry with back-off while it is still listed."""
        with scope:
            delay = 0.1
            for _attempt in range(50):
                try:
                    await self._receive_from(bus, topic, uri)
                    delay = 0.1  # a connection that ended cleanly: reconnect promptly
                except BadReply as exc:  # its XML-RPC answer: retried with back-off
                    self._stats.bad_replies += 1
                    _log.debug("ros1: %s from %s: %s", topic, uri[:200], exc)
                except (
                    OSError,
                    TimeoutError,
                    TransportError,
                    anyio.EndOfStream,
                    anyio.IncompleteRead,
                    anyio.BrokenResourceError,
                ) as exc:
                    _log.debug("ros1: %s from %s: %s", topic, uri[:200], exc)
                except (ValueError, TypeError) as exc:  # malformed header or frame:
                    # this connection only
                    self._stats.malformed += 1
                    _peer_log.log(logging.WARNING, "ros1: closing %s from %s: %s", topic,
                                  uri[:200], exc)
                await anyio.sleep(delay)
                delay = min(delay * 2, 2.0)
        if self._incoming.get((topic, uri)) is scope:
            del self._incoming[(topic, uri)]

    async def _request_topic(self, topic: str, uri: str) -> tuple[str, int]:
        """``requestTopic`` at ``uri`` (at most :data:`MAX_CONCURRENT_REQUESTS` at once):
        the TCPROS (host, port) offered.

        Raises:
            BadReply: no ``["TCPROS", host, port]`` with a port in 1..65535.
            TransportError: no answer, or a host outside loopback (``refused_hosts``).
        """
        limiter = self._request_limiter
        if limiter is None:
            raise TransportError("the node is not running")
        proven = (topic, uri) in self._delivering
        async with contextlib.nullcontext() if proven else limiter:
            reply = await call(
                uri, "requestTopic", self._name, topic, [["TCPROS"]], timeout=self._timeout
            )
        if not (isinstance(reply, list) and len(reply) >= 3 and reply[0] == "TCPROS"):
            raise BadReply(f"requestTopic at {uri:.200}: no TCPROS endpoint in {reply!r:.200}")
        host, port = reply[1], reply[2]
        if not isinstance(host, str) or not host or len(host) > 255:
            raise BadReply(f"requestTopic at {uri:.200}: bad host {host!r:.80}")
        if not isinstance(port, int) or isinstance(port, bool) or not 0 < port < 65536:
            raise BadReply(f"requestTopic at {uri:.200}: port {port!r:.40} not in 1..65535")
        if not self._remote_ok and not _is_loopback(host):
            self._stats.refused_hosts += 1
            raise TransportError(
                f"publisher {uri:.200} offers {host}:{port}, outside loopback (allow_remote=False)"
            )
        return host, port

    async def _receive_from(self, bus: BusLike, topic: str, uri: str) -> None:
        """One connection to the publisher at ``uri`` (roscpp's
        ``TransportPublisherLink``): ``requestTopic``, connect, send our connection
        header (asking for ``tcp_nodelay``, as ``ros::TransportHints().tcpNoDelay()``
        does; the publisher then sets TCP_NODELAY, ``TransportTCP::parseHeader``), check
        the publisher's header, then deliver each message until the connection ends.

        Raises:
            BadReply: the publisher's XML-RPC answer is junk (the caller counts it).
            TransportError, OSError, anyio.EndOfStream: the connection could not be
                made or ended (the caller retries).
            ValueError: a malformed header or frame (the caller counts it).
        """
        host, port = await self._request_topic(topic, uri)
        link = _Inbound(self, bus, topic, uri)
        hello = encode_header(
            {
                "callerid": self._name,
                "topic": topic,
                "md5sum": self._topic_md5(topic),
                "type": self.topic_type(topic),
                "message_definition": self._topic_definition(topic),
                "tcp_nodelay": "1",
            }
        )
        try:
            loop = running_asyncio_loop()  # None under trio, also in guest mode
            if topic == self._clock_topic:
                await self._pump_clock(link, host, port, hello)
            elif loop is not None:
                await self._pump_asyncio(loop, link, host, port, hello)
            else:
                await self._pump_stream(link, host, port, hello)
        finally:
            if link.conn_id:
                self._close_conn(link.conn_id)

    async def _pump_clock(self, link: _Inbound, host: str, port: int, hello: bytes) -> None:
        """The clock topic, on any backend: the connection is read by a thread of its
        own (roscpp reads in its poll thread too), which decodes each message and keeps
        it newest-only while a :class:`~tfbus.clock.SimClock` follows the topic
        (:meth:`keep_newest`), waking the event loop only when one is due, or for every
        message when none follows; the connection header is checked in the event loop.
        A ``/clock`` at 1 kHz then costs no event-loop wake-up per message."""
        timeout = max(self._timeout, 1.0)
        conn = _ClockConnection()
        # the connection's own thread: not one of anyio's default pool for its lifetime
        run = functools.partial(anyio.to_thread.run_sync, abandon_on_cancel=True,
                                limiter=anyio.CapacityLimiter(1))
        try:
            with anyio.fail_after(timeout):
                frames = await run(conn.call, conn.open, host, port, hello, timeout,
                                   link.splitter)
            # the header: refused or wrong md5sum raise here; it makes the splitter's
            # sink self._clock_frame, which the reads below feed
            link._frame(frames[0])
            for raw in frames[1:]:  # messages read with the header
                self._clock_frame(raw)
            await run(conn.call, conn.read, link.splitter)
        finally:
            conn.end()

    def _clock_frame(self, raw: bytes | memoryview) -> None:
        """One message of a clock connection (its thread): decoded, then kept or queued
        for the event loop (:class:`~tfbus.transports._newest.NewestClock`).

        Raises:
            WireDecodeError: not a ``rosgraph_msgs/Clock`` (the connection ends; counted
                in ``malformed``).
        """
        newest = self._newest
        try:
            message = decode_clock(raw)
        except Exception:
            with newest.lock:
                newest.taken += 1  # received, then counted malformed by the caller
            raise
        with newest.lock:
            newest.taken += 1
            wake = newest.offer(message, self._stats)
        if wake:
            self._wake_clock()

    def _wake_clock(self) -> None:
        """Wake the loop to deliver what the newest-only clock holds (any thread)."""
        wakeup = self._clock_wakeup
        if wakeup is not None:
            wakeup.wake()

    def _drain_clock(self, woken: bool) -> bool:
        """Deliver the clock messages the connections' threads queued and the one kept
        (event loop)."""
        newest = self._newest
        with newest.lock:
            held = newest.take_all()
            taken, newest.taken = newest.taken, 0
        stats = self._stats
        stats.received += taken
        bus, topic = self._bus, self._clock_topic
        if held and bus is not None and topic is not None:
            bus.deliver_many_nowait(topic, held)
            stats.delivered += len(held)
        return False

    async def _pump_asyncio(
        self, loop: asyncio.AbstractEventLoop, link: _Inbound, host: str, port: int, hello: bytes
    ) -> None:
        """On asyncio: an :class:`asyncio.Protocol` splits, decodes and delivers in the
        event loop's read callback (roscpp does its reads in the poll thread,
        ``Connection::readTransport``), so a message costs no task wake-up before the
        subscriber's own; this task only waits for the connection to end."""
        timeout = max(self._timeout, 1.0)
        ended = anyio.Event()
        with anyio.fail_after(timeout):
            transport, pump = await open_pumped_connection(
                loop, host, port, link.splitter.feed, ended, link.header_or_end
            )
        try:
            _set_nodelay(transport.get_extra_info("socket"))
            transport.write(hello)
            with anyio.fail_after(timeout):
                await link.header_or_end.wait()
            await ended.wait()
            raise pump.error if pump.error is not None else anyio.EndOfStream
        finally:
            transport.abort()

    async def _pump_stream(self, link: _Inbound, host: str, port: int, hello: bytes) -> None:
        """Any other anyio backend (trio): receive as much as is there, split, deliver."""
        timeout = max(self._timeout, 1.0)
        with anyio.fail_after(timeout):
            stream = await anyio.connect_tcp(host, port)
        async with stream:
            _set_nodelay(stream.extra(anyio.abc.SocketAttribute.raw_socket))
            await stream.send(hello)
            feed = link.splitter.feed
            with anyio.fail_after(timeout):
                while not link.conn_id:
                    feed(await stream.receive())
            while True:
                feed(await stream.receive())

    def _open_conn(self, peer: str, direction: str, topic: str) -> int:
        self._next_conn += 1
        self._bus_info[self._next_conn] = [self._next_conn, peer, direction, "TCPROS", topic, True]
        self._stats.connections_opened += 1
        return self._next_conn

    def _close_conn(self, conn_id: int) -> None:
        if self._bus_info.pop(conn_id, None) is not None:
            self._stats.connections_closed += 1

    # -- publisher side: subscribers connect to us ------------------------------------------

    async def _serve_subscriber(self, stream: anyio.abc.SocketStream) -> None:
        async with stream:
            try:
                with anyio.fail_after(max(self._timeout, 1.0)):
                    header = decode_header(
                        await read_frame(
                            BufferedByteReceiveStream(stream),
                            MAX_HEADER_BYTES,
                            "connection header",
                        )
                    )
            except (ValueError, struct.error) as exc:
                self._stats.malformed += 1
                _peer_log.log(logging.WARNING, "ros1: bad connection header from a subscriber: %s",
                              exc)
                return
            except (
                TimeoutError,
                OSError,
                anyio.EndOfStream,
                anyio.IncompleteRead,
                anyio.BrokenResourceError,
            ):
                return
            topic = header.get("topic", "")
            md5 = header.get("md5sum", "")
            ours = self._topic_md5(topic)
            if topic not in self._published or md5 not in (ours, "*"):
                why = (
                    f"{self._name} does not publish {topic!r:.200}"
                    if topic not in self._published
                    else f"md5sum mismatch: {md5!r:.80} != {ours}"
                )
                with contextlib.suppress(OSError, anyio.BrokenResourceError):
                    await stream.send(encode_header({"error": why}))
                return
            if header.get("tcp_nodelay") == "1":
                with contextlib.suppress(OSError):
                    stream.extra(anyio.abc.SocketAttribute.raw_socket).setsockopt(
                        socket.IPPROTO_TCP, socket.TCP_NODELAY, 1
                    )
            latching = topic in _LATCHED
            raw = topic in self._raw_types
            reply = {
                "callerid": self._name,
                "md5sum": ours,
                "type": self.topic_type(topic),
                "message_definition": "" if raw else self._codec.definition,
                "latching": "1" if latching else "0",
                "topic": topic,
            }
            try:
                await stream.send(encode_header(reply))
            except (OSError, anyio.BrokenResourceError):
                return
            if header.get("probe") == "1":
                return
            out = _Outgoing(topic, header.get("callerid", "?"), self._queue_size)
            if latching and topic in self._latched_frame:
                out.frames.put(self._latched_frame[topic])
            out.conn_id = self._open_conn(out.peer, "o", topic)
            self._outgoing.setdefault(topic, []).append(out)
            try:
                await serve_subscriber(stream, out.frames, self._count_sent)
            finally:
                with contextlib.suppress(ValueError):
                    self._outgoing.get(topic, []).remove(out)
                self._close_conn(out.conn_id)

    def _count_sent(self) -> None:
        self._stats.sent += 1
