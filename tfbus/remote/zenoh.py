"""Lookups served to thin clients: :class:`BufferServer` and :class:`BufferClient`.

tf2_ros's ``buffer_server`` / ``BufferClient`` (tf2_ros ``buffer_server.cpp``,
``buffer_client.py``) over Zenoh: one process keeps the :class:`~tfbus.buffer.Buffer`
(subscribed to ``/tf``), others ask it for transforms without subscribing to ``/tf``::

    async with Bus(transport=ZenohTransport()) as bus:          # the server's host
        async with TransformListener(buffer, bus), BufferServer(buffer, bus):
            ...

    async with Bus(transport=ZenohTransport(topics=())) as bus:  # a thin client
        client = BufferClient(bus)
        t = await client.lookup_transform("map", "base_link", Time(0), timeout=1.0)

Protocol: a Zenoh queryable on ``{prefix[/namespace]}/@buffer/{name}`` (a verbatim
``@`` chunk, never matched by ``/**`` data subscriptions). A request is a tfbus wire
payload (:mod:`tfbus.codecs.native`, plain msgpack map) ``{"op": "lookup" | "full" |
"can", "target", "source", "time" (ns), "target_time", "source_time", "fixed",
"timeout" (seconds of the **server's** clock, or None: forever)}``; the reply is a
``TransformStamped``, ``{"can": bool}`` or ``{"error": <tf2 class name>, "message":
...}``, raised on the client as the same :mod:`tfbus.errors` class with the same
message. As tf2_ros's ``buffer_server`` (``checkTransforms``), a lookup whose timeout
expires is answered with ``lookupTransform``'s own error then (``LookupException``,
``ExtrapolationException``, ...). A request that does not decode is counted and left
unanswered; one with a bad field is answered with an ``InvalidArgumentException`` naming
the field and value.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, Final, TypeVar

import anyio
import anyio.from_thread
import zenoh

from tfbus import errors
from tfbus.codecs.native import WireCodec, new_sender_id
from tfbus.errors import (
    InvalidArgumentException,
    TimeoutException,
    TransformException,
    TransportError,
    WireError,
)
from tfbus.messages import TransformStamped
from tfbus.time import Duration, Time

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.transports.zenoh import ZenohTransport

__all__ = ["DEFAULT_SERVER_NAME", "BufferClient", "BufferServer", "ServerStatistics"]

log = logging.getLogger("tfbus.remote")

DEFAULT_SERVER_NAME: Final = "tf2_buffer_server"
"""The default server name: tf2_ros's ``buffer_server`` node name."""

_EXCEPTIONS: Final[Mapping[str, type[TransformException]]] = {
    cls.__name__: cls
    for cls in (
        errors.TransformException,
        errors.LookupException,
        errors.ConnectivityException,
        errors.ExtrapolationException,
        errors.BackwardExtrapolationException,
        errors.ForwardExtrapolationException,
        errors.NoDataForExtrapolationException,
        errors.InvalidArgumentException,
        errors.TimeoutException,
    )
}
_OPS: Final = ("lookup", "full", "can")
_M = TypeVar("_M")


def _zenoh_transport(bus: Bus) -> ZenohTransport:
    from tfbus.transports.zenoh import ZenohTransport

    transport = bus.transport
    if not isinstance(transport, ZenohTransport):
        raise TypeError(f"a remote buffer needs a bus over Zenoh, got transport {transport!r}")
    if transport.key_prefix.endswith("/*"):
        raise ValueError("a remote buffer needs one namespace, not a fleet bus (namespace=*)")
    return transport


def _session(transport: ZenohTransport) -> zenoh.Session:
    session = transport.session
    if session is None:
        raise RuntimeError("the bus is not open (open it with 'async with bus:' first)")
    return session


def _key(transport: ZenohTransport, name: str) -> str:
    from tfbus.transports.zenoh.keys import encode_chunk

    if not name:
        raise ValueError("the server name must not be empty")
    return f"{transport.key_prefix}/@buffer/{encode_chunk(name)}"


@dataclass(slots=True)
class ServerStatistics:
    """Counters of a :class:`BufferServer`.

    Attributes:
        requests: queries received.
        answered: transforms (or can_transform answers) sent back.
        errors: tf2 errors sent back (lookup, timeout, bad argument...).
        malformed: queries dropped unanswered (not a tfbus request).
        busy: queries refused because ``max_pending`` were already being answered.
    """

    requests: int = 0
    answered: int = 0
    errors: int = 0
    malformed: int = 0
    busy: int = 0


