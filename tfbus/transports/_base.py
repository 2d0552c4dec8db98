"""What every transport shares: the bus it feeds, the thread-to-loop wake-up, the common
statistics counters and the :class:`PeerAware` protocol.

* :class:`BusLike` -- the part of :class:`~tfbus.bus.Bus` a transport calls
  (``deliver_nowait`` / ``deliver_many_nowait``), so a transport's ``run`` can be
  driven by a test double as well as by a bus.
* :class:`ThreadWakeup` -- a middleware thread (Zenoh's callbacks, Cyclone's listener)
  signals the event loop through a socket pair: the thread writes one byte when no
  wake-up is pending, and the loop drains whatever the middleware queued -- one
  wake-up per burst (:meth:`ThreadWakeup.serve`: in asyncio's read callback of the
  socket, or after ``anyio.wait_readable`` on trio).
* :class:`TransportStatistics` -- the counters every transport has, with one meaning
  each (each transport's statistics class adds its own).
* :class:`PeerAware` -- what a transport that knows its peers (Zenoh's liveliness)
  offers; the command line asks ``isinstance(transport, PeerAware)``, never a scheme name.
* :class:`LookupServing` -- a transport that serves and asks transform lookups
  (tf2_ros's ``buffer_server`` / ``BufferClient``) over its own middleware: Zenoh (a
  queryable), ROS 1 (the ``LookupTransform`` action on the transport's node), ROS 2 (the
  ``LookupTransform`` action over DDS on the transport's participant);
  :class:`tfbus.remote.BufferServer` and :class:`tfbus.remote.BufferClient` ask
  ``isinstance(transport, LookupServing)``. Counted in :class:`ServerStatistics`.
* :class:`Backlogged` -- a transport whose middleware threads queue received messages
  for the event loop says how many still wait (``tfbus view`` draws only when the
  intake is caught up).

A new transport copies the template of ``docs/architecture.md`` ("Adding a transport").
"""

from __future__ import annotations

import math
import os
import socket
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Any,
    Final,
    NamedTuple,
    NoReturn,
    Protocol,
    TypeVar,
    runtime_checkable,
)

import anyio
import anyio.lowlevel

from tfbus._aio import running_asyncio_loop
from tfbus.errors import InvalidArgumentException, TimeoutException
from tfbus.time import Duration
from tfbus.topics import PEERS_TOPIC, TF_TOPICS

if TYPE_CHECKING:
    from asyncio import AbstractEventLoop, Handle

    from tfbus.buffer import Buffer
    from tfbus.messages import TransformStamped
    from tfbus.time import Time

__all__ = [
    "DEFAULT_MAX_WAIT",
    "DEFAULT_SERVER_NAME",
    "DOMAIN_ID_MAX",
    "LOOKUPS_OWN_ERROR",
    "MAX_FRAME_ID_BYTES",
    "PEERS_TOPIC",
    "Backlogged",
    "BusLike",
    "LookupClient",
    "LookupServer",
    "LookupServing",
    "NodeLabelled",
    "PeerAware",
    "PeerEvent",
    "PeerInfo",
    "ServerStatistics",
    "ThreadWakeup",
    "TransportStatistics",
]


class BusLike(Protocol):
    """The bus as a transport sees it (:class:`~tfbus.bus.Bus` implements it)."""

    def deliver_nowait(self, topic: str, message: object) -> None:
        """Deliver one remote message to the local subscribers."""

    def deliver_many_nowait(self, topic: str, messages: Iterable[object]) -> None:
        """Deliver several remote messages of one topic, in order."""

    def reaches(self, topic: str) -> bool:
        """Whether a message delivered on ``topic`` now reaches anyone (a subscriber,
        or a latch keeping it for subscribers to come)."""



def heard_beyond(bus: object, topic: str, followers: int) -> bool:
    """Whether ``topic`` has listeners on ``bus`` besides its ``followers`` newest-only
    followers (a :class:`~tfbus.clock.SimClock` each, with one callback on the topic):
    such listeners get the topic at least every ``NEWEST_MAX_DELAY`` of the transport.
    True for a bus that cannot tell (no ``listeners``). Safe from a transport's thread
    (two reads of the bus's tables)."""
    listeners = getattr(bus, "listeners", None)
    return listeners is None or int(listeners(topic)) > followers


_TF_TOPICS: Final = frozenset(TF_TOPICS)


