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
"timeout" (seconds of the **server's** clock, or None: forever)}``, plus ``"fail_fast":
true`` when the client asks for it (:meth:`tfbus.buffer.Buffer.wait_for_transform`'s
``fail_fast``; absent means false, so older servers and clients interoperate: an older
server ignores the field and waits), and for a lookup
under a non-exact policy (:mod:`tfbus.core.policy`) ``"policy": [kind, a, b]`` (kind
``"nearest"`` / ``"clamp"`` with ``a`` = max_delta ns, ``"previous"``, ``"window"`` with
``a`` = past ns and ``b`` = future_wait ns; unused numbers 0; on every op: a ``"can"``
answers whether the policy can, a ``"full"`` applies it to both legs); the reply is a
``TransformStamped`` (a ``PolicyResult`` under a policy), ``{"can": bool}`` or
``{"error": <tf2 class name>, "message": ...}``, raised on the client as the same
:mod:`tfbus.errors` class with the same message. As tf2_ros's ``buffer_server``
(``checkTransforms``), a lookup whose timeout expires is answered with
``lookupTransform``'s own error then (``LookupException``, ``ExtrapolationException``,
...). A request that does not decode is counted and left
unanswered; one with a bad field is answered with an ``InvalidArgumentException`` naming
the field and value.

The server holds against any querier: every wait is bounded (``max_wait``, 60 s by
default: a ``timeout`` of None or longer waits that long; tf2_ros's ``buffer_server``
has no such bound), at most ``max_pending`` lookups wait at once and at most
``max_per_peer`` of them from one Zenoh session, frame ids are at most
:data:`MAX_FRAME_ID_BYTES` long, and a lookup whose querier is gone stops waiting. For
that a request also carries ``"query_timeout"`` (wall seconds the querier waits for the
answer) and, when its timeout is None or over 1 s, ``"id"`` (a random hex token of the
lookup): while such a lookup is asked, the client holds a Zenoh liveliness token
``{key}/@lookup/{id}``. The server
stops a lookup, unanswered, when that token goes (the client's lookup was cancelled, or
its session closed: Zenoh deletes a session's tokens when it leaves), and answers it as
an expired timeout after ``query_timeout`` wall seconds (or ``max_wait``, whichever is
less). The querier is the Zenoh session id of the query's source info (``SourceInfo``,
set by :class:`BufferClient`); queries without one share a single per-peer share. Zenoh
does not authenticate that id: on an untrusted network use Zenoh's access control.