def _field(request: Mapping[str, Any], name: str, kind: str) -> Any:
    value = request.get(name)
    ok = (
        isinstance(value, str)
        if kind == "frame"
        else isinstance(value, int) and not isinstance(value, bool)
        if kind == "time"
        else value is None
        or (isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0
            and not math.isnan(value))
    )
    if ok and kind == "time":
        try:
            return Time.from_ns(int(value))  # type: ignore[arg-type]
        except ValueError:
            ok = False
    if not ok:
        raise InvalidArgumentException(f"request field {name!r} has an invalid value {value!r}")
    return value


class BufferServer:
    """Answer lookups from ``buffer`` to :class:`BufferClient` s (tf2_ros
    ``buffer_server``), as a Zenoh queryable of ``bus``'s transport.

    Use ``async with BufferServer(buffer, bus):`` inside ``async with bus:``. Lookups
    wait on ``buffer`` (its clock bounds the requested timeouts); each one runs as a task
    of the server, at most ``max_pending`` at a time (more are answered with a
    ``TransformException`` "server busy").

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from.
        bus: an open bus over Zenoh (``ZenohTransport``, one namespace).
        name: the server's name in its key (default ``tf2_buffer_server``).
        max_pending: most requests answered at once.

    Raises:
        TypeError: the bus is not carried over Zenoh.
        ValueError: an empty name, a fleet bus, or ``max_pending`` < 1.
    """

    def __init__(
        self,
        buffer: Buffer,
        bus: Bus,
        *,
        name: str = DEFAULT_SERVER_NAME,
        max_pending: int = 1000,
    ) -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending!r}")
        self._buffer = buffer
        self._transport = _zenoh_transport(bus)
        self._name = name
        self._key = _key(self._transport, name)
        self._codec = WireCodec()
        self._sender = new_sender_id()
        self._max_pending = max_pending
        self._pending = 0
        self._pending_lock = threading.Lock()  # Zenoh threads add, the event loop removes
        self._stats = ServerStatistics()
        self._portal: anyio.from_thread.BlockingPortal | None = None
        self._queryable: zenoh.Queryable[None] | None = None

    @property
    def key(self) -> str:
        """The Zenoh key the server answers on."""
        return self._key

    def statistics(self) -> ServerStatistics:
        """A copy of the counters."""
        s = self._stats
        return ServerStatistics(**{f.name: getattr(s, f.name) for f in fields(s)})

    async def __aenter__(self) -> BufferServer:
        """Declare the queryable.

        Raises:
            RuntimeError: the bus is not open, or the server is already running.
            TransportError: Zenoh refused the declaration.
        """
        if self._portal is not None:
            raise RuntimeError("this BufferServer is already running")
        session = _session(self._transport)
        portal = anyio.from_thread.BlockingPortal()
        await portal.__aenter__()
        self._portal = portal
        try:
            self._queryable = session.declare_queryable(self._key, self._on_query)
        except zenoh.ZError as err:
            self._portal = None
            await portal.__aexit__(None, None, None)
            raise TransportError(f"cannot declare the buffer server {self._key}: {err}") from err
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Undeclare the queryable and cancel the lookups still waiting."""
        queryable, self._queryable = self._queryable, None
        portal, self._portal = self._portal, None
        if queryable is not None:
            with contextlib.suppress(Exception):
                queryable.undeclare()  # type: ignore[no-untyped-call]
        if portal is not None:
            await portal.stop(cancel_remaining=True)
            await portal.__aexit__(None, None, None)

    # -- Zenoh thread ------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        self._stats.requests += 1
        portal = self._portal
        payload = query.payload
        data = b"" if payload is None else payload.to_bytes()
        with self._pending_lock:
            accepted = portal is not None and self._pending < self._max_pending
            if accepted:
                self._pending += 1
        if portal is None or not accepted:
            self._stats.busy += 1
            with query:
                self._reply_error(query, TransformException("buffer server busy or stopping"))
            return
        try:
            portal.start_task_soon(self._answer, query, data)
        except RuntimeError:  # the portal stopped meanwhile
            with self._pending_lock:
                self._pending -= 1
            with query:
                self._reply_error(query, TransformException("buffer server stopping"))

    # -- event loop ----------------------------------------------------------------------

    async def _answer(self, query: zenoh.Query, data: bytes) -> None:
        try:
            with query:
                try:
                    request = self._codec.decode(data).message
                except WireError:
                    request = None
                if not isinstance(request, dict):
                    self._stats.malformed += 1
                    return
                try:
                    result = await self._run(request)
                except TransformException as exc:
                    self._reply_error(query, exc)
                    return
                except Exception as exc:  # never end the server on one request
                    log.warning("lookup request %r failed: %r", request, exc)
                    self._reply_error(query, TransformException(f"server error: {exc}"))
                    return
                self._stats.answered += 1
                query.reply(self._key, self._codec.encode(result, sender=self._sender, seq=1))
        except zenoh.ZError as exc:
            log.debug("cannot answer a lookup: %s", exc)
        finally:
            with self._pending_lock:
                self._pending -= 1

    async def _run(self, request: Mapping[str, Any]) -> object:
        op = request.get("op")
        if op not in _OPS:
            raise InvalidArgumentException(f"request field 'op' has an invalid value {op!r}")
        timeout = _field(request, "timeout", "timeout")
        buffer = self._buffer
        if op == "full":
            target = _field(request, "target", "frame")
            target_time = _field(request, "target_time", "time")
            source = _field(request, "source", "frame")
            source_time = _field(request, "source_time", "time")
            fixed = _field(request, "fixed", "frame")
            try:
                return await buffer.lookup_transform_full_async(
                    target, target_time, source, source_time, fixed, timeout
                )
            except TimeoutException:
                return buffer.lookup_transform_full(
                    target, target_time, source, source_time, fixed
                )
        target = _field(request, "target", "frame")
        source = _field(request, "source", "frame")
        time = _field(request, "time", "time")
        if op == "can":
            return {"can": await buffer.can_transform_async(target, source, time, timeout)}
        try:
            return await buffer.lookup_transform_async(target, source, time, timeout)
        except TimeoutException:
            # tf2_ros buffer_server.cpp checkTransforms: once the goal times out, the
            # answer is lookupTransform's own result or error (LookupException, ...).
            return buffer.lookup_transform(target, source, time)

    def _reply_error(self, query: zenoh.Query, exc: TransformException) -> None:
        self._stats.errors += 1
        name = type(exc).__name__ if type(exc).__name__ in _EXCEPTIONS else "TransformException"
        body = {"error": name, "message": str(exc)}
        with contextlib.suppress(zenoh.ZError):
            query.reply(self._key, self._codec.encode(body, sender=self._sender, seq=1))


class BufferClient:
    """:class:`~tfbus.buffer.Buffer`'s awaitable lookups, answered by a remote
    :class:`BufferServer` (tf2_ros ``BufferClient``): no ``/tf`` subscription here.

    Timeouts are seconds of the **server's** clock (the server waits); the Zenoh query
    itself is bounded by ``timeout + timeout_padding`` seconds of wall time (tf2_ros
    ``BufferClient``'s ``timeout_padding``, 2 s), after which
    :class:`~tfbus.errors.TimeoutException` is raised. With ``timeout`` None (wait
    forever on the server) the query is bounded by ``max_wait`` seconds.

    Args:
        bus: an open bus over Zenoh (a client can open it with ``topics=()`` to receive
            no data at all).
        name: the server's name (default ``tf2_buffer_server``).
        timeout_padding: wall-clock seconds added to each timeout for the round trip.
        max_wait: wall-clock bound of a query without a timeout.

    Raises:
        TypeError: the bus is not carried over Zenoh.
        ValueError: an empty name, a fleet bus, or a negative padding.
    """

    def __init__(
        self,
        bus: Bus,
        *,
        name: str = DEFAULT_SERVER_NAME,
        timeout_padding: float = 2.0,
        max_wait: float = 3600.0,
    ) -> None:
        if not timeout_padding >= 0 or not max_wait > 0:
            raise ValueError(
                f"timeout_padding must be >= 0 and max_wait > 0, got {timeout_padding!r}, "
                f"{max_wait!r}"
            )
        self._transport = _zenoh_transport(bus)
        self._key = _key(self._transport, name)
        self._codec = WireCodec()
        self._sender = new_sender_id()
        self._padding = timeout_padding
        self._max_wait = max_wait

    async def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
    ) -> TransformStamped:
        """The server's ``lookup_transform_async(target_frame, source_frame, time,
        timeout)`` (:meth:`tfbus.buffer.Buffer.lookup_transform_async`).

        Raises:
            The server's tf2 exception (same class, same message); TimeoutException if
            no answer came within the padded timeout; TransportError if the bus closed.
        """
        request = {"op": "lookup", "target": target_frame, "source": source_frame,
                   "time": time.ns}
        return _typed(await self._ask(request, timeout), TransformStamped)

    async def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
    ) -> TransformStamped:
        """The server's ``lookup_transform_full_async`` (time travel through
        ``fixed_frame``).

        Raises: as :meth:`lookup_transform`.
        """
        request = {"op": "full", "target": target_frame, "target_time": target_time.ns,
                   "source": source_frame, "source_time": source_time.ns,
                   "fixed": fixed_frame}
        return _typed(await self._ask(request, timeout), TransformStamped)

    async def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
    ) -> bool:
        """Whether the server's buffer has the transform within ``timeout``
        (:meth:`tfbus.buffer.Buffer.can_transform_async`); False also when the server
        does not answer in time.

        Raises:
            TransportError: the bus closed.
        """
        request = {"op": "can", "target": target_frame, "source": source_frame,
                   "time": time.ns}
        try:
            answer = await self._ask(request, timeout)
        except TransformException:
            return False
        return isinstance(answer, dict) and answer.get("can") is True

    async def transform(
        self, obj: _M, target_frame: str, timeout: float | Duration | None = None
    ) -> _M:
        """Express a stamped object in ``target_frame`` (tf2_ros ``BufferClient.transform``):
        the lookup is remote, the function registered for ``type(obj)``
        (:mod:`tfbus.convert`) is applied here.

        Raises:
            TypeError: no transform function for ``type(obj)`` (before any query).
            The lookup's errors, as :meth:`lookup_transform`.
        """
        from tfbus.buffer import Buffer, _header_of

        do_transform = Buffer.registration.get(type(obj))
        header = _header_of(obj)
        ts = await self.lookup_transform(target_frame, header.frame_id, header.stamp, timeout)
        result: _M = do_transform(obj, ts)
        return result

    async def _ask(self, request: dict[str, Any], timeout: float | Duration | None) -> object:
        if isinstance(timeout, Duration):
            timeout = timeout.to_sec()
        if timeout is not None and (
            isinstance(timeout, bool) or not isinstance(timeout, (int, float))
            or math.isnan(timeout)
        ):
            raise ValueError(f"timeout must be seconds (a number) or None, got {timeout!r}")
        if timeout is not None and timeout < 0:
            timeout = 0.0
        if timeout == math.inf:
            timeout = None
        request["timeout"] = timeout
        wall = self._max_wait if timeout is None else timeout + self._padding
        payload = self._codec.encode(request, sender=self._sender, seq=1)
        session = _session(self._transport)
        replies = await anyio.to_thread.run_sync(
            _query, session, self._key, payload, wall, abandon_on_cancel=True
        )
        for data in replies:
            try:
                answer = self._codec.decode(data).message
            except WireError:
                continue
            if isinstance(answer, dict) and "error" in answer:
                cls = _EXCEPTIONS.get(str(answer.get("error")), TransformException)
                raise cls(str(answer.get("message", "")))
            return answer
        raise errors.TimeoutException(
            f"no answer from buffer server {self._key} within {wall:g} s"
        )


def _query(session: zenoh.Session, key: str, payload: bytes, wall: float) -> list[bytes]:
    """A Zenoh get (worker thread): the payloads of the ok replies."""
    try:
        replies = session.get(key, payload=payload, timeout=wall,
                              target=zenoh.QueryTarget.BEST_MATCHING)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]
    except zenoh.ZError as err:
        raise TransportError(f"buffer query on {key} failed: {err}") from err


def _typed(answer: object, cls: type[_M]) -> _M:
    if not isinstance(answer, cls):
        raise TransformException(f"unexpected answer from the buffer server: {answer!r:.80}")
    return answer
