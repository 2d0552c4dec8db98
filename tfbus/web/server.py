"""``tfbus web``'s WebSocket server: rosbridge's tf ops (:mod:`tfbus.web.rosbridge`) for
every client, on anyio (asyncio and trio alike) with wsproto, the sans-I/O WebSocket
protocol (RFC 6455), over anyio's TCP listener.

Every wait and each client's share is bounded:

* the opening handshake must arrive within ``handshake_timeout`` seconds and fit h11's
  16 KiB header limit; its ``Host`` and ``Origin`` are checked by the
  :class:`~tfbus.view.guard.PageGuard` ``tfbus view`` uses (refused: ``403``, counted);
  past ``max_clients`` connections a new one gets ``503``;
* each client has its own outgoing queue of ``queue_size`` messages: when it is full the
  oldest is dropped and counted (:attr:`Client.dropped`); a client that does not take a
  message within ``send_timeout`` seconds is disconnected (:attr:`TfWebServer.slow`).
  One writer task per client: a slow client delays only itself;
* a message over :data:`~tfbus.web.rosbridge.MAX_MESSAGE_BYTES` is read no further than
  that and dropped, answered with a ``status``; subscriptions, goals and source frames
  per client are capped (:mod:`tfbus.web.rosbridge`);
* a client that closes (a Close frame, RFC 6455 5.5.1) gets the Close reply and nothing
  after it: messages for it from then on, and those still queued, are dropped and counted
  (:attr:`Client.closed_drops`, :attr:`TfWebServer.dropped_closed`);
* a connection that fails in any way is closed and counted
  (:attr:`TfWebServer.errors`), logged as one line per :data:`LOG_PERIOD`, never a
  traceback; the other clients go on.
"""

from __future__ import annotations

import json
import logging
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import anyio
import anyio.abc
from wsproto import ConnectionType, WSConnection
from wsproto.connection import ConnectionState
from wsproto.events import (
    AcceptConnection,
    BytesMessage,
    CloseConnection,
    Ping,
    Pong,
    RejectConnection,
    Request,
    TextMessage,
)
from wsproto.utilities import LocalProtocolError, RemoteProtocolError

from tfbus.clock import Clock, SystemClock
from tfbus.ratelimit import RateLimitedLog
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.view.guard import PageGuard
from tfbus.web.rosbridge import MAX_MESSAGE_BYTES, Session, served_topics

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.messages import TFMessage, TransformStamped

__all__ = ["LOG_PERIOD", "Client", "TfWebServer"]

LOG_PERIOD: Final = 5.0
"""Seconds between two log lines of the same kind."""
_READ: Final = 65536

_log = RateLimitedLog(logging.getLogger("tfbus.web"), period=LOG_PERIOD)


def _note(msg: str, *args: object) -> None:
    _log.log(time.monotonic(), logging.WARNING, msg, *args)


class Client:
    """One connected client: its rosbridge :class:`~tfbus.web.rosbridge.Session` and its
    bounded outgoing queue (frames ready to send)."""

    def __init__(self, session: Session, queue_size: int) -> None:
        self.session = session
        self.queue_size = queue_size
        self.outbox: deque[bytes] = deque()
        self.control: deque[bytes] = deque()
        """Pongs and the close frame: never dropped (at most a few)."""
        self.dropped = 0
        """Messages dropped from a full queue (the oldest first)."""
        self.closed_drops = 0
        """Messages not sent because the connection was closing or closed (a Close frame
        received or sent: RFC 6455 5.5.1 allows no data frame after it)."""
        self.sent = 0
        """Messages written to the socket."""
        self.wake = anyio.Event()
        self.goals_changed = anyio.Event()
        self.ws = WSConnection(ConnectionType.SERVER)

    def push(self, message: dict[str, Any]) -> None:
        """Queue one message (JSON text); a full queue drops its oldest, counted; on a
        closing or closed connection the message is dropped, counted in
        :attr:`closed_drops`."""
        if self.ws.state is not ConnectionState.OPEN:
            self.closed_drops += 1
            return
        data = self.ws.send(TextMessage(json.dumps(message, separators=(",", ":"),
                                                   allow_nan=False)))
        if len(self.outbox) >= self.queue_size:
            self.outbox.popleft()
            self.dropped += 1
        self.outbox.append(data)
        self.wake.set()

    def push_control(self, event: Ping | Pong | CloseConnection) -> None:
        """Queue a control frame (a pong, the Close reply) ahead of the messages; one the
        connection's state no longer allows is dropped, counted in :attr:`closed_drops`."""
        try:
            data = self.ws.send(event)
        except LocalProtocolError:
            self.closed_drops += 1
            return
        if len(self.control) < 4:
            self.control.append(data)
        self.wake.set()

    def close_outbox(self) -> None:
        """After a Close frame: the queued messages are never sent (counted)."""
        self.closed_drops += len(self.outbox)
        self.outbox.clear()


