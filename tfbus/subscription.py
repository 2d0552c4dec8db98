"""Subscriptions of a :class:`~tfbus.bus.Bus`: :class:`Subscription`, a
bounded drop-oldest queue read by a task, and :class:`CallbackSubscription`, a function
called inside each publish or delivery. Made by :meth:`~tfbus.bus.Bus.subscribe` and
:meth:`~tfbus.bus.Bus.subscribe_callback`; re-exported by :mod:`tfbus.bus`.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final, Generic, Protocol, TypeVar

import anyio
import anyio.lowlevel

from tfbus.core.kernels import compiled_extension
from tfbus.ratelimit import CountLimitedLog

__all__ = [
    "CallbackStatistics",
    "CallbackSubscription",
    "Subscription",
    "SubscriptionStatistics",
]

_log = logging.getLogger("tfbus.bus")

T = TypeVar("T")


class _Owner(Protocol):
    """What a subscription needs of its :class:`~tfbus.bus.Bus` (no import of it: the
    bus imports this module)."""

    def _counters(self, topic: str) -> _TopicCounters: ...

    def _unsubscribe(self, sub: Subscription[Any]) -> None: ...

    def _unsubscribe_callback(self, cb: CallbackSubscription) -> None: ...


@dataclass(frozen=True, slots=True)
class SubscriptionStatistics:
    """Counters of one subscription (``Subscription.statistics()``).

    ``delivered == received + dropped + queued`` at all times.

    Attributes:
        topic: the topic subscribed to.
        queue_size: the queue's capacity.
        queued: messages waiting in the queue now.
        delivered: messages put into the queue.
        received: messages taken out by ``receive``/``receive_nowait``/iteration.
        dropped: messages evicted unread because the queue was full (oldest first).
        tasks_waiting_receive: tasks blocked in ``receive()`` now.
    """

    topic: str
    queue_size: int
    queued: int
    delivered: int
    received: int
    dropped: int
    tasks_waiting_receive: int


class _PyTopicCounters:
    """The counters of one topic on one bus (the pure twin of
    ``tfbus._cbus.TopicCounters``, whose docstring says what each counts)."""

    __slots__ = ("delivered", "dropped", "published", "remote")

    def __init__(self) -> None:
        self.published = 0
        self.remote = 0
        self.delivered = 0
        self.dropped = 0


class _CallbackFields:
    """The fields of :class:`CallbackSubscription` a bus's delivery counts and calls (the
    pure twin of ``tfbus._cbus.CallbackFields``)."""

    __slots__ = ("_callback", "_counters", "_delivered")


def _compiled_fields() -> tuple[type, type]:
    """The classes of a topic's counters and of a callback subscription's delivered
    fields: the compiled ones (:mod:`tfbus._cbus`, where
    :func:`~tfbus.core.kernels.compiled_extension` finds it, which the compiled delivery
    counts in C), else their pure twins."""
    module = compiled_extension("tfbus._cbus")
    if module is None:
        return _PyTopicCounters, _CallbackFields
    return module.TopicCounters, module.CallbackFields


if TYPE_CHECKING:
    _TopicCounters = _PyTopicCounters
    _CallbackBase = _CallbackFields
else:
    _TopicCounters, _CallbackBase = _compiled_fields()


class Subscription(Generic[T]):
    """A bounded, drop-oldest queue of the messages published on one topic.

    Made by :meth:`~tfbus.bus.Bus.subscribe`; registered from creation until closed. Use it as a
    context manager (``async with`` or ``with``) so that leaving the block, by any route
    including cancellation, unregisters it. Iterate with ``async for msg in sub``
    (ends when the subscription or the bus closes), or call :meth:`receive` /
    :meth:`receive_nowait`.
    """

    def __init__(self, bus: _Owner, topic: str, queue_size: int) -> None:
        """Use :meth:`~tfbus.bus.Bus.subscribe` rather than building one directly."""
        self._bus = bus
        self._topic = topic
        self._queue_size = queue_size
        self._queue: deque[T] = deque()
        self._counters = bus._counters(topic)
        self._event: anyio.Event | None = None
        self._waiting = 0
        self._delivered = 0
        self._received = 0
        self._dropped = 0
        self._closed = False  # closed by its owner: receive raises ClosedResourceError
        self._ended = False  # the bus closed: receive drains, then raises EndOfStream

    @property
    def topic(self) -> str:
        """The topic subscribed to."""
        return self._topic

    @property
    def queue_size(self) -> int:
        """The queue's capacity."""
        return self._queue_size

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called."""
        return self._closed

    # -- fed by the bus ---------------------------------------------------------------

    def _put(self, message: T) -> None:
        queue = self._queue
        if len(queue) >= self._queue_size:
            queue.popleft()
            self._dropped += 1
            self._counters.dropped += 1
        queue.append(message)
        self._delivered += 1
        self._counters.delivered += 1
        event = self._event
        if event is not None:
            self._event = None
            event.set()

    def _end(self) -> None:
        self._ended = True
        self._wake()

    def _wake(self) -> None:
        event = self._event
        if event is not None:
            self._event = None
            event.set()

    # -- consumer side ----------------------------------------------------------------

    def receive_nowait(self) -> T:
        """Take the oldest queued message.

        Raises:
            anyio.ClosedResourceError: if this subscription was closed.
            anyio.EndOfStream: if the bus closed and the queue is empty.
            anyio.WouldBlock: if the queue is empty.
        """
        if self._closed:
            raise anyio.ClosedResourceError
        if self._queue:
            self._received += 1
            return self._queue.popleft()
        if self._ended:
            raise anyio.EndOfStream
        raise anyio.WouldBlock

    async def receive(self) -> T:
        """Wait for and take the oldest queued message (always a checkpoint).

        Raises:
            anyio.ClosedResourceError: if this subscription is or gets closed.
            anyio.EndOfStream: if the bus closed and the queue is empty.
            anyio.get_cancelled_exc_class(): if the calling task is cancelled.
        """
        await anyio.lowlevel.checkpoint()
        while True:
            try:
                return self.receive_nowait()
            except anyio.WouldBlock:
                pass
            if self._event is None:
                self._event = anyio.Event()
            event = self._event
            self._waiting += 1
            try:
                await event.wait()
            finally:
                self._waiting -= 1

    def __aiter__(self) -> Subscription[T]:
        return self

    async def __anext__(self) -> T:
        """The next message; iteration stops when the subscription or the bus closes.

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled.
        """
        try:
            return await self.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise StopAsyncIteration from None

    def close(self) -> None:
        """Unregister from the bus and discard queued messages (idempotent).

        Tasks blocked in :meth:`receive` raise ``anyio.ClosedResourceError`` (an
        ``async for`` just ends).
        """
        if self._closed:
            return
        self._closed = True
        self._queue.clear()
        self._bus._unsubscribe(self)
        self._wake()

    async def aclose(self) -> None:
        """:meth:`close`, then a cancel-shielded checkpoint (anyio's ``aclose`` style)."""
        self.close()
        await anyio.lowlevel.cancel_shielded_checkpoint()

    def statistics(self) -> SubscriptionStatistics:
        """A snapshot of this subscription's counters."""
        return SubscriptionStatistics(
            topic=self._topic,
            queue_size=self._queue_size,
            queued=len(self._queue),
            delivered=self._delivered,
            received=self._received,
            dropped=self._dropped,
            tasks_waiting_receive=self._waiting,
        )

    def __enter__(self) -> Subscription[T]:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    async def __aenter__(self) -> Subscription[T]:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "ended" if self._ended else "open"
        return (
            f"<Subscription {self._topic!r} {state} queued={len(self._queue)}/"
            f"{self._queue_size} dropped={self._dropped}>"
        )


class CallbackSubscription(_CallbackBase):
    """A function called with every message delivered on one topic, inside the publish or
    delivery itself (no queue, no task switch). Made by :meth:`~tfbus.bus.Bus.subscribe_callback`;
    registered until :meth:`close` (or ``with``-block exit) or until the bus closes.

    The callback runs in the publisher's task (or the transport's): it must be quick and
    must not block. An exception it raises is counted in :meth:`statistics` and logged
    (by count), never passed to the publisher; the other subscribers still get the
    message.
    """

    def __init__(self, bus: _Owner, topic: str, callback: Callable[[Any], None]) -> None:
        """Use :meth:`~tfbus.bus.Bus.subscribe_callback` rather than building one directly."""
        self._bus = bus
        self._topic = topic
        self._callback = callback
        self._counters = bus._counters(topic)
        self._delivered = 0
        self._errors = 0
        self._closed = False

    @property
    def topic(self) -> str:
        """The topic subscribed to."""
        return self._topic

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called or the bus closed."""
        return self._closed

    def _call(self, message: object) -> None:
        # A bus's delivery (Bus._deliver_each, or its compiled twin) makes this call
        # inline (the same four steps).
        self._delivered += 1
        self._counters.delivered += 1
        try:
            self._callback(message)
        except Exception as exc:  # never the publisher's problem
            self._failed(exc)

    def _failed(self, exc: Exception) -> None:
        """Count and log (by count) an exception the callback raised."""
        self._errors += 1
        _CALLBACK_ERRORS.log(
            logging.ERROR, "a %s callback raised %s: %s", self._topic, type(exc).__name__, exc
        )

    def close(self) -> None:
        """Unregister (idempotent): the callback is not called again."""
        if not self._closed:
            self._closed = True
            self._bus._unsubscribe_callback(self)

    def statistics(self) -> CallbackStatistics:
        """Messages passed to the callback, and how many times it raised."""
        return CallbackStatistics(self._topic, self._delivered, self._errors)

    def __enter__(self) -> CallbackSubscription:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"<CallbackSubscription {self._topic} {state} delivered={self._delivered}>"


@dataclass(frozen=True, slots=True)
class CallbackStatistics:
    """Counters of one :class:`CallbackSubscription`.

    Attributes:
        topic: the topic.
        delivered: messages passed to the callback.
        errors: calls that raised (counted and logged, not propagated).
    """

    topic: str
    delivered: int
    errors: int


_CALLBACK_ERRORS: Final = CountLimitedLog(_log, 1000, clock=time.monotonic)