class PeerEvent(NamedTuple):
    """A remote node or one of its published topics appeared or disappeared.

    Attributes:
        alive: True when it appeared, False when it went away (closed or died).
        node_id: the remote node's id (Zenoh: its session id, hex), unique per process run.
        name: the node's name (Zenoh: ``ZenohTransport(name=...)``, default ``prog-pid``).
        topic: the topic the remote started/stopped publishing, or ``""`` for the node.
    """

    alive: bool
    node_id: str
    name: str
    topic: str = ""


@dataclass(frozen=True, slots=True)
class PeerInfo:
    """A live remote node (a :class:`PeerAware` transport's ``broadcasters()``).

    Attributes:
        node_id: the remote node's id (Zenoh: its session id, hex).
        name: its name.
        topics: the topics it has published so far (a broadcaster has ``/tf`` and/or
            ``/tf_static``).
    """

    node_id: str
    name: str
    topics: frozenset[str] = frozenset()

    @property
    def is_broadcaster(self) -> bool:
        """True if it has published ``/tf`` or ``/tf_static`` (on a fleet bus,
        ``namespace=*``: ``/robot7/tf`` or ``/robot7/tf_static``)."""
        return any(t in _TF_TOPICS or t.endswith(TF_TOPICS) for t in self.topics)


@runtime_checkable
class NodeLabelled(Protocol):
    """A transport that makes a named node (Zenoh, ROS 1, ROS 2; not ``memory``)."""

    def node_label(self) -> tuple[str, str]:
        """(the node's name or ``""``, its id on the network or ``""``), for log lines."""
        ...


@runtime_checkable
class PeerAware(Protocol):
    """A transport that knows the other processes on its network (Zenoh's liveliness).

    It delivers a :class:`PeerEvent` on the local bus topic :attr:`peers_topic` whenever a
    peer appears, disappears or starts/stops publishing a topic. The command line asks
    ``isinstance(transport, PeerAware)`` (a runtime-checkable Protocol) instead of
    testing a scheme name.

    A transport may also have ``peers_version``, an int that changes whenever its peers
    or their topics may have changed (Zenoh's and rmw_zenoh's have): a reader that
    derives something from :meth:`broadcasters` for every message (the command line's
    sender of each message) reads them again only when it changed.
    """

    peers_topic: str
    """The local bus topic of the :class:`PeerEvent` messages (:data:`PEERS_TOPIC`)."""

    @property
    def node_id(self) -> str:
        """This transport's id as its peers see it (``""`` while not running)."""
        ...

    def broadcasters(self) -> Mapping[str, PeerInfo]:
        """The live peers that have published ``/tf`` or ``/tf_static``, by node id."""
        ...


@runtime_checkable
class Backlogged(Protocol):
    """A transport that queues what its middleware threads receive for the event loop
    (Zenoh's inbound queue): :attr:`pending` says how much is not delivered yet. A
    consumer with optional work (``tfbus view``'s redraws) asks
    ``isinstance(transport, Backlogged)`` and puts that work off while the queue is not
    empty, so the queue does not grow while the work runs.
    """

    @property
    def pending(self) -> int:
        """Entries received and not yet delivered into the bus (0 when caught up)."""
        ...


DEFAULT_SERVER_NAME: Final = "tf2_buffer_server"
"""The default lookup server name: tf2_ros's ``buffer_server`` node name (ROS 1: the
action ``/tf2_buffer_server``)."""
DEFAULT_MAX_WAIT: Final = 60.0
"""Seconds a lookup server waits for one lookup at most, by default (tf2_ros's
``buffer_server`` waits for as long as the goal's timeout asks)."""

LOOKUPS_OWN_ERROR: Final = (TimeoutException, InvalidArgumentException)
"""The errors of an awaited lookup after which a lookup server answers with the
synchronous lookup's own result or error, as tf2_ros ``buffer_server.cpp``
(``checkTransforms``: once a goal's timeout expires, ``lookupTransform``'s answer). A
:class:`~tfbus.errors.TimeoutException` is that timeout. An
:class:`~tfbus.errors.InvalidArgumentException` is an argument that can never be valid (an
empty frame id, a leading ``/``): the awaited lookup refuses it at once, having checked
every argument first, whereas tf2's ``canTransform`` answers false until the timeout and
``lookupTransform`` then checks the target frame before the source; so for an unknown
target frame and an empty source frame tf2's server answers ``LookupException`` (code 1),
and so do tfbus's servers (at once: waiting cannot change the answer)."""

MAX_FRAME_ID_BYTES: Final = 1024
"""Longest frame id (UTF-8 bytes) a lookup server over Zenoh looks up. tf2 accepts any
length (``BufferCore::validateFrameId`` refuses only empty ids and a leading ``/``); real
frame ids (``base_link``, ``robot7/arm/wrist_3_link``) are tens of bytes."""


