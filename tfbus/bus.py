"""The in-process message bus: topics, subscriptions with bounded queues, latching.

::

    async with Bus() as bus:
        async with bus.subscribe("/tf") as sub:
            bus.publish_nowait("/tf", TFMessage([ts]))
            msg = await sub.receive()

Publishing never blocks and never waits for subscribers: every :class:`Subscription`
has its own bounded queue and, when it is full, the *oldest* queued message is dropped
and counted (the newest data is what a transform consumer wants). A slow subscriber
therefore never slows a publisher or the other subscribers.

``/tf`` and ``/tf_static`` carry :class:`~tfbus.messages.TFMessage`. ``/tf_static`` is
latched per child frame (:class:`~tfbus.latch.StaticLatch`): the bus keeps the latest
valid static transform of every ``child_frame_id`` (a re-send replaces that child's
entry; ``laser`` and ``/laser`` are one child; an invalid transform never replaces a
valid one) and a new subscriber to ``/tf_static`` immediately receives one
``TFMessage`` holding all of them.

A :class:`Transport` (:mod:`tfbus.transports`: ``MemoryTransport``, Zenoh) carries
messages between buses: the bus runs ``transport.run(bus)`` in its task group, hands
every local publish to ``transport.send_nowait``, and the transport injects remote
messages with :meth:`Bus.deliver_nowait`, which never sends them back out.

Like anyio's memory object streams, every awaitable operation has a ``*_nowait`` twin
and both :class:`Bus` and :class:`Subscription` report ``statistics()``.

A :class:`CallbackSubscription` (:meth:`Bus.subscribe_callback`) is the other kind of
subscriber: a plain function called inside each publish or delivery on its topic, with no
queue and no task switch -- how a :class:`~tfbus.listener.TransformListener` stores
transforms the moment they are published (tf2_ros's listener is a subscription callback
too). Such a callback must be quick and must not raise: an exception is counted and
logged, never passed to the publisher.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from itertools import repeat
from types import TracebackType
from typing import Any, Final, Protocol, TypeVar, runtime_checkable

import anyio
import anyio.abc
import anyio.lowlevel

from tfbus._aio import ShieldedYield, _running_trio, exit_task_group, running_asyncio_loop
from tfbus.core.kernels import compiled_extension
from tfbus.latch import StaticLatch
from tfbus.messages import TFMessage
from tfbus.subscription import (
    CallbackStatistics,
    CallbackSubscription,
    Subscription,
    SubscriptionStatistics,
    _TopicCounters,
)
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

__all__ = [
    "MAX_IDLE_TOPICS",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "Bus",
    "CallbackStatistics",
    "CallbackSubscription",
    "Subscription",
    "SubscriptionStatistics",
    "TopicStatistics",
    "Transport",
]


_log = logging.getLogger(__name__)

_TF_TOPICS: Final = frozenset({TF_TOPIC, TF_STATIC_TOPIC})

MAX_IDLE_TOPICS: Final = 1024
"""Topics without a subscriber whose counters a bus keeps (:meth:`Bus.statistics`), the
latest to become idle; an older one's counters are dropped (they start again from 0 if
the topic is used again)."""

T = TypeVar("T")

_COMPILED = compiled_extension("tfbus._cbus")
"""The compiled delivery, cancellation test and yield after a publish (:mod:`tfbus._cbus`,
where :func:`~tfbus.core.kernels.compiled_extension` finds it), or None: the pure-Python
ones (``Bus._deliver_each``, :func:`_asyncio_cancel_called`'s closure,
:class:`~tfbus._aio.ShieldedYield`)."""


def _backend_checkpoint_if_cancelled() -> Callable[[], Awaitable[None]]:
    """``anyio.lowlevel.checkpoint_if_cancelled`` of the running event loop's backend,
    looked up once: the public function finds the backend on every call (sniffio and a
    module look-up: about a third of its cost, ~0.4 us of every publish on asyncio).
    ``anyio.lowlevel.current_token().backend_class`` is anyio's public way to it (anyio
    >= 4.11); with an older anyio, the public function itself."""
    current_token = getattr(anyio.lowlevel, "current_token", None)
    backend = getattr(current_token(), "backend_class", None) if current_token else None
    method = getattr(backend, "checkpoint_if_cancelled", None)
    return method if callable(method) else anyio.lowlevel.checkpoint_if_cancelled


def _backend_cancel_shielded_checkpoint() -> Callable[[], Awaitable[None]]:
    """``anyio.lowlevel.cancel_shielded_checkpoint`` of the running event loop's backend,
    looked up once, as :func:`_backend_checkpoint_if_cancelled` (on trio the public
    function's backend look-up is three of its seven Python calls)."""
    current_token = getattr(anyio.lowlevel, "current_token", None)
    backend = getattr(current_token(), "backend_class", None) if current_token else None
    method = getattr(backend, "cancel_shielded_checkpoint", None)
    return method if callable(method) else anyio.lowlevel.cancel_shielded_checkpoint


def _asyncio_cancel_called(loop: Any) -> Callable[[], bool] | None:
    """On anyio's asyncio backend, a plain function answering what
    ``checkpoint_if_cancelled`` finds out before it raises: whether a cancel scope
    around the calling task was cancelled, with no shielded scope in between (the same
    walk from the task's innermost scope outwards, over the same fields). A publish
    awaits the checkpoint only when it answers True, so an uncancelled publish creates
    no coroutine for it (about 1 us of the bus path on asyncio).

    The calling task is read from asyncio's table of ``loop``'s current tasks, and its
    anyio state from the ``WeakKeyDictionary``'s own dict, where present (two Python
    calls fewer on CPython 3.11); else through ``asyncio.current_task`` and ``get``. With
    those tables and the compiled core, the walk is ``tfbus._cbus.AsyncioCancelCalled``'s
    (C code, no Python frame).

    None when anyio's asyncio backend does not keep these (``_task_states``, a
    ``CancelScope``'s ``_cancel_called``, ``_shield`` and ``_parent_scope``): the bus then
    awaits the public checkpoint every time.
    """
    try:
        import asyncio.tasks
        from weakref import ref

        from anyio._backends._asyncio import CancelScope, _task_states
    except ImportError:  # pragma: no cover - an anyio without the asyncio backend module
        return None
    probe = CancelScope()
    if not all(hasattr(probe, a) for a in ("_cancel_called", "_shield", "_parent_scope")):
        return None  # pragma: no cover - another anyio layout: the public checkpoint
    tasks: Any = getattr(asyncio.tasks, "_current_tasks", None)
    states: Any = getattr(_task_states, "data", None)
    if not isinstance(tasks, dict) or not isinstance(states, dict):  # pragma: no cover
        current_task = asyncio.current_task
        weak_states = _task_states

        def cancel_called_portable() -> bool:
            state = weak_states.get(current_task())  # type: ignore[arg-type]
            return state is not None and _scope_cancelled(state.cancel_scope)

        return cancel_called_portable

    if _COMPILED is not None:  # the same walk in C
        compiled: Callable[[], bool] = _COMPILED.AsyncioCancelCalled(loop, tasks, states).called
        return compiled

    def cancel_called() -> bool:
        task = tasks.get(loop)
        state = None if task is None else states.get(ref(task))
        if state is None:
            return False
        scope = state.cancel_scope
        while scope is not None:
            if scope._cancel_called:
                return True
            if scope._shield:
                return False
            scope = scope._parent_scope
        return False

    return cancel_called


def _trio_cancel_called(lowlevel: Any) -> Callable[[], bool] | None:
    """On trio (``lowlevel``: ``trio.lowlevel``, called in a trio task), a plain function
    answering what ``trio.lowlevel.checkpoint_if_cancelled`` finds out before it
    checkpoints: whether the calling task's cancel status is effectively cancelled, or the
    task is the run's main task with a KeyboardInterrupt pending (trio
    ``_core/_run.py``: ``checkpoint_if_cancelled``, over the same fields). Answering
    False, it counts the task's cancel point (``Task._cancel_points``) as that function
    does on its uncancelled path. A publish awaits the checkpoint only when it answers
    True, so an uncancelled publish creates no coroutine for it (two Python calls and a
    coroutine of the bus path on trio).

    The calling task is the one trio's ``current_task`` reads (the run's thread-local
    context). None when trio does not keep these fields (the task's ``_cancel_status``
    with its ``effectively_cancelled``, ``_runner`` with its ``main_task`` and
    ``ki_pending``, ``_cancel_points``; that context): the bus then awaits the public
    checkpoint every time.
    """
    task = lowlevel.current_task()
    run = sys.modules.get("trio._core._run")
    context: Any = getattr(run, "GLOBAL_RUN_CONTEXT", None)
    status = getattr(task, "_cancel_status", None)
    runner = getattr(task, "_runner", None)
    if (
        getattr(context, "task", None) is not task
        or type(getattr(status, "effectively_cancelled", None)) is not bool
        or not hasattr(runner, "main_task")
        or type(getattr(runner, "ki_pending", None)) is not bool
        or type(getattr(task, "_cancel_points", None)) is not int
    ):
        return None  # pragma: no cover - another trio layout: the public checkpoint

    def cancel_called() -> bool:
        task = context.task
        if task._cancel_status.effectively_cancelled or (
            task is task._runner.main_task and task._runner.ki_pending
        ):
            return True
        task._cancel_points += 1
        return False

    return cancel_called


def _scope_cancelled(scope: Any) -> bool:
    """Whether ``scope`` or an enclosing scope up to the first shielded one (included)
    was cancelled: anyio's ``checkpoint_if_cancelled`` walk."""
    while scope is not None:
        if scope._cancel_called:
            return True
        if scope._shield:
            return False
        scope = scope._parent_scope
    return False


@runtime_checkable
class Transport(Protocol):
    """Carries topics between buses (processes, machines). Fixed contract.

    A bus calls ``await tg.start(transport.run, bus)`` when it opens and cancels it when
    it closes; it calls ``send_nowait`` for every locally published message.
    """

    async def run(
        self,
        bus: Bus,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Connect; ``task_status.started()``; then inject remote messages with
        ``bus.deliver_nowait(topic, message)`` until cancelled."""
        ...

    def send_nowait(self, topic: str, message: object) -> None:
        """Carry a locally published message to remote peers. Must never block."""
        ...


@dataclass(frozen=True, slots=True)
class TopicStatistics:
    """Counters of one topic on one bus (``Bus.statistics()``).

    Attributes:
        topic: the topic name.
        published: messages that entered the topic here (local publishes + remote).
        remote: of those, how many came in through the transport (``deliver_nowait``).
        delivered: message copies put into subscription queues or passed to callbacks
            (one per subscriber), including latched ``/tf_static`` snapshots given to
            late subscribers.
        dropped: copies evicted unread from a full subscription queue (drop-oldest).
        subscribers: subscriptions (queued and callback) open now.
    """

    topic: str
    published: int
    remote: int
    delivered: int
    dropped: int
    subscribers: int


class Bus:
    """Topics with subscriptions, ``/tf_static`` latching and an optional transport.

    ``Bus(transport=None, queue_size=100)``; ``queue_size`` is the default capacity of
    each subscription's queue. Open it with ``async with Bus() as bus:``; the bus owns a
    task group running the transport, and closing it stops the transport and ends every
    subscription (queued messages can still be read, then ``EndOfStream``).
    """

    def __init__(self, transport: Transport | None = None, queue_size: int = 100) -> None:
        """Create a bus (not yet open).

        Raises:
            ValueError: if ``queue_size`` is less than 1.
        """
        if queue_size < 1:
            raise ValueError(f"queue_size must be at least 1, got {queue_size!r}")
        self._transport = transport
        self._queue_size = queue_size
        self._subscriptions: dict[str, list[Subscription[Any]]] = {}
        self._callbacks: dict[str, list[CallbackSubscription]] = {}
        self._topic_counters: dict[str, _TopicCounters] = {}
        # Topics with counters and no subscription nor callback, the latest last.
        self._idle_topics: dict[str, None] = {}
        self._latch = StaticLatch()
        # What every publish and remote delivery runs: compiled, on these very objects,
        # with the compiled core; else _deliver_each.
        self._deliver: Callable[[str, object], None] = (
            self._deliver_each
            if _COMPILED is None
            else _COMPILED.Delivery(
                self._latch, self._topic_counters, self._subscriptions, self._callbacks,
                self._counters,
            ).deliver
        )
        self._task_group: anyio.abc.TaskGroup | None = None
        self._state = "new"  # "new" -> "open" -> "closed"
        # Called once when the bus closes (a TransformListener on it: its buffer's waits).
        self._on_close: list[Callable[[], None]] = []
        # The checkpoints around a publish: set for the event loop the bus is opened in.
        self._before_publish: Callable[[], Awaitable[None]] = (
            anyio.lowlevel.checkpoint_if_cancelled
        )
        self._after_publish: Callable[[], Awaitable[None]] = (
            anyio.lowlevel.cancel_shielded_checkpoint
        )
        # Whether the checkpoint before a publish must be awaited (it raises only when
        # this answers True); None: always await it (a backend whose cancellation state
        # tfbus cannot read).
        self._maybe_cancelled: Callable[[], bool] | None = None

    @property
    def transport(self) -> Transport | None:
        """The transport given at construction, if any."""
        return self._transport

    # -- lifecycle --------------------------------------------------------------------

    async def __aenter__(self) -> Bus:
        """Open the bus and start the transport (``await tg.start(transport.run, bus)``).

        Raises:
            RuntimeError: if the bus was already opened.
            Exception: whatever ``transport.run`` raises before it reports started.
        """
        if self._state != "new":
            raise RuntimeError("a Bus can be opened only once")
        loop = running_asyncio_loop()
        trio = None if loop is not None else _running_trio()
        if loop is not None:
            # A C callable giving the one ShieldedYield: no Python-level __call__.
            yield_type = ShieldedYield if _COMPILED is None else _COMPILED.ShieldedYield
            shielded_yield = yield_type(loop)
            self._after_publish = repeat(shielded_yield).__next__
            self._maybe_cancelled = _asyncio_cancel_called(loop)
            self._before_publish = _backend_checkpoint_if_cancelled()
        elif trio is not None:
            # trio's own pair, which anyio's trio backend wraps in one more coroutine each.
            self._after_publish = trio.cancel_shielded_checkpoint
            self._before_publish = trio.checkpoint_if_cancelled
            self._maybe_cancelled = _trio_cancel_called(trio)
        else:
            self._after_publish = _backend_cancel_shielded_checkpoint()
            self._before_publish = _backend_checkpoint_if_cancelled()
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._task_group = tg
        self._state = "open"
        if self._transport is not None:
            try:
                await tg.start(self._transport.run, self)
            except BaseException as exc:
                self._shutdown()
                tg.cancel_scope.cancel()
                await tg.__aexit__(None, None, None)
                raise exc
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        """Close the bus: end all subscriptions, leave every TransformListener still
        on it (the waits pending on their buffers fail with
        :class:`~tfbus.errors.BufferClosedException`, as when a listener is left) and
        cancel the transport task.

        What the ``async with`` body raised leaves as itself, never inside an
        ``ExceptionGroup`` (:func:`tfbus._aio.exit_task_group`): ``except
        TimeoutException:`` around the block catches a timeout raised in it.

        Raises:
            BaseException: the body's exception, as itself (a transport failure at the
                same time is its ``__context__``).
            BaseExceptionGroup: if the transport task failed while the body did not raise.
        """
        self._shutdown()
        tg = self._task_group
        assert tg is not None
        return await exit_task_group(tg, exc_type, exc, tb)

    def _shutdown(self) -> None:
        self._state = "closed"
        for subs in self._subscriptions.values():
            for sub in subs:
                sub._end()
        for callbacks in self._callbacks.values():
            for cb in callbacks:
                cb._closed = True
        self._callbacks.clear()
        hooks, self._on_close = self._on_close, []
        for hook in hooks:
            hook()

    def _check_open(self) -> None:
        if self._state == "open":
            return
        if self._state == "closed":
            raise anyio.ClosedResourceError("the bus is closed")
        raise RuntimeError("the bus is not open: use 'async with Bus() as bus:'")

    def _counters(self, topic: str) -> _TopicCounters:
        counters = self._topic_counters.get(topic)
        if counters is None:
            counters = self._topic_counters[topic] = _TopicCounters()
            if not self.reaches(topic):
                self._went_idle(topic)
        return counters

    def _went_idle(self, topic: str) -> None:
        """``topic`` has no subscription nor callback now: its empty lists go, and its
        counters are kept among the :data:`MAX_IDLE_TOPICS` latest idle topics' (memory
        bounded by the topics in use, not by every topic ever used)."""
        self._subscriptions.pop(topic, None)
        self._callbacks.pop(topic, None)
        self._idle_topics.pop(topic, None)
        self._idle_topics[topic] = None
        while len(self._idle_topics) > MAX_IDLE_TOPICS:
            oldest = next(iter(self._idle_topics))
            del self._idle_topics[oldest]
            if not self.reaches(oldest):
                self._topic_counters.pop(oldest, None)

    # -- subscribing --------------------------------------------------------------------

    def subscribe(self, topic: str, queue_size: int | None = None) -> Subscription[Any]:
        """Subscribe to ``topic``; the subscription is live as soon as this returns.

        A subscription to ``/tf_static`` starts with one ``TFMessage`` holding every
        latched static transform (if there are any).

        Args:
            topic: the topic name.
            queue_size: this subscription's queue capacity (default: the bus's).

        Raises:
            ValueError: if ``queue_size`` is less than 1.
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
        """
        self._check_open()
        size = self._queue_size if queue_size is None else queue_size
        if size < 1:
            raise ValueError(f"queue_size must be at least 1, got {size!r}")
        sub: Subscription[Any] = Subscription(self, topic, size)
        self._idle_topics.pop(topic, None)
        subs = self._subscriptions.get(topic)
        if subs is None:
            self._subscriptions[topic] = [sub]
        else:
            # Copy-on-write: a delivery loop in progress keeps its own list.
            self._subscriptions[topic] = [*subs, sub]
        if topic == TF_STATIC_TOPIC and self._latch:
            sub._put(self._latch.message())
        return sub

    def subscribe_callback(
        self, topic: str, callback: Callable[[Any], None]
    ) -> CallbackSubscription:
        """Call ``callback(message)`` inside every publish and delivery on ``topic``,
        from now on (see :class:`CallbackSubscription`). A callback on ``/tf_static`` is
        first called, before this returns, with one ``TFMessage`` holding every latched
        static transform (if there are any).

        Raises:
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
        """
        self._check_open()
        cb = CallbackSubscription(self, topic, callback)
        self._idle_topics.pop(topic, None)
        # Copy-on-write: a delivery loop in progress keeps its own list.
        self._callbacks[topic] = [*self._callbacks.get(topic, ()), cb]
        if topic == TF_STATIC_TOPIC and self._latch:
            cb._call(self._latch.message())
        return cb

    def _unsubscribe_callback(self, cb: CallbackSubscription) -> None:
        callbacks = self._callbacks.get(cb.topic)
        if callbacks is not None and cb in callbacks:
            self._callbacks[cb.topic] = [c for c in callbacks if c is not cb]
            if not self.reaches(cb.topic):
                self._went_idle(cb.topic)

    def _unsubscribe(self, sub: Subscription[Any]) -> None:
        subs = self._subscriptions.get(sub.topic)
        if subs is None or sub not in subs:
            return
        self._subscriptions[sub.topic] = [s for s in subs if s is not sub]
        if not self.reaches(sub.topic):
            self._went_idle(sub.topic)

    # -- publishing ---------------------------------------------------------------------

    def publish_nowait(self, topic: str, message: object) -> None:
        """Deliver ``message`` to every subscriber of ``topic`` here and to the transport.

        Never blocks: full subscription queues drop their oldest message.

        Raises:
            TypeError: if ``topic`` is ``/tf`` or ``/tf_static`` and ``message`` is not a
                ``TFMessage``.
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
            Exception: whatever ``transport.send_nowait`` raises (after local delivery).
        """
        if self._state != "open":
            self._check_open()
        if (
            type(message) is not TFMessage
            and topic in _TF_TOPICS
            and not isinstance(message, TFMessage)
        ):
            raise TypeError(f"{topic} carries TFMessage, not {type(message).__name__}")
        self._deliver(topic, message)
        if self._transport is not None:
            self._transport.send_nowait(topic, message)

    async def publish(self, topic: str, message: object) -> None:
        """:meth:`publish_nowait` plus a checkpoint; never waits for subscribers.

        Raises:
            TypeError: if ``topic`` is ``/tf`` or ``/tf_static`` and ``message`` is not a
                ``TFMessage``.
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
            Exception: whatever ``transport.send_nowait`` raises (after local delivery).
            anyio.get_cancelled_exc_class(): if cancelled (before publishing).
        """
        maybe_cancelled = self._maybe_cancelled
        if maybe_cancelled is None or maybe_cancelled():
            await self._before_publish()  # anyio's checkpoint_if_cancelled
        self.publish_nowait(topic, message)
        await self._after_publish()  # a cancel-shielded checkpoint: it was published

    def deliver_nowait(self, topic: str, message: object) -> None:
        """Deliver a *remote* message to local subscribers (for transports).

        Latches ``/tf_static`` like a local publish but does not send the message back to
        the transport, and does not type-check it (a listener guards against junk).

        A message that arrives once the bus is closing is dropped, not an error: the
        transport's task is being cancelled, and on asyncio it may still run once with
        data it had already received before its cancellation is delivered (anyio does
        not cancel a task whose awaited future is done).

        Raises:
            RuntimeError: if the bus is not open yet.
        """
        if self._state != "open":
            if self._state == "closed":
                return
            self._check_open()
        counters = self._topic_counters.get(topic)  # _counters, inline: a call fewer
        if counters is None:
            counters = self._counters(topic)
        counters.remote += 1
        self._deliver(topic, message)

    def deliver_many_nowait(self, topic: str, messages: Iterable[object]) -> None:
        """:meth:`deliver_nowait` for each of ``messages``, in order.

        Raises:
            RuntimeError: if the bus is not open yet.
        """
        if self._state != "open":
            if self._state == "closed":
                return  # closing: dropped, as in deliver_nowait
            self._check_open()
        for message in messages:
            self._counters(topic).remote += 1
            self._deliver(topic, message)

    def _deliver_each(self, topic: str, message: object) -> None:
        """Deliver ``message`` here: ``/tf_static`` latched, the topic's counters, each
        queued subscription's ``_put`` and each callback (counted; what it raises goes to
        its subscription's ``_failed``). The pure twin of ``tfbus._cbus.Delivery``."""
        if topic == TF_STATIC_TOPIC:
            self._latch.add(message)
        counters = self._topic_counters.get(topic)
        if counters is None:
            counters = self._counters(topic)
        counters.published += 1
        subs = self._subscriptions.get(topic)
        if subs:
            for sub in subs:
                sub._put(message)
        callbacks = self._callbacks.get(topic)
        if callbacks:
            for cb in callbacks:  # CallbackSubscription._call, inline: one call fewer
                cb._delivered += 1
                counters.delivered += 1
                try:
                    cb._callback(message)
                except Exception as exc:  # never the publisher's problem
                    cb._failed(exc)

    def reaches(self, topic: str) -> bool:
        """Whether a message delivered on ``topic`` now reaches anyone: a subscription
        or a callback on it, or the ``/tf_static`` latch, which hands it to subscribers
        still to come. A transport asks before it counts a payload as delivered (e.g. to
        drop a later copy of it as a duplicate)."""
        return (
            topic == TF_STATIC_TOPIC
            or bool(self._subscriptions.get(topic))
            or bool(self._callbacks.get(topic))
        )

    def listeners(self, topic: str) -> int:
        """How many subscriptions and callbacks on ``topic`` receive it here now (a
        newest-only transport asks, from its own thread, whether ``topic`` has listeners
        besides the :class:`~tfbus.clock.SimClock` following it newest-only)."""
        return len(self._subscriptions.get(topic, ())) + len(self._callbacks.get(topic, ()))

    def latched_statics(self) -> TFMessage:
        """One ``TFMessage`` of the latest static transform of every child frame.

        This is what a late ``/tf_static`` subscriber receives first; a transport may
        also send it to newly connected peers.
        """
        return self._latch.message()

    # -- statistics ---------------------------------------------------------------------

    def statistics(self) -> dict[str, TopicStatistics]:
        """Per topic: its counters, for every topic subscribed to now and for the
        :data:`MAX_IDLE_TOPICS` topics that most recently lost their last subscriber or
        were first published with none (a bus that sees ever new topic names, a fleet's
        robots coming and going, keeps a bounded record)."""
        return {
            topic: TopicStatistics(
                topic=topic,
                published=c.published,
                remote=c.remote,
                delivered=c.delivered,
                dropped=c.dropped,
                subscribers=len(self._subscriptions.get(topic, ()))
                + len(self._callbacks.get(topic, ())),
            )
            for topic, c in self._topic_counters.items()
        }

    def __repr__(self) -> str:
        subs = sum(len(s) for s in self._subscriptions.values())
        subs += sum(len(c) for c in self._callbacks.values())
        return f"<Bus {self._state} topics={len(self._topic_counters)} subscriptions={subs}>"