Threads: the queryable is a :class:`~tfbus.transports.zenoh.queryable.LoopQueryable`:
Zenoh's thread only queues each query (at most ``max_pending``; beyond, it answers "buffer
server busy" at once, counted in ``busy``) and wakes the event loop through
:class:`~tfbus.transports._base.ThreadWakeup`, where the query is decoded, admitted and
answered by a task; a Zenoh thread never waits for the loop. A client's lookup is a Zenoh
``get`` whose reply wakes the waiting task through a socket
(:func:`~tfbus.transports.zenoh.queryable.get_replies`): no thread per pending lookup.
"""

from __future__ import annotations

import contextlib
import logging
import math
import secrets
from collections.abc import Mapping
from dataclasses import fields
from typing import TYPE_CHECKING, Any, Final, TypeVar, overload

import anyio
import anyio.abc
import zenoh

from tfbus import errors
from tfbus._aio import Awaiting, coroutine_method
from tfbus.codecs.native import WireCodec, new_sender_id, register_message_type
from tfbus.core.policy import (
    Clamp,
    Exact,
    LookupPolicy,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
)
from tfbus.errors import (
    InvalidArgumentException,
    TransformException,
    TransportError,
    WireEncodeError,
    WireError,
)
from tfbus.messages import TransformStamped
from tfbus.time import Duration, Time
from tfbus.transports._base import (
    DEFAULT_MAX_WAIT,
    DEFAULT_SERVER_NAME,
    LOOKUPS_OWN_ERROR,
    MAX_FRAME_ID_BYTES,
    ServerStatistics,
    transform_remotely,
)
from tfbus.transports.zenoh.queryable import LoopQueryable, get_replies

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.transports.zenoh import ZenohTransport

__all__ = [
    "DEFAULT_MAX_WAIT",
    "DEFAULT_SERVER_NAME",
    "MAX_FRAME_ID_BYTES",
    "BufferClient",
    "BufferServer",
    "ServerStatistics",
]

log = logging.getLogger("tfbus.remote")

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
_ARGUMENTS: Final = {"target": "target_frame", "source": "source_frame",
                     "fixed": "fixed_frame"}  # request field -> lookup argument
_MAX_REQUEST_BYTES: Final = 16 << 10  # a request with 4 frame ids of 1 KiB is smaller
_MAX_ID_CHARS: Final = 64
# A lookup that may wait longer than this (server seconds) holds a liveliness token so
# that the server ends it once its querier is gone; a shorter one ends there within its
# timeout anyway, and spares the token's two messages (about 0.4 ms a lookup).
_TRACKED_AFTER: Final = 1.0
_M = TypeVar("_M")

for _cls in (PolicyReport, PolicyResult):  # a policy lookup's answer crosses the wire typed
    register_message_type(_cls)

_INT64_MAX: Final = (1 << 63) - 1


def _policy_to_wire(policy: LookupPolicy) -> list[Any]:
    """``[kind, a ns, b ns]`` of a non-exact policy (the request's ``"policy"``)."""
    if isinstance(policy, Nearest):
        return ["nearest", policy.max_delta.ns, 0]
    if isinstance(policy, Clamp):
        return ["clamp", policy.max_delta.ns, 0]
    if isinstance(policy, Previous):
        return ["previous", 0, 0]
    if isinstance(policy, Window):
        return ["window", policy.past.ns, policy.future_wait.ns]
    raise TypeError(
        "policy must be Exact(), Nearest(max_delta), Clamp(max_delta), Previous() or "
        f"Window(past, future_wait), got {policy!r}"
    )


def _policy_field(request: Mapping[str, Any]) -> LookupPolicy | None:
    """The request's ``"policy"``, or None when absent.

    Raises:
        InvalidArgumentException: not ``[kind, a, b]`` with a known kind and two ints in
            [0, 2**63 - 1], naming the field and value.
    """
    value = request.get("policy")
    if value is None:
        return None
    ok = (
        isinstance(value, list) and len(value) == 3
        and value[0] in ("nearest", "clamp", "previous", "window")
        and all(type(v) is int and 0 <= v <= _INT64_MAX for v in value[1:])
    )
    if not ok:
        raise InvalidArgumentException(
            f"request field 'policy' has an invalid value {value!r:.200}")
    kind, a, b = value
    if kind == "nearest":
        return Nearest(Duration.from_ns(a))
    if kind == "clamp":
        return Clamp(Duration.from_ns(a))
    if kind == "previous":
        return Previous()
    return Window(Duration.from_ns(a), Duration.from_ns(b))


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
        raise InvalidArgumentException(
            f"request field {name!r} has an invalid value {value!r:.200}")
    if isinstance(value, str) and len(value) > MAX_FRAME_ID_BYTES // 4:
        size = len(value.encode())
        if size > MAX_FRAME_ID_BYTES:
            raise InvalidArgumentException(
                f"request field {name!r} is a frame id of {size} bytes, longer than "
                f"{MAX_FRAME_ID_BYTES}")
    return value


def _lookup_id(request: Mapping[str, Any]) -> str | None:
    """The request's ``id`` if it is a usable key chunk (hex digits, at most 64)."""
    value = request.get("id")
    if isinstance(value, str) and 0 < len(value) <= _MAX_ID_CHARS \
            and all(c in "0123456789abcdef" for c in value):
        return value
    return None


def _querier(query: zenoh.Query) -> str:
    """The Zenoh session id of the query's source info ("" when the querier set none)."""
    try:
        info = query.source_info
        return "" if info is None else str(info.source_id.zid)
    except Exception:  # source info is unstable API: a querier without it is anonymous
        return ""


class _Lookup:
    """A lookup the server holds: its querier, and how to end it when its querier goes
    (all on the event loop)."""

    __slots__ = ("cancelled", "lookup_id", "peer", "scope")

    def __init__(self, peer: str, lookup_id: str | None) -> None:
        self.peer = peer
        self.lookup_id = lookup_id
        self.scope: anyio.CancelScope | None = None
        self.cancelled = False


class BufferServer:
    """Answer lookups from ``buffer`` to :class:`BufferClient` s (tf2_ros
    ``buffer_server``), as a Zenoh queryable of ``bus``'s transport.

    Use ``async with BufferServer(buffer, bus):`` inside ``async with bus:``. Lookups
    wait on ``buffer`` (its clock bounds the requested timeouts); each one runs as a task
    of the server. Every wait is bounded and no querier can hold the server for others
    (module doc):

    * a ``timeout`` of None, or longer than ``max_wait``, waits ``max_wait`` seconds of
      the buffer's clock; any lookup is answered as an expired timeout (the lookup's own
      result or error, as tf2_ros ``buffer_server.cpp`` ``checkTransforms``) after
      ``max_wait`` wall seconds or its querier's ``query_timeout``, whichever is less;
    * a lookup whose querier cancelled it or whose Zenoh session left is ended unanswered
      (its liveliness token ``{key}/@lookup/{id}`` was deleted), its slot freed;
    * at most ``max_pending`` lookups wait at once and at most ``max_per_peer`` of one
      querier (the Zenoh session id of the query's source info); more are answered at once
      with a ``TransformException`` "buffer server busy: ..."; so are queries beyond
      ``max_pending`` still queued for a busy event loop, in Zenoh's thread (module doc);
    * a frame id longer than :data:`MAX_FRAME_ID_BYTES` is answered with an
      ``InvalidArgumentException`` naming the field, and so is a request over 16 KiB.

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from.
        bus: an open bus over Zenoh (``ZenohTransport``, one namespace).
        name: the server's name in its key (default ``tf2_buffer_server``).
        max_pending: most lookups waiting at once.
        max_per_peer: most lookups of one querier waiting at once (default
            ``max_pending // 4``, at least 1).
        max_wait: longest wait of one lookup, seconds (default :data:`DEFAULT_MAX_WAIT`).

    Raises:
        TypeError: the bus is not carried over Zenoh.
        ValueError: an empty name, a fleet bus, ``max_pending`` or ``max_per_peer`` < 1,
            or ``max_wait`` not a positive finite number.
    """

    def __init__(
        self,
        buffer: Buffer,
        bus: Bus,
        *,
        name: str = DEFAULT_SERVER_NAME,
        max_pending: int = 1000,
        max_per_peer: int | None = None,
        max_wait: float = DEFAULT_MAX_WAIT,
    ) -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending!r}")
        if max_per_peer is None:
            max_per_peer = max(1, max_pending // 4)
        if max_per_peer < 1:
            raise ValueError(f"max_per_peer must be at least 1, got {max_per_peer!r}")
        if isinstance(max_wait, bool) or not isinstance(max_wait, (int, float)) \
                or not 0 < max_wait < math.inf:
            raise ValueError(f"max_wait must be positive finite seconds, got {max_wait!r}")
        self._buffer = buffer
        self._transport = _zenoh_transport(bus)
        self._name = name
        self._key = _key(self._transport, name)
        self._codec = WireCodec()
        self._sender = new_sender_id()
        self._max_pending = max_pending
        self._max_per_peer = max_per_peer
        self._max_wait = float(max_wait)
        self._pending = 0
        self._per_peer: dict[str, int] = {}
        self._lookups: dict[str, _Lookup] = {}  # by lookup id
        self._stats = ServerStatistics()
        self._queryable: LoopQueryable | None = None
        self._tasks: anyio.abc.TaskGroup | None = None
        self._tokens: zenoh.Subscriber[None] | None = None

    @property
    def key(self) -> str:
        """The Zenoh key the server answers on."""
        return self._key

    @property
    def where(self) -> str:
        """Where the server answers, for log lines: its Zenoh key."""
        return self._key

    def statistics(self) -> ServerStatistics:
        """A copy of the counters (``pending``: the lookups waiting now)."""
        s = self._stats
        copy = ServerStatistics(**{f.name: getattr(s, f.name) for f in fields(s)})
        copy.pending = self._pending
        queryable = self._queryable
        if queryable is not None:  # queries counted and refused in Zenoh's threads
            copy.requests += queryable.received
            copy.busy += queryable.refused
            copy.errors += queryable.refused
        return copy

    async def __aenter__(self) -> BufferServer:
        """Declare the queryable (and the liveliness subscriber of the lookups' tokens).

        Raises:
            RuntimeError: the bus is not open, or the server is already running.
            TransportError: Zenoh refused the declaration.
        """
        if self._tasks is not None:
            raise RuntimeError("this BufferServer is already running")
        session = _session(self._transport)
        self._fold_counts()
        queryable = self._queryable = LoopQueryable(
            self._key, self._on_query, self._refuse, max_queued=self._max_pending,
            noted=self._on_gone,
        )
        tasks = anyio.create_task_group()
        await tasks.__aenter__()
        self._tasks = tasks
        try:
            self._tokens = session.liveliness().declare_subscriber(
                f"{self._key}/@lookup/*", self._on_token)
            await tasks.start(queryable.serve, session)
        except (zenoh.ZError, TransportError) as err:
            await self.__aexit__(None, None, None)
            if isinstance(err, TransportError):
                raise
            raise TransportError(f"cannot declare the buffer server {self._key}: {err}") from err
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Undeclare the queryable, refuse the queries not yet taken ("buffer server
        stopping") and end the lookups still waiting, unanswered (their clients' queries
        end at once)."""
        tokens, self._tokens = self._tokens, None
        tasks, self._tasks = self._tasks, None
        if tokens is not None:
            with contextlib.suppress(Exception):
                tokens.undeclare()  # type: ignore[no-untyped-call]
        if tasks is not None:
            tasks.cancel_scope.cancel()
            await tasks.__aexit__(None, None, None)
        self._fold_counts()

    def _fold_counts(self) -> None:
        """Add the ended queryable's counts to the server's own."""
        queryable, self._queryable = self._queryable, None
        if queryable is not None:
            self._stats.requests += queryable.received
            self._stats.busy += queryable.refused
            self._stats.errors += queryable.refused

    # -- Zenoh threads -----------------------------------------------------------------

    def _on_token(self, sample: zenoh.Sample) -> None:
        """A lookup's liveliness token went: its querier cancelled it or left."""
        if sample.kind != zenoh.SampleKind.DELETE:
            return
        queryable = self._queryable
        if queryable is not None:
            queryable.notify(str(sample.key_expr).rsplit("/", 1)[-1])

    def _refuse(self, query: zenoh.Query, message: str) -> None:
        """The error reply to a query the server will not take (queue full, stopping)."""
        text = "buffer server stopping" if message == "stopping" else \
            f"buffer server busy: {message}"
        body = {"error": "TransformException", "message": text}
        # a codec of this call: Zenoh threads refuse while the loop encodes answers
        query.reply(self._key, WireCodec().encode(body, sender=self._sender, seq=1))

    # -- event loop: taking queries ----------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        data = b"" if payload is None else payload.to_bytes()
        if len(data) > _MAX_REQUEST_BYTES:
            with query:
                self._reply_error(query, InvalidArgumentException(
                    f"request of {len(data)} bytes, longer than {_MAX_REQUEST_BYTES}"))
            return
        try:
            request = self._codec.decode(data).message
        except WireError:
            request = None
        if not isinstance(request, dict):
            self._stats.malformed += 1
            query.drop()  # type: ignore[no-untyped-call]
            return
        lookup = _Lookup(_querier(query), _lookup_id(request))
        refusal = self._admit(lookup)
        tasks = self._tasks
        if refusal is None and tasks is not None:
            tasks.start_soon(self._answer, query, request, lookup)
            return
        if refusal is None:
            self._release(lookup)
            refusal = TransformException("buffer server stopping")
        with query:
            self._reply_error(query, refusal)

    def _admit(self, lookup: _Lookup) -> TransformException | None:
        """Take a slot for ``lookup``, or the error that refuses it."""
        if lookup.lookup_id is not None and lookup.lookup_id in self._lookups:
            return InvalidArgumentException(
                f"request field 'id' has a value {lookup.lookup_id!r} already waiting")
        if self._pending >= self._max_pending:
            self._stats.busy += 1
            return TransformException(
                f"buffer server busy: {self._pending} lookups waiting (max_pending)")
        held = self._per_peer.get(lookup.peer, 0)
        if held >= self._max_per_peer:
            self._stats.busy += 1
            return TransformException(
                f"buffer server busy: {held} lookups of this querier waiting "
                "(max_per_peer)")
        self._pending += 1
        self._per_peer[lookup.peer] = held + 1
        if lookup.lookup_id is not None:
            self._lookups[lookup.lookup_id] = lookup
        return None

    def _release(self, lookup: _Lookup) -> None:
        self._pending -= 1
        held = self._per_peer[lookup.peer] - 1
        if held:
            self._per_peer[lookup.peer] = held
        else:
            del self._per_peer[lookup.peer]
        if lookup.lookup_id is not None and self._lookups.get(lookup.lookup_id) is lookup:
            del self._lookups[lookup.lookup_id]

    def _on_gone(self, lookup_id: str) -> None:
        """The lookup ``lookup_id``'s querier cancelled it or left: end its wait."""
        lookup = self._lookups.get(lookup_id)
        if lookup is None:
            return
        lookup.cancelled = True
        if lookup.scope is not None:
            lookup.scope.cancel()

    # -- event loop ----------------------------------------------------------------------

    async def _answer(self, query: zenoh.Query, request: dict[str, Any],
                      lookup: _Lookup) -> None:
        try:
            with query:
                wall = self._max_wait
                sent = request.get("query_timeout")
                if isinstance(sent, (int, float)) and not isinstance(sent, bool) \
                        and sent >= 0:
                    wall = min(wall, float(sent))
                with anyio.CancelScope() as gone:
                    lookup.scope = gone
                    if lookup.cancelled:
                        gone.cancel()
                    try:
                        with anyio.move_on_after(wall):
                            result = await self._run(request, self._max_wait)
                            self._reply(query, result)
                            return
                        # past the wall bound: answered as an expired timeout
                        self._reply(query, await self._run(request, 0.0))
                    except TransformException as exc:
                        self._reply_error(query, exc)
                    except Exception as exc:  # never end the server on one request
                        log.warning("lookup request %r failed: %r", request, exc)
                        self._reply_error(query, TransformException(f"server error: {exc}"))
                if gone.cancelled_caught:
                    self._stats.cancelled += 1
        except zenoh.ZError as exc:
            log.debug("cannot answer a lookup: %s", exc)
        finally:
            self._release(lookup)

    def _reply(self, query: zenoh.Query, result: object) -> None:
        self._stats.answered += 1
        query.reply(self._key, self._codec.encode(result, sender=self._sender, seq=1))

    async def _run(self, request: Mapping[str, Any], max_wait: float) -> object:
        op = request.get("op")
        if op not in _OPS:
            raise InvalidArgumentException(f"request field 'op' has an invalid value {op!r}")
        if "id" in request and _lookup_id(request) is None:
            raise InvalidArgumentException(
                f"request field 'id' has an invalid value {request['id']!r:.200}")
        timeout = _field(request, "timeout", "timeout")
        timeout = max_wait if timeout is None else min(timeout, max_wait)
        fail_fast = request.get("fail_fast", False)
        if not isinstance(fail_fast, bool):
            raise InvalidArgumentException(
                f"request field 'fail_fast' has an invalid value {fail_fast!r:.200}")
        buffer = self._buffer
        if op == "full":
            target = _field(request, "target", "frame")
            target_time = _field(request, "target_time", "time")
            source = _field(request, "source", "frame")
            source_time = _field(request, "source_time", "time")
            fixed = _field(request, "fixed", "frame")
            full_policy = _policy_field(request)
            try:
                return await buffer.lookup_transform_full_async(
                    target, target_time, source, source_time, fixed, timeout,
                    fail_fast=fail_fast, policy=full_policy,
                )
            except LOOKUPS_OWN_ERROR:
                return buffer.lookup_transform_full(
                    target, target_time, source, source_time, fixed, policy=full_policy
                )
        target = _field(request, "target", "frame")
        source = _field(request, "source", "frame")
        time = _field(request, "time", "time")
        policy = _policy_field(request)
        if op == "can":
            return {"can": await buffer.can_transform_async(target, source, time, timeout,
                                                            fail_fast=fail_fast,
                                                            policy=policy)}
        if policy is not None:
            try:
                return await buffer.lookup_transform_async(
                    target, source, time, timeout, policy=policy
                )
            except LOOKUPS_OWN_ERROR:
                return buffer.lookup_transform(target, source, time, policy=policy)
        try:
            return await buffer.lookup_transform_async(target, source, time, timeout,
                                                       fail_fast=fail_fast)
        except LOOKUPS_OWN_ERROR:
            # tf2_ros buffer_server.cpp checkTransforms: once the goal times out (or
            # an argument can never be valid), the answer is lookupTransform's own
            # result or error (LookupException, ...), in its order of checks.
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
    :class:`~tfbus.errors.TimeoutException` is raised. With ``timeout`` None the query is
    bounded by ``max_wait`` seconds (and the server waits at most its own ``max_wait``,
    60 s by default, then answers with the lookup's own result or error). A lookup
    cancelled here (a cancelled task, ``anyio.move_on_after``) ends its Zenoh query at
    once, and, if its timeout is None or over 1 s, its wait on the server too (module
    doc).

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

    carries_policy: Final = True
    """Lookups may carry a :mod:`tfbus.core.policy` (``tfbus.remote`` asks)."""

    @overload
    def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """The server's ``lookup_transform_async(target_frame, source_frame, time,
        timeout, fail_fast=fail_fast, policy=policy)``
        (:meth:`tfbus.buffer.Buffer.lookup_transform_async`; ``fail_fast`` travels as the
        request's ``"fail_fast"`` field): under a non-exact policy, the server's
        :class:`~tfbus.core.policy.PolicyResult`.

        Raises:
            The server's tf2 exception (same class, same message); TimeoutException if
            no answer came within the padded timeout; TransportError if the bus closed;
            TypeError: ``policy`` is not a lookup policy; WireEncodeError: a frame id
            that cannot be sent (a lone surrogate), naming the argument and value.
        """
        request: dict[str, Any] = {"op": "lookup", "target": target_frame,
                                   "source": source_frame, "time": time.ns}
        if policy is not None and type(policy) is not Exact:
            request["policy"] = _policy_to_wire(policy)
            return _typed(await self._ask(request, timeout, fail_fast), PolicyResult)
        return _typed(await self._ask(request, timeout, fail_fast), TransformStamped)

    @overload
    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """The server's ``lookup_transform_full_async`` (time travel through
        ``fixed_frame``); ``policy`` travels as the request's ``"policy"`` (the answer
        is then the server's :class:`~tfbus.core.policy.PolicyResult`).

        Raises: as :meth:`lookup_transform`.
        """
        request: dict[str, Any] = {
            "op": "full", "target": target_frame, "target_time": target_time.ns,
            "source": source_frame, "source_time": source_time.ns, "fixed": fixed_frame}
        if policy is not None and type(policy) is not Exact:
            request["policy"] = _policy_to_wire(policy)
            return _typed(await self._ask(request, timeout, fail_fast), PolicyResult)
        return _typed(await self._ask(request, timeout, fail_fast), TransformStamped)

    @coroutine_method
    async def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> bool:
        """Whether the server's buffer has the transform within ``timeout``
        (:meth:`tfbus.buffer.Buffer.can_transform_async`, ``fail_fast`` and ``policy``
        too); False also when the server does not answer in time.

        Raises:
            TransportError: the bus closed. TypeError: ``policy`` is not a lookup policy.
            WireEncodeError: a frame id that cannot be sent (a lone surrogate), named.
        """
        request: dict[str, Any] = {"op": "can", "target": target_frame,
                                   "source": source_frame, "time": time.ns}
        if policy is not None and type(policy) is not Exact:
            request["policy"] = _policy_to_wire(policy)
        try:
            answer = await self._ask(request, timeout, fail_fast)
        except TransformException:
            return False
        return isinstance(answer, dict) and answer.get("can") is True

    @overload
    def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[_M]: ...

    @overload
    def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[tuple[_M, PolicyReport]]: ...

    @coroutine_method  # type: ignore[misc]
    async def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> _M | tuple[_M, PolicyReport]:
        """Express a stamped object in ``target_frame`` (tf2_ros ``BufferClient.transform``):
        the lookup is remote, the function registered for ``type(obj)``
        (:mod:`tfbus.convert`) is applied here. Under a non-exact ``policy``,
        ``(transformed object, PolicyReport)`` (as :meth:`tfbus.buffer.Buffer.transform`).

        Raises:
            TypeError: no transform function for ``type(obj)`` (before any query), or
                ``policy`` is not a lookup policy.
            The lookup's errors, as :meth:`lookup_transform`.
        """
        if policy is not None and type(policy) is not Exact:
            from tfbus.buffer import Buffer, _header_of

            do_transform = Buffer.registration.get(type(obj))
            header = _header_of(obj)
            found = await self.lookup_transform(
                target_frame, header.frame_id, header.stamp, timeout, fail_fast=fail_fast,
                policy=policy,
            )
            assert isinstance(found, PolicyResult)
            return do_transform(obj, found.transform), found.report
        return await transform_remotely(self, obj, target_frame, timeout, fail_fast)

    async def _ask(self, request: dict[str, Any], timeout: float | Duration | None,
                   fail_fast: bool = False) -> object:
        if fail_fast:
            request["fail_fast"] = True
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
        lookup_id: str | None = None
        if timeout is None or timeout > _TRACKED_AFTER:
            lookup_id = secrets.token_hex(16)
            request["id"] = lookup_id
        request["query_timeout"] = wall
        try:
            payload = self._codec.encode(request, sender=self._sender, seq=1)
        except WireEncodeError:
            for name, value in request.items():  # name the argument that cannot be sent
                if isinstance(value, str) and not value.isascii():
                    try:
                        value.encode()
                    except UnicodeEncodeError:
                        raise WireEncodeError(
                            f"{_ARGUMENTS.get(name, name)} {value!r:.100} cannot be sent: "
                            "not UTF-8 encodable (a lone surrogate)") from None
            raise
        session = _session(self._transport)
        replies = await _query(session, self._key, payload, wall, lookup_id)
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


async def _query(session: zenoh.Session, key: str, payload: bytes, wall: float,
                 lookup_id: str | None) -> list[bytes]:
    """A Zenoh get, waited for on the event loop (no worker thread:
    :func:`~tfbus.transports.zenoh.queryable.get_replies`): the payloads of the ok
    replies. While it waits, the lookup's liveliness token ``{key}/@lookup/{lookup_id}``
    is declared if it has an id (the server ends the lookup when it goes: the lookup was
    cancelled here, or this session left); the query carries this session's id as
    source info."""
    token = None
    if lookup_id is not None:
        try:
            token = session.liveliness().declare_token(f"{key}/@lookup/{lookup_id}")
        except zenoh.ZError as err:
            raise TransportError(f"buffer query on {key} failed: {err}") from err
    try:
        try:
            source: zenoh.SourceInfo | None = zenoh.SourceInfo(session.id, 0)
        except Exception:  # source info is unstable API: ask without it
            source = None
        return await get_replies(session, key, payload, max(wall, 1e-3), source_info=source)
    except TransportError as err:
        raise TransportError(f"buffer query on {key} failed: {err.__cause__}") from err.__cause__
    finally:
        if token is not None:
            with contextlib.suppress(Exception):  # the session may have closed meanwhile
                token.undeclare()  # type: ignore[no-untyped-call]


def _typed(answer: object, cls: type[_M]) -> _M:
    if not isinstance(answer, cls):
        raise TransformException(f"unexpected answer from the buffer server: {answer!r:.80}")
    return answer