@dataclass(slots=True)
class ServerStatistics:
    """Counters of a lookup server (:class:`LookupServer`; monotonic since it was made,
    ``pending`` now), one shape on every transport.

    Attributes:
        requests: lookups received (Zenoh: queries; ROS 1: goals), valid or not.
        answered: transforms (or can_transform answers) sent back.
        errors: tf2 errors sent back (lookup, timeout, bad argument, busy on Zenoh...).
        malformed: requests dropped unanswered because they did not decode.
        busy: requests refused because the server held its most lookups (Zenoh:
            ``max_pending`` or ``max_per_peer``; ROS 1: ``max_pending``, REJECTED; ROS 2:
            ``max_pending`` or ``max_per_peer``, ``accepted=False``).
        cancelled: lookups ended because their client cancelled them or left (ROS 1:
            PREEMPTED or RECALLED by an actionlib cancel request; ROS 2: CANCELED by a
            ``cancel_goal`` request or because the client's request writer left).
        pending: lookups waiting now.
        unsendable: answers the middleware cannot carry, not sent (ROS 1: a stamp at or
            after 2**32 s; ROS 2: at or after 2**31 s, the goal ABORTED).
    """

    requests: int = 0
    answered: int = 0
    errors: int = 0
    malformed: int = 0
    busy: int = 0
    cancelled: int = 0
    pending: int = 0
    unsendable: int = 0


@runtime_checkable
class LookupServer(Protocol):
    """A running lookup server (what :meth:`LookupServing.serve_lookups` gives): an async
    context manager answering while entered."""

    @property
    def where(self) -> str:
        """Where it answers, for log lines (a Zenoh key, a ROS 1 action namespace)."""
        ...

    def statistics(self) -> ServerStatistics:
        """A copy of its counters."""
        ...

    async def __aenter__(self) -> Any:
        """Start answering."""
        ...

    async def __aexit__(self, *exc: object) -> None:
        """End answering; lookups still waiting are dropped."""
        ...


_M = TypeVar("_M")


@runtime_checkable
class LookupClient(Protocol):
    """:class:`~tfbus.buffer.Buffer`'s awaitable lookups answered by a remote server
    (what :meth:`LookupServing.lookup_client` gives): timeouts are seconds of the
    server's clock (None: the server's longest wait); the server's tf2 error is raised
    as the same :mod:`tfbus.errors` class."""

    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration | None = None, *,
                               fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform``; ``fail_fast`` as
        :meth:`tfbus.buffer.Buffer.wait_for_transform`'s, where the wire carries it."""
        ...

    async def lookup_transform_full(self, target_frame: str, target_time: Time,
                                    source_frame: str, source_time: Time, fixed_frame: str,
                                    timeout: float | Duration | None = None, *,
                                    fail_fast: bool = False) -> TransformStamped:
        """tf2_ros ``BufferClient.lookup_transform_full``."""
        ...

    async def can_transform(self, target_frame: str, source_frame: str, time: Time,
                            timeout: float | Duration | None = None, *,
                            fail_fast: bool = False) -> bool:
        """tf2_ros ``BufferClient.can_transform``."""
        ...

    async def transform(self, obj: _M, target_frame: str,
                        timeout: float | Duration | None = None, *,
                        fail_fast: bool = False) -> _M:
        """tf2_ros ``BufferClient.transform``."""
        ...


def action_client_limits(timeout_padding: float, max_wait: float) -> tuple[float, float]:
    """``(timeout_padding, max_wait)`` of a LookupTransform action client (ROS 1 and
    ROS 2) as floats: wall seconds added to each goal's timeout for the round trip, and
    the goal timeout sent for a timeout of None.

    Raises:
        ValueError: ``timeout_padding`` is negative or not finite, or ``max_wait`` is not
            positive finite.
    """
    if not 0.0 <= timeout_padding < math.inf or not 0.0 < max_wait < math.inf:
        raise ValueError(f"timeout_padding must be finite seconds >= 0 and max_wait "
                         f"positive finite seconds, got {timeout_padding!r}, {max_wait!r}")
    return float(timeout_padding), float(max_wait)


def goal_timeout(timeout: float | Duration | None, max_wait: float) -> float:
    """The seconds a LookupTransform goal carries for a client's ``timeout`` (``None``:
    ``max_wait``; tf2_msgs' ``timeout`` is a finite duration).

    Raises:
        ValueError: ``timeout`` is negative, not finite, or not seconds nor a Duration.
    """
    if timeout is None:
        return max_wait
    seconds = timeout.to_sec() if isinstance(timeout, Duration) else timeout
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
            or not 0 <= seconds < math.inf:
        raise ValueError(f"timeout must be finite seconds >= 0 or None, got {timeout!r}")
    return float(seconds)


