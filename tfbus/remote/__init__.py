"""Lookups served to thin clients, one API on every bus: a process that keeps a
:class:`~tfbus.buffer.Buffer` answers lookups for others that do not subscribe to
``/tf`` (tf2_ros's ``buffer_server`` and ``BufferClient``)::

    async with Bus(transport=transport) as bus:                 # the server's host
        async with TransformListener(buffer, bus), BufferServer(buffer, bus):
            ...

    async with Bus(transport=thin_transport) as bus:            # a thin client
        client = BufferClient(bus)
        t = await client.lookup_transform("map", "base_link", Time(0), timeout=1.0)

Each transport serves lookups over its own middleware (the
:class:`~tfbus.transports._base.LookupServing` capability):

* Zenoh: a queryable on ``{prefix}/@buffer/{name}``
  (:mod:`tfbus.transports.zenoh.lookups`);
* ROS 1: tf2_ros's own ``tf2_msgs/LookupTransform`` action ``/{name}`` on the
  transport's node (:mod:`tfbus.transports.ros1.action`), interoperating with Debian's
  ``buffer_server`` and ``tf2_ros.BufferClient``;
* ROS 2: tf2_ros's ``tf2_msgs/action/LookupTransform`` action ``/{name}`` over DDS on the
  transport's participant (:mod:`tfbus.transports.ros2.action`; rmw_cyclonedds_cpp's
  request/reply mapping).

A bus whose transport has no such capability is refused with a TypeError naming it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeVar, overload

from tfbus._aio import Awaiting, coroutine_method
from tfbus.core.policy import (
    Clamp,
    Exact,
    LookupPolicy,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
    policy_args,
)
from tfbus.transports._base import (
    DEFAULT_MAX_WAIT,
    DEFAULT_SERVER_NAME,
    MAX_FRAME_ID_BYTES,
    LookupClient,
    LookupServer,
    LookupServing,
    ServerStatistics,
)

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.messages import TransformStamped
    from tfbus.time import Duration, Time

__all__ = [
    "DEFAULT_MAX_WAIT",
    "DEFAULT_SERVER_NAME",
    "MAX_FRAME_ID_BYTES",
    "BufferClient",
    "BufferServer",
    "ServerStatistics",
]


_M = TypeVar("_M")


def _serving(bus: Bus) -> LookupServing:
    transport = bus.transport
    if transport is None:
        raise TypeError("remote lookups need a bus over a transport that serves them "
                        "(Zenoh, ROS 1, ROS 2); this bus has no transport")
    if not isinstance(transport, LookupServing):
        raise TypeError(f"remote lookups need a transport that serves them (Zenoh, ROS 1, ROS 2); "
                        f"{type(transport).__name__} does not: {transport!r}")
    return transport


class BufferServer:
    """Answer lookups from ``buffer`` to :class:`BufferClient` s (tf2_ros
    ``buffer_server``) over ``bus``'s transport: ``async with BufferServer(buffer, bus):``
    inside ``async with bus:``.

    Every wait is bounded by ``max_wait`` (seconds, default :data:`DEFAULT_MAX_WAIT`) and
    at most ``max_pending`` lookups wait at once; a lookup whose client cancelled it ends
    at once. The options are the transport's (``Zenoh``:
    :class:`tfbus.transports.zenoh.lookups.BufferServer`, with ``max_per_peer``; ROS 1:
    :class:`tfbus.transports.ros1.action.LookupActionServer`; ROS 2:
    :class:`tfbus.transports.ros2.action.LookupActionServer`, with ``max_per_peer``).

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` to answer from.
        bus: the bus whose transport answers.
        options: ``name`` (default ``tf2_buffer_server``), ``max_pending``, ``max_wait``,
            and the transport's own.

    Raises:
        TypeError: the bus's transport does not serve lookups (named), or an option it
            does not have.
        ValueError: a bad option value (named).
    """

    def __init__(self, buffer: Buffer, bus: Bus, **options: Any) -> None:
        self._server: LookupServer = _serving(bus).serve_lookups(buffer, bus, **options)

    @property
    def where(self) -> str:
        """Where the server answers (a Zenoh key, a ROS 1 action), for log lines."""
        return self._server.where

    @property
    def server(self) -> LookupServer:
        """The transport's own server (its counters and properties)."""
        return self._server

    def statistics(self) -> ServerStatistics:
        """A copy of the counters (:class:`ServerStatistics`, one shape on every
        transport)."""
        return self._server.statistics()

    async def __aenter__(self) -> BufferServer:
        """Start answering.

        Raises:
            RuntimeError: the bus is not open, or the server runs already.
            TransportError: the middleware refused.
        """
        await self._server.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        """End answering; lookups still waiting are dropped."""
        await self._server.__aexit__(*exc)


class BufferClient:
    """:class:`~tfbus.buffer.Buffer`'s awaitable lookups answered by a remote
    :class:`BufferServer` (or tf2_ros's ``buffer_server`` on ROS 1) over ``bus``'s
    transport: no ``/tf`` subscription here.

    Timeouts are seconds of the **server's** clock; the wait here is bounded by
    ``timeout + timeout_padding`` wall seconds (tf2_ros ``BufferClient``'s
    ``timeout_padding``, 2 s), then :class:`~tfbus.errors.TimeoutException`. A lookup
    cancelled here is cancelled on the server too.

    Args:
        bus: an open bus whose transport serves lookups.
        options: ``name`` (default ``tf2_buffer_server``), ``timeout_padding``,
            ``max_wait`` (the bound of a lookup whose timeout is None).

    Raises:
        TypeError: the bus's transport does not serve lookups (named), or an option it
            does not have.
        ValueError: a bad option value (named).
    """

    def __init__(self, bus: Bus, **options: Any) -> None:
        self._client: LookupClient = _serving(bus).lookup_client(bus, **options)

    @property
    def client(self) -> LookupClient:
        """The transport's own client."""
        return self._client

    @overload
    def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                         timeout: float | Duration | None = None, *,
                         fail_fast: bool = False,
                         policy: Exact | None = None) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                         timeout: float | Duration | None = None, *,
                         fail_fast: bool = False,
                         policy: Nearest | Clamp | Previous | Window
                         ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                               timeout: float | Duration | None = None, *,
                               fail_fast: bool = False, policy: LookupPolicy | None = None
                               ) -> TransformStamped | PolicyResult:
        """The server's ``lookup_transform_async(target_frame, source_frame, time,
        timeout, fail_fast=fail_fast, policy=policy)``
        (:meth:`tfbus.buffer.Buffer.lookup_transform_async`). ``fail_fast`` is the
        server's (Zenoh's wire carries it; ROS 1's tf2_msgs/LookupTransform action
        cannot: a ValueError there).

        ``policy`` (:mod:`tfbus.core.policy`): a non-exact one crosses the wire on Zenoh
        (the answer is the server's :class:`~tfbus.core.policy.PolicyResult`); the ROS
        ``LookupTransform`` action (tf2_msgs) has no field for one.

        Raises:
            The server's tf2 exception (same class, same message); TimeoutException if
            no answer came within the padded timeout; ValueError for a bad timeout;
            TransportError if the bus closed; TypeError: a non-exact ``policy`` on a
            transport whose lookups cannot carry one (ROS 1), or not a policy.
        """
        if self._policy_client(policy) is not None:
            client: Any = self._client  # the Zenoh client: policy= beyond LookupClient
            answer: PolicyResult = await client.lookup_transform(
                target_frame, source_frame, time, timeout, fail_fast=fail_fast, policy=policy
            )
            return answer
        return await self._client.lookup_transform(target_frame, source_frame, time, timeout,
                                                   fail_fast=fail_fast)

    def _policy_client(self, policy: object) -> Any:
        """The client to send a non-exact ``policy`` with (None for none or ``Exact()``).

        Raises:
            TypeError: ``policy`` is not a lookup policy, or the transport's lookups
                cannot carry one (the ROS ``LookupTransform`` action, ROS 1 and ROS 2).
        """
        if policy is None or type(policy) is Exact:
            return None
        policy_args(policy)  # a TypeError for anything else
        if not getattr(self._client, "carries_policy", False):
            raise TypeError(
                f"{type(self._client).__qualname__} cannot carry a lookup policy (the "
                "ROS LookupTransform action has no field for one): look up with "
                "policy= on a Buffer fed by a TransformListener instead"
            )
        return self._client

    @overload
    def lookup_transform_full(self, target_frame: str, target_time: Time,
                              source_frame: str, source_time: Time, fixed_frame: str,
                              timeout: float | Duration | None = None, *,
                              fail_fast: bool = False,
                              policy: Exact | None = None) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform_full(self, target_frame: str, target_time: Time,
                              source_frame: str, source_time: Time, fixed_frame: str,
                              timeout: float | Duration | None = None, *,
                              fail_fast: bool = False,
                              policy: Nearest | Clamp | Previous | Window
                              ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform_full(self, target_frame: str, target_time: Time,
                                    source_frame: str, source_time: Time, fixed_frame: str,
                                    timeout: float | Duration | None = None, *,
                                    fail_fast: bool = False,
                                    policy: LookupPolicy | None = None
                                    ) -> TransformStamped | PolicyResult:
        """The server's ``lookup_transform_full_async`` (time travel through
        ``fixed_frame``); ``fail_fast`` and ``policy`` as :meth:`lookup_transform` (a
        non-exact policy applies to both legs and returns the server's
        :class:`~tfbus.core.policy.PolicyResult`).

        Raises: as :meth:`lookup_transform`.
        """
        client = self._policy_client(policy)
        if client is not None:
            answer: PolicyResult = await client.lookup_transform_full(
                target_frame, target_time, source_frame, source_time, fixed_frame, timeout,
                fail_fast=fail_fast, policy=policy)
            return answer
        return await self._client.lookup_transform_full(
            target_frame, target_time, source_frame, source_time, fixed_frame, timeout,
            fail_fast=fail_fast)

    @coroutine_method
    async def can_transform(self, target_frame: str, source_frame: str, time: Time,
                            timeout: float | Duration | None = None, *,
                            fail_fast: bool = False,
                            policy: LookupPolicy | None = None) -> bool:
        """Whether the server's buffer has the transform within ``timeout``; False also
        when the server does not answer in time. ``fail_fast`` and ``policy`` as
        :meth:`lookup_transform` (whether a lookup under the policy answers).

        Raises:
            ValueError: a bad timeout. TransportError: the bus closed.
            TypeError: as :meth:`lookup_transform` for ``policy``.
        """
        client = self._policy_client(policy)
        if client is not None:
            can: bool = await client.can_transform(target_frame, source_frame, time, timeout,
                                                   fail_fast=fail_fast, policy=policy)
            return can
        return await self._client.can_transform(target_frame, source_frame, time, timeout,
                                                fail_fast=fail_fast)

    @coroutine_method
    async def transform(self, obj: _M, target_frame: str,
                        timeout: float | Duration | None = None, *,
                        fail_fast: bool = False,
                        policy: LookupPolicy | None = None) -> _M | tuple[_M, PolicyReport]:
        """Express a stamped object in ``target_frame`` (tf2_ros ``BufferClient.transform``):
        the lookup is remote (``fail_fast`` and ``policy`` as :meth:`lookup_transform`),
        the function registered for ``type(obj)`` (:mod:`tfbus.convert`) is applied
        here. Under a non-exact ``policy``: ``(transformed object, PolicyReport)``.

        Raises:
            TypeError: no transform function for ``type(obj)`` (before any lookup), or
                as :meth:`lookup_transform` for ``policy``.
            The lookup's errors, as :meth:`lookup_transform`.
        """
        client = self._policy_client(policy)
        if client is not None:
            pair: tuple[_M, PolicyReport] = await client.transform(
                obj, target_frame, timeout, fail_fast=fail_fast, policy=policy)
            return pair
        return await self._client.transform(obj, target_frame, timeout, fail_fast=fail_fast)
