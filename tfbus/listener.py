"""``TransformListener``: the task that feeds ``/tf`` and ``/tf_static`` into a buffer.

::

    async with Bus() as bus, TransformListener(buffer, bus):
        ...   # buffer fills up with every transform broadcast on bus

Each message is stored with one ``set_transforms`` call (a message of one transform
into a ``BufferCore`` or ``Buffer`` with the core's own batch store: one
``set_transform`` / ``set_transform_static`` call, counted alike); one bad transform (invalid
input, data older than the cache, a repeated stamp) is counted and logged (rate-limited
on the listener's clock, :mod:`tfbus.ratelimit`) and the valid ones beside it are
stored. On each message the listener reads its clock and clears the buffer when time
jumped back (tf2_ros ``TransformListener``). Objects that are not ``TFMessage``s are
counted and skipped. The listener never dies of bad input.

With the compiled core, a ``TFMessage`` whose transforms are a tuple (what a broadcaster
and every transport deliver) is stored by the compiled handler
:class:`tfbus._clistener.InlineHandler` (no Python frame between the bus and the store;
the same counts, warnings, authorities and clock read as
:meth:`TransformListener._handle`, which handles every other message, and every message
with the pure-Python core).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

import anyio
import anyio.abc

from tfbus._aio import exit_task_group
from tfbus.buffer import Buffer, clear_on_jump_back
from tfbus.bus import Bus, CallbackSubscription, Subscription
from tfbus.clock import Clock, SystemClock
from tfbus.core import BatchResult, BufferCore
from tfbus.core.kernels import compiled_extension
from tfbus.errors import TransformException
from tfbus.messages import TFMessage, TransformStamped
from tfbus.ratelimit import RateLimitedLog
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

if TYPE_CHECKING:
    from tfbus._clistener import InlineHandler

__all__ = ["ListenerStatistics", "TransformListener", "TransformSink"]

_log = logging.getLogger(__name__)


def _compiled_handler() -> type[InlineHandler] | None:
    """The compiled message handler (:class:`tfbus._clistener.InlineHandler`: a message
    stored with no Python frame, where :func:`~tfbus.core.kernels.compiled_extension` finds
    it), else None: the listener's own ``_handle`` handles every message."""
    module = compiled_extension("tfbus._clistener")
    if module is None:
        return None
    compiled: type[InlineHandler] = module.InlineHandler
    return compiled


_HANDLER = _compiled_handler()
"""The compiled handler class, or None; read when a listener subscribes."""


class TransformSink(Protocol):
    """What a listener feeds: :class:`~tfbus.core.BufferCore` and
    :class:`~tfbus.buffer.Buffer` both qualify.

    Each TFMessage is stored with one ``set_transforms`` call (as
    :meth:`tfbus.core.BufferCore.set_transforms`: ``stored``, ``refused`` and
    ``errors``, ``[(index, exception)]``, are read from its result); ``clear`` is called
    when the clock jumps back (tf2_ros ``TransformListener``).
    """

    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str, is_static: bool, /
    ) -> BatchResult:
        """Store a batch; report counts and per-item errors; never raise for bad items."""
        ...

    def clear(self) -> None:
        """Drop all dynamic data (static transforms stay)."""
        ...


@dataclass(frozen=True, slots=True)
class ListenerStatistics:
    """Counters of a :class:`TransformListener`.

    Attributes:
        messages: TFMessages handled (both topics).
        stored: transforms the buffer accepted.
        refused: transforms the buffer refused (TF_OLD_DATA / TF_REPEATED_DATA: data
            older than the cache window, or a stamp it already has). ``BufferCore``
            itself logs these as TF_OLD_DATA / TF_REPEATED_DATA warnings.
        invalid: transforms the buffer rejected as malformed
            (``TransformException``, e.g. ``InvalidArgumentException``: NaN, bad
            quaternion, empty or self frame id).
        malformed: objects on the topics that are not ``TFMessage``s, and items of a
            TFMessage that are not ``TransformStamped``s or that broke the buffer in
            some other way (any other ``Exception``).
        dropped: messages the listener's subscriptions dropped because it fell behind.
    """

    messages: int
    stored: int
    refused: int
    invalid: int
    malformed: int
    dropped: int