def refuse_fail_fast(fail_fast: bool, middleware: str) -> None:
    """A ``tf2_msgs/LookupTransform`` goal (ROS 1 and ROS 2's buffer_server action) has no
    field for ``fail_fast``: refuse it, never drop it.

    Raises:
        ValueError: ``fail_fast`` is true, naming ``middleware``.
    """
    if fail_fast:
        raise ValueError(
            f"fail_fast=True cannot be sent to a {middleware} buffer_server: the "
            "tf2_msgs/LookupTransform action's goal has no such field (use a Zenoh "
            "BufferServer, or a local Buffer)")


async def transform_remotely(client: LookupClient, obj: _M, target_frame: str,
                             timeout: float | Duration | None, fail_fast: bool = False) -> _M:
    """tf2_ros ``BufferClient.transform`` for any :class:`LookupClient`: ``obj``'s
    transform is looked up remotely (``client.lookup_transform`` at its header's frame
    and stamp), then the function registered for ``type(obj)`` (:mod:`tfbus.convert`,
    ``Buffer.registration``) is applied here.

    Raises:
        TypeError: no transform function for ``type(obj)`` (before any lookup).
        The lookup's errors, as ``client.lookup_transform``.
    """
    from tfbus.buffer import Buffer, _header_of

    do_transform = Buffer.registration.get(type(obj))
    header = _header_of(obj)
    ts = await client.lookup_transform(target_frame, header.frame_id, header.stamp, timeout,
                                       fail_fast=fail_fast)
    result: _M = do_transform(obj, ts)
    return result


@runtime_checkable
class LookupServing(Protocol):
    """A transport that serves transform lookups to thin clients and asks them
    (tf2_ros ``buffer_server`` / ``BufferClient``) over its own middleware. The facade
    :mod:`tfbus.remote` asks ``isinstance(transport, LookupServing)``, never a scheme
    name; a new transport gets remote lookups by implementing these two methods."""

    def serve_lookups(self, buffer: Buffer, bus: Any, **options: Any) -> LookupServer:
        """A :class:`LookupServer` answering from ``buffer`` on this transport's
        ``bus`` (open), with the transport's options (``name``, ``max_pending``,
        ``max_wait``...).

        Raises:
            TypeError: an option this transport does not have.
            ValueError: a bad option value (named).
        """
        ...

    def lookup_client(self, bus: Any, **options: Any) -> LookupClient:
        """A :class:`LookupClient` asking the server ``name`` over ``bus`` (open).

        Raises:
            TypeError: an option this transport does not have.
            ValueError: a bad option value (named).
        """
        ...


@dataclass(slots=True)
class TransportStatistics:
    """The counters shared by every transport's statistics (monotonic since it was made).

    One meaning each, whatever the middleware: every payload taken from the network counts
    in ``received`` and then ends in ``delivered`` or in a drop counter (``malformed``, or
    a transport's own: ``wrong_version``, ``overflow``, ...).

    Attributes:
        sent: messages put on the network (ROS 1: one per subscriber connection).
        send_errors: local messages refused before sending (not encodable: a stamp out of
            the middleware's range, a message of the wrong type, ...).
        received: payloads taken from the network (valid or not).
        delivered: valid messages delivered into the bus.
        malformed: received payloads dropped because they did not decode (ROS 1: each
            also closed its connection).
    """

    sent: int = 0
    send_errors: int = 0
    received: int = 0
    delivered: int = 0
    malformed: int = 0