class TfWebServer:
    """Serve tf to roslibjs / roslibpy web apps (rosbridge v2 JSON, module docstring).

    Args:
        buffer: where lookups are made (a :class:`~tfbus.buffer.Buffer` a
            :class:`~tfbus.listener.TransformListener` fills).
        bus: the open bus: ``/tf`` and ``/tf_static`` relayed to subscribers, a client's
            published transforms put on it.
        host: address to bind (``127.0.0.1``: this machine only).
        port: TCP port (0: any free one; :attr:`port` after :meth:`serve` started).
        clock: times the goals' rates and stamps what is sent (tf2_web_republisher
            stamps ``ros::Time::now()``); the wall clock by default.
        token: a secret letting in a client from another name (``?token=``), as
            ``tfbus view --token``.
        queue_size: messages each client's outgoing queue holds.
        max_clients: connections served at once.
        send_timeout: seconds a client may take to accept a message before it is
            disconnected.
        handshake_timeout: seconds a new connection has to send its opening handshake.

    Raises:
        ValueError: a limit is not positive, or ``token`` is not a valid token.
    """

    def __init__(self, buffer: Buffer, bus: Bus, *, host: str = "127.0.0.1", port: int = 9090,
                 clock: Clock | None = None, token: str | None = None, queue_size: int = 256,
                 max_clients: int = 64, send_timeout: float = 10.0,
                 handshake_timeout: float = 10.0) -> None:
        for name, value in (("queue_size", queue_size), ("max_clients", max_clients),
                            ("send_timeout", send_timeout),
                            ("handshake_timeout", handshake_timeout)):
            if not value > 0:
                raise ValueError(f"{name} must be > 0, got {value!r}")
        PageGuard(host, port, token)
        self.buffer = buffer
        self.bus = bus
        self.host = host
        self.port = port
        self.clock: Clock = clock if clock is not None else SystemClock()
        self.token = token
        self.queue_size = queue_size
        self.max_clients = max_clients
        self.send_timeout = send_timeout
        self.handshake_timeout = handshake_timeout
        self.guard = PageGuard(host, port, token)
        """The ``Host`` / ``Origin`` check; ``guard.refused`` counts refused handshakes."""
        self.clients: set[Client] = set()
        """The clients connected now."""
        self.accepted = 0
        """Connections accepted so far."""
        self.busy = 0
        """Connections refused with 503 (``max_clients`` reached)."""
        self.slow = 0
        """Clients disconnected for not taking a message within ``send_timeout``."""
        self.errors = 0
        """Connections closed for a protocol or socket error."""
        self.refused = 0
        """Client requests answered with an error status (over every client so far)."""
        self.dropped = 0
        """Messages dropped from full client queues (over every client so far)."""
        self.dropped_closed = 0
        """Messages dropped because their client's connection was closing or closed
        (over every client gone so far; :attr:`Client.closed_drops`)."""

    # ---------------------------------------------------------------- lookups
    def _lookup(self, target: str, source: str) -> TransformStamped:
        return self.buffer.lookup_transform(target, source, Time(0))

    def _topics(self) -> list[tuple[str, str]]:
        return served_topics(())

    # ---------------------------------------------------------------- serving
    async def serve(self, *, task_status: anyio.abc.TaskStatus[int] =
                    anyio.TASK_STATUS_IGNORED) -> None:
        """Listen and serve until cancelled; ``await tg.start(server.serve)`` returns the
        port once bound.

        Raises:
            OSError: the address cannot be bound (the port is taken).
        """
        listener = await anyio.create_tcp_listener(local_host=self.host, local_port=self.port)
        async with listener, anyio.create_task_group() as tg:
            self.port = int(listener.extra(anyio.abc.SocketAttribute.local_port))
            self.guard = PageGuard(self.host, self.port, self.token)
            for topic in (TF_TOPIC, TF_STATIC_TOPIC):
                tg.start_soon(self._relay, topic)
            task_status.started(self.port)
            await listener.serve(self._connection, task_group=tg)

    async def _relay(self, topic: str) -> None:
        async with self.bus.subscribe(topic, queue_size=1000) as sub:
            async for message in sub:
                self.relay(topic, message)

    def relay(self, topic: str, message: TFMessage) -> None:
        """Send a bus message on ``topic`` to every client subscribed to it (a client whose
        connection is closing drops it, counted: :attr:`Client.closed_drops`)."""
        for client in list(self.clients):
            try:
                out = client.session.tf_message(topic, message)
                if out is not None:
                    client.push(out)
            except Exception as err:  # one client's failure: counted, the others served
                self.errors += 1
                _note("tfbus web: a message for one client failed (%s: %.80s; %d so far)",
                      type(err).__name__, str(err), self.errors)

    async def _connection(self, stream: anyio.abc.ByteStream) -> None:
        client: Client | None = None
        try:
            async with stream:
                client = await self._handshake(stream)
                if client is not None:
                    await self._run(stream, client)
        except Exception as err:  # one client's failure: counted, never a traceback
            self.errors += 1
            _note("tfbus web: a connection failed (%s: %.80s; %d so far)",
                  type(err).__name__, str(err), self.errors)
        finally:
            if client is not None:
                self.clients.discard(client)
                self.refused += client.session.refused
                self.dropped += client.dropped
                self.dropped_closed += client.closed_drops

    async def _handshake(self, stream: anyio.abc.ByteStream) -> Client | None:
        session = Session(self._lookup, self._topics)
        client = Client(session, self.queue_size)
        ws = client.ws
        request: Request | None = None
        with anyio.move_on_after(self.handshake_timeout):
            while request is None:
                try:
                    data = await stream.receive(_READ)
                except (anyio.EndOfStream, anyio.BrokenResourceError):
                    return None
                try:
                    ws.receive_data(data)
                    for event in ws.events():
                        if isinstance(event, Request):
                            request = event
                except RemoteProtocolError as err:
                    self.errors += 1
                    _note("tfbus web: a handshake failed (%.80s; %d so far)", str(err),
                          self.errors)
                    hint = err.event_hint
                    if isinstance(hint, RejectConnection):
                        await stream.send(ws.send(hint))
                    return None
        if request is None:
            self.errors += 1
            _note("tfbus web: no handshake within %g s (%d so far)", self.handshake_timeout,
                  self.errors)
            return None
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in request.extra_headers}
        why = self.guard.check(request.host, headers.get("origin"), request.target,
                               headers.get("cookie", ""))
        if why is not None:
            self.guard.note("refused", why)
            await stream.send(ws.send(RejectConnection(status_code=403)))
            return None
        if len(self.clients) >= self.max_clients:
            self.busy += 1
            _note("tfbus web: %d clients already, one more refused (%d so far)",
                  self.max_clients, self.busy)
            await stream.send(ws.send(RejectConnection(status_code=503)))
            return None
        await stream.send(ws.send(AcceptConnection()))
        self.accepted += 1
        self.clients.add(client)
        return client

    async def _run(self, stream: anyio.abc.ByteStream, client: Client) -> None:
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._writer, stream, client, tg.cancel_scope)
            tg.start_soon(self._ticker, client)
            await self._reader(stream, client)
            # flush what is queued (a close reply), briefly, then end
            with anyio.move_on_after(min(1.0, self.send_timeout)):
                while client.outbox or client.control:
                    await anyio.sleep(0.01)
            tg.cancel_scope.cancel()

    async def _writer(self, stream: anyio.abc.ByteStream, client: Client,
                      scope: anyio.CancelScope) -> None:
        while True:
            await client.wake.wait()
            client.wake = anyio.Event()
            while client.control or client.outbox:
                data = client.control.popleft() if client.control else client.outbox.popleft()
                try:
                    with anyio.fail_after(self.send_timeout):
                        await stream.send(data)
                except TimeoutError:
                    self.slow += 1
                    _note("tfbus web: a client took over %g s to take a message; "
                          "disconnected (%d so far)", self.send_timeout, self.slow)
                    scope.cancel()
                    return
                except (anyio.BrokenResourceError, anyio.ClosedResourceError):
                    scope.cancel()
                    return
                client.sent += 1

    async def _ticker(self, client: Client) -> None:
        while True:
            due = client.session.next_due_ns()
            changed = client.goals_changed
            if due is None:
                await changed.wait()
            else:
                await _first(self.clock.sleep_until(Time.from_ns(due)), changed.wait())
            if changed.is_set():
                client.goals_changed = anyio.Event()
            for message in client.session.tick(self.clock.now()):
                client.push(message)

    async def _reader(self, stream: anyio.abc.ByteStream, client: Client) -> None:
        ws, session = client.ws, client.session
        parts: list[str] = []
        size = 0
        binary = False
        while True:
            try:
                data = await stream.receive(_READ)
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                return
            ws.receive_data(data)
            for event in ws.events():
                if isinstance(event, CloseConnection):
                    # The Close reply goes first and last: nothing queued follows it.
                    self.clients.discard(client)
                    client.push_control(event.response())
                    client.close_outbox()
                    return
                if isinstance(event, Ping):
                    client.push_control(event.response())
                elif isinstance(event, (TextMessage, BytesMessage)):
                    size += len(event.data)
                    binary = binary or isinstance(event, BytesMessage)
                    if size <= MAX_MESSAGE_BYTES and isinstance(event, TextMessage):
                        parts.append(event.data)
                    if not event.message_finished:
                        continue
                    before = len(session.republishers), session.next_due_ns()
                    if size > MAX_MESSAGE_BYTES:
                        outcome = session.handle_oversize(MAX_MESSAGE_BYTES)
                    elif binary:
                        outcome = session.handle_binary(size)
                    else:
                        outcome = session.handle("".join(parts), self.clock.now())
                    parts, size, binary = [], 0, False
                    self._apply(client, outcome.replies, outcome.publish, outcome.subscribed)
                    if (len(session.republishers), session.next_due_ns()) != before:
                        client.goals_changed.set()

    def _apply(self, client: Client, replies: list[dict[str, Any]],
               publish: list[tuple[str, TFMessage]], subscribed: list[str]) -> None:
        for reply in replies:
            client.push(reply)
        for topic, message in publish:
            self.bus.publish_nowait(topic, message)
        if TF_STATIC_TOPIC in subscribed:
            latched = self.bus.latched_statics()
            if latched.transforms:
                out = client.session.tf_message(TF_STATIC_TOPIC, latched)
                if out is not None:
                    client.push(out)


async def _first(*waits: Any) -> None:
    """Return when the first of ``waits`` (awaitables) is done; cancel the others."""
    async with anyio.create_task_group() as tg:
        def run(w: Any) -> Callable[[], Any]:
            async def go() -> None:
                await w
                tg.cancel_scope.cancel()
            return go
        for w in waits:
            tg.start_soon(run(w))