class TransformListener:
    """Subscribes to ``/tf`` and ``/tf_static`` and stores every transform in a buffer.

    ``TransformListener(buffer, bus, *, authority=None, clock=None,
    queue_size=None, log_period=5.0, inline=True)``. Use ``async with``: entering
    subscribes to both topics and stores the latched static transforms before it returns
    (so a lookup right after sees them); leaving unregisters both subscriptions.

    Inline (the default, as tf2_ros's listener is a subscription callback): each message
    is stored inside the publish or delivery that carries it
    (:meth:`tfbus.bus.Bus.subscribe_callback`), so a waiting lookup is woken with no task
    switch in between. With ``inline=False`` the listener reads bounded queues in one task
    per topic instead (``queue_size``; a slow buffer then drops the oldest messages rather
    than slowing publishers).

    Args:
        buffer: a ``BufferCore``, a ``Buffer``, or anything with their
            ``set_transforms`` and ``clear`` (see :class:`TransformSink`).
        bus: the bus to listen on (must be open).
        authority: the authority recorded with each transform. None (the default):
            the publisher's name where the transport gives one — ROS 1's caller id
            (the TCPROS ``callerid``, as tf2_ros's ROS 1 listener records
            ``msg_evt.getPublisherName()``), carried by the message's class
            (:func:`tfbus.transports.ros1.transport.tf_message_from`) — else
            ``"default_authority"`` (tf2_ros's ROS 2 listener's). A string: that
            authority for every transform.
        clock: read on each message, as tf2_ros does: a time earlier than the last one
            read is a jump back, which clears the buffer; also paces log messages.
            Default: the buffer's clock for a ``Buffer``, else ``SystemClock()``.
        queue_size: with ``inline=False``, queue capacity of each subscription (default:
            the bus's).
        log_period: seconds between two log messages for the same reason.
        inline: store in the publisher's call (default) instead of in listener tasks.
    """

    def __init__(
        self,
        buffer: TransformSink,
        bus: Bus,
        *,
        authority: str | None = None,
        clock: Clock | None = None,
        queue_size: int | None = None,
        log_period: float = 5.0,
        inline: bool = True,
    ) -> None:
        """Create a listener (not yet listening; use ``async with``)."""
        self._buffer = buffer
        self._bus = bus
        self._authority = "default_authority" if authority is None else authority
        self._publisher_authority = authority is None
        self._queue_size = queue_size
        self._inline = inline
        self._callbacks: list[CallbackSubscription] = []
        self._handlers: list[InlineHandler] = []  # the compiled ones: their counts
        if clock is None:
            clock = buffer.clock if isinstance(buffer, Buffer) else SystemClock()
        self._clock = clock
        # The clock read on every message: now_ns() builds no Time.
        self._now_ns: Callable[[], int] = clock.now_ns
        self._unfollow_jumps: Callable[[], None] | None = None
        # A message of one transform into a BufferCore (or a Buffer) that keeps the
        # core's batch store goes through its one-transform store, set_transform(_static):
        # the same checks, counts and wake-ups at a fraction of a one-item batch's cost.
        self._store_one: tuple[Callable[[Any, str], bool], Callable[[Any, str], bool]] | None
        self._store_one = None
        # A subclass that overrides any of the three keeps the batch store.
        kind: Any = type(buffer)
        if (
            isinstance(buffer, BufferCore)
            and "set_transforms" not in getattr(buffer, "__dict__", ())
            and kind.set_transforms in (Buffer.set_transforms, BufferCore.set_transforms)
            and kind.set_transform in (Buffer.set_transform, BufferCore.set_transform)
            and kind.set_transform_static
            in (Buffer.set_transform_static, BufferCore.set_transform_static)
        ):
            self._store_one = (buffer.set_transform, buffer.set_transform_static)
        self._log = RateLimitedLog(_log, log_period)
        self._task_group: anyio.abc.TaskGroup | None = None
        self._subs: list[Subscription[Any]] = []
        self._entered = False
        self._messages = 0
        self._stored = 0
        self._refused = 0
        self._invalid = 0
        self._malformed = 0

    @property
    def buffer(self) -> TransformSink:
        """The buffer fed."""
        return self._buffer

    async def __aenter__(self) -> TransformListener:
        """Subscribe and store the latched statics (then, with ``inline=False``, start
        the listening tasks).

        Raises:
            RuntimeError: if the listener was already entered, or the bus is not open.
            anyio.ClosedResourceError: if the bus is closed.
        """
        if self._entered:
            raise RuntimeError("a TransformListener can be entered only once")
        self._entered = True
        # A jump back of the clock read on each message clears the sink (one owner; a
        # Buffer on this clock already follows it, and is cleared once).
        self._unfollow_jumps = clear_on_jump_back(self._buffer, self._clock)
        if self._inline:
            self._callbacks = [
                self._bus.subscribe_callback(TF_STATIC_TOPIC, self._handler(True))
            ]
            try:
                self._callbacks.append(
                    self._bus.subscribe_callback(TF_TOPIC, self._handler(False))
                )
            except BaseException:
                self._callbacks[0].close()
                raise
            self._feed_started()
            return self
        static = self._bus.subscribe(TF_STATIC_TOPIC, self._queue_size)
        try:
            dynamic = self._bus.subscribe(TF_TOPIC, self._queue_size)
        except BaseException:
            static.close()
            raise
        self._subs = [static, dynamic]
        self._drain(static, True)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._task_group = tg
        tg.start_soon(self._run, static, True, name="TransformListener /tf_static")
        tg.start_soon(self._run, dynamic, False, name="TransformListener /tf")
        self._feed_started()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        """Stop listening: unregister both subscriptions (and cancel the tasks). When this
        was the last listener feeding its :class:`~tfbus.buffer.Buffer`, the waits
        pending on it fail at once with :class:`~tfbus.errors.BufferClosedException`
        (nothing will store the data they wait for); the buffer stays usable. What the
        ``async with`` body raised leaves as itself (:func:`tfbus._aio.exit_task_group`)."""
        if self._unfollow_jumps is not None:
            self._unfollow_jumps()
        if self._feed_ended in self._bus._on_close:
            self._bus._on_close.remove(self._feed_ended)
            self._feed_ended()
        for cb in self._callbacks:
            cb.close()
        tg = self._task_group
        if tg is None:
            return None
        try:
            return await exit_task_group(tg, exc_type, exc, tb)
        finally:
            for sub in self._subs:
                sub.close()

    def _handler(self, static: bool) -> Callable[[object], None]:
        """The bus callback of one topic: the compiled handler
        (:class:`tfbus._clistener.InlineHandler`) when it is built and the buffer has the
        one-transform store, else :meth:`_handle` for that topic."""
        store = self._store_one
        if _HANDLER is None or store is None:
            return partial(self._handle, static)
        handler = _HANDLER(self, static, store[static], self._buffer.set_transforms,
                           self._now_ns, self._authority, self._publisher_authority)
        self._handlers.append(handler)
        return handler

    def _feed_started(self) -> None:
        if isinstance(self._buffer, Buffer):
            self._buffer._listener_entered()
            self._bus._on_close.append(self._feed_ended)

    def _feed_ended(self) -> None:
        """This listener no longer feeds its Buffer (left, or its bus closed): the
        buffer's pending waits fail if no other listener feeds it."""
        assert isinstance(self._buffer, Buffer)
        self._buffer._listener_left()

    async def _run(self, sub: Subscription[Any], static: bool) -> None:
        async for message in sub:
            self._handle(static, message)
            self._drain(sub, static)

    def _drain(self, sub: Subscription[Any], static: bool) -> None:
        """Handle every message already queued, without yielding."""
        # Nothing else runs meanwhile, so the queue only shrinks: this terminates.
        while True:
            try:
                message = sub.receive_nowait()
            except (anyio.WouldBlock, anyio.EndOfStream, anyio.ClosedResourceError):
                return
            self._handle(static, message)

    def _warn(self, now_ns: int, msg: str, *args: object) -> None:
        """One rate-limited warning, timed by the clock read of the message it is about."""
        self._log.log(now_ns / 1e9, logging.WARNING, msg, *args)

    def _handle(self, static: bool, message: object) -> None:
        self._messages += 1
        # tf2_ros TransformListener::subscription_callback_impl reads the clock on each
        # message: the time of this message's warnings; a SystemClock that reads earlier
        # than before fires its on_jump callbacks then (the clock owns the detection;
        # clear_on_jump_back's callback clears the sink).
        now_ns = self._now_ns()
        authority = self._authority
        if type(message) is not TFMessage:  # a subclass (or junk): checked and named
            if not isinstance(message, TFMessage):
                self._malformed += 1
                self._warn(
                    now_ns,
                    "ignoring a %s on %s: expected TFMessage",
                    type(message).__name__,
                    TF_STATIC_TOPIC if static else TF_TOPIC,
                )
                return
            if self._publisher_authority:
                named = getattr(type(message), "authority", None)
                if isinstance(named, str) and named:
                    authority = named
        transforms = message.transforms
        one = self._store_one
        if one is not None and type(transforms) is tuple and len(transforms) == 1:
            # The one-transform store (see __init__), counted and logged as the items of
            # a batch below: stored, refused (False: TF_OLD_DATA or TF_REPEATED_DATA,
            # which the core logs), invalid (a TransformException), malformed (any other
            # Exception, e.g. TypeError for an item that is not a TransformStamped).
            try:
                stored = one[static](transforms[0], authority)
            except Exception as failed:
                self._store_failed(static, now_ns, failed)
                return
            if stored:
                self._stored += 1
            else:
                self._refused += 1
            return
        topic = TF_STATIC_TOPIC if static else TF_TOPIC
        try:
            items = iter(transforms)
        except TypeError:
            self._malformed += 1
            self._warn(now_ns, "ignoring a TFMessage on %s: not iterable", topic)
            return
        try:
            result = self._buffer.set_transforms(items, authority, static)
        except Exception as bug:  # a sink that breaks its contract: count, never die
            self._sink_failed(static, now_ns, bug)
            return
        self._stored += result.stored
        self._refused += result.refused
        for _, exc in result.errors:
            self._store_failed(static, now_ns, exc)

    def _sink_failed(self, static: bool, now_ns: int, bug: Exception) -> None:
        """Count and log a message whose ``set_transforms`` raised (a sink that breaks its
        contract: it should return each item's error instead), as malformed; here or in
        the compiled handler. Never raised to the publisher."""
        self._malformed += 1
        self._warn(now_ns, "ignoring a TFMessage on %s: %s: %s",
                   TF_STATIC_TOPIC if static else TF_TOPIC, type(bug).__name__, bug)

    def _store_failed(self, static: bool, now_ns: int, failed: Exception) -> None:
        """Count and log a transform the buffer did not take because it raised: the
        exception of a one-transform store (here or in the compiled handler) or one of a
        batch's ``errors``. Invalid: a ``TransformException``; malformed: any other
        ``Exception`` (e.g. ``TypeError`` for an item that is not a TransformStamped)."""
        topic = TF_STATIC_TOPIC if static else TF_TOPIC
        if isinstance(failed, TransformException):
            self._invalid += 1
            self._warn(now_ns, "ignoring a transform on %s: %s", topic, failed)
        else:
            self._malformed += 1
            self._warn(
                now_ns,
                "ignoring a malformed transform on %s: %s: %s",
                topic,
                type(failed).__name__,
                failed,
            )

    def statistics(self) -> ListenerStatistics:
        """A snapshot of the listener's counters."""
        handlers = self._handlers
        return ListenerStatistics(
            messages=self._messages + sum(h.messages for h in handlers),
            stored=self._stored + sum(h.stored for h in handlers),
            refused=self._refused + sum(h.refused for h in handlers),
            invalid=self._invalid,
            malformed=self._malformed,
            dropped=sum(sub.statistics().dropped for sub in self._subs),
        )

    def __repr__(self) -> str:
        s = self.statistics()
        return (
            f"<TransformListener stored={s.stored} refused={s.refused} invalid={s.invalid} "
            f"malformed={s.malformed} dropped={s.dropped}>"
        )