class ThreadWakeup:
    """Wake the event loop from a middleware thread, once per burst.

    The loop side (:meth:`serve`, or :meth:`wait` and :meth:`rearm`) runs on asyncio and
    trio; :meth:`wake` may be called from any thread and never blocks. Create it in the
    transport's ``run`` and :meth:`close` it on the way out.
    """

    def __init__(self) -> None:
        """Open the socket pair (non-blocking both ways)."""
        self._r, self._w = socket.socketpair()
        self._r.setblocking(False)
        self._w.setblocking(False)
        self._pending = False
        self._closed = False

    def wake(self) -> None:
        """Signal the loop, unless a wake-up is already pending (any thread, non-blocking)."""
        if not self._pending and not self._closed:
            self._pending = True
            try:  # noqa: SIM105 (a try, not contextlib.suppress: no object a message)
                self._w.send(b"\0")
            except OSError:  # full buffer: a wake-up is queued anyway
                pass

    def rearm(self) -> None:
        """Let the next :meth:`wake` signal again: call it *before* draining the queue,
        so nothing queued after the drain goes unnoticed."""
        self._pending = False

    async def wait(self) -> None:
        """Wait until :meth:`wake` was called, then consume the signal."""
        await anyio.wait_readable(self._r)
        try:  # noqa: SIM105 (as in wake: no suppress object a wake-up)
            self._r.recv(4096)
        except BlockingIOError:
            pass

    async def serve(self, drain: Callable[[bool], bool]) -> NoReturn:
        """Call ``drain(True)`` after each wake-up until cancelled (re-armed just before);
        ``drain`` handles a bounded batch of what the thread queued and returns True when
        more remains, and is then called again, ``drain(False)``, once the event loop's
        other ready work has run (a checkpoint between batches).

        On asyncio the socket is watched by one ``loop.add_reader`` for the whole call and
        ``drain`` runs in the loop's read callback, in the loop iteration that saw the
        wake-up: no task resumes in between, and the socket is not registered with the
        selector and removed again at every wait (what ``anyio.wait_readable`` does), so a
        wake-up costs one loop iteration fewer -- at low message rates, where every wake-up
        finds the loop idle, those are a large part of the latency. Elsewhere (trio, or an
        asyncio loop without ``add_reader``): a loop on :meth:`wait`.

        Raises:
            Exception: whatever ``drain`` raises, as itself (the watch ends).
            anyio.get_cancelled_exc_class(): when cancelled (the normal end).
        """
        loop = running_asyncio_loop()
        if loop is not None:
            await self._serve_in_reader(loop, drain)
        while True:
            await self.wait()
            self.rearm()
            more = drain(True)
            while more:
                await anyio.lowlevel.checkpoint()
                more = drain(False)

    async def _serve_in_reader(
        self, loop: AbstractEventLoop, drain: Callable[[bool], bool]
    ) -> None:
        """:meth:`serve` in asyncio's read callback; returns only if the loop has no
        ``add_reader`` (then :meth:`serve` falls back to :meth:`wait`)."""
        sock = self._r
        ended = loop.create_future()  # done with drain's exception: it ends the watch
        later: Handle | None = None  # the next batch's call, when more remains

        def run(first: bool) -> None:
            nonlocal later
            later = None
            try:
                more = drain(first)
            except Exception as exc:  # raised in the task that called serve()
                if not ended.done():
                    ended.set_exception(exc)
                return
            if more and not ended.done():
                later = loop.call_soon(run, False)

        def readable() -> None:
            try:  # noqa: SIM105 (as in wake: no suppress object a wake-up)
                sock.recv(4096)
            except (BlockingIOError, InterruptedError):
                pass
            self._pending = False  # rearm before draining: nothing queued later is missed
            if later is None and not ended.done():
                run(True)
            # else: the batch already scheduled takes what was queued

        try:
            loop.add_reader(sock, readable)
        except NotImplementedError:  # e.g. the proactor loop on Windows
            return
        try:
            await ended
        finally:
            loop.remove_reader(sock)
            if later is not None:
                later.cancel()

    def close(self) -> None:
        """Close both sockets (later :meth:`wake` calls do nothing)."""
        self._closed = True
        self._pending = False
        self._r.close()
        self._w.close()


DOMAIN_ID_MAX: Final = 232
"""Largest ROS 2 domain id: the largest DDS domain whose RTPS ports fit in 16 bits (RTPS
2.x, 9.6.1.1; ROS 2's "domain ID" concept page gives the same bound). Every ROS 2 bus
(DDS and rmw_zenoh) takes ids in 0..232."""


def ros_domain_id(domain_id: int | None) -> int:
    """The ROS 2 domain id of a bus: ``domain_id``, or when None ``ROS_DOMAIN_ID`` from
    the environment (0 when unset or blank), as rcl's ``rcl_get_default_domain_id`` reads it.

    Raises:
        ValueError: ``ROS_DOMAIN_ID`` is not an integer, or the id is not an int in
            0..:data:`DOMAIN_ID_MAX` (the message names the value).
    """
    if domain_id is None:
        env = os.environ.get("ROS_DOMAIN_ID", "").strip()
        try:
            domain_id = int(env) if env else 0
        except ValueError:
            raise ValueError(f"ROS_DOMAIN_ID must be an integer, got {env!r}") from None
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) \
            or not 0 <= domain_id <= DOMAIN_ID_MAX:
        raise ValueError(f"domain_id must be in 0..{DOMAIN_ID_MAX}, got {domain_id!r}")
    return domain_id
