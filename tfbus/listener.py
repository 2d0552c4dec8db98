"""``TransformListener``: the task that feeds ``/tf`` and ``/tf_static`` into a buffer.

::

    async with Bus() as bus, TransformListener(buffer, bus):
        ...   # buffer fills up with every transform broadcast on bus

Each transform of each message is stored on its own: one bad transform (invalid
input, data older than the cache, a repeated stamp) is counted and logged (rate-limited)
and the valid ones beside it are stored. Objects that are not ``TFMessage``s are
counted and skipped. The listener never dies of bad input.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Protocol

import anyio
import anyio.abc

from tfbus.bus import TF_STATIC_TOPIC, TF_TOPIC, Bus, Subscription
from tfbus.clock import Clock, SystemClock
from tfbus.errors import TransformException
from tfbus.messages import TFMessage, TransformStamped

__all__ = ["ListenerStatistics", "TransformListener", "TransformSink"]

_log = logging.getLogger(__name__)


class TransformSink(Protocol):
    """What a listener feeds: ``BufferCore`` and ``Buffer`` both qualify.

    A sink that also has ``set_transforms(transforms, authority, is_static) -> (stored,
    refused, [(index, exception)])`` (as :meth:`tfbus.core.BufferCore.set_transforms`)
    gets each TFMessage in one call; otherwise the listener stores transform by transform.
    """

    def set_transform(self, transform: TransformStamped, authority: str, /) -> bool:
        """Store a dynamic transform; False if refused (old or repeated)."""
        ...

    def set_transform_static(self, transform: TransformStamped, authority: str, /) -> bool:
        """Store a static transform; False if refused."""
        ...


_Errors = list[tuple[int, Exception]]
_StoreMany = Callable[[Iterable[Any], str, bool], tuple[int, int, _Errors]]


def _store_each(sink: TransformSink) -> _StoreMany:
    """A batch store over a sink that only has the single-transform methods, with the
    result and error contract of :meth:`tfbus.core.BufferCore.set_transforms`."""

    def store_many(transforms: Iterable[Any], authority: str, is_static: bool) -> tuple[
        int, int, _Errors
    ]:
        store = sink.set_transform_static if is_static else sink.set_transform
        stored = refused = 0
        errors: _Errors = []
        for i, ts in enumerate(transforms):
            try:
                if not isinstance(ts, TransformStamped):
                    raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                if store(ts, authority):
                    stored += 1
                else:
                    refused += 1
            except Exception as exc:
                errors.append((i, exc))
        return stored, refused, errors

    return store_many


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


class _RateLimitedLog:
    """At most one warning per reason per ``period`` seconds of clock time."""

    __slots__ = ("_clock", "_last", "_period_ns", "_suppressed")

    def __init__(self, clock: Clock, period: float) -> None:
        self._clock = clock
        self._period_ns = round(period * 1e9)
        self._last: dict[str, int] = {}
        self._suppressed: dict[str, int] = {}

    def warn(self, reason: str, fmt: str, *args: object) -> None:
        if not _log.isEnabledFor(logging.WARNING):
            return
        now = self._clock.now().ns
        last = self._last.get(reason)
        if last is not None and last <= now < last + self._period_ns:
            self._suppressed[reason] = self._suppressed.get(reason, 0) + 1
            return
        self._last[reason] = now
        suppressed = self._suppressed.pop(reason, 0)
        more = f" ({suppressed} more like this suppressed)" if suppressed else ""
        _log.warning(fmt + "%s", *args, more)


class TransformListener:
    """Subscribes to ``/tf`` and ``/tf_static`` and stores every transform in a buffer.

    ``TransformListener(buffer, bus, *, authority="default_authority", clock=None,
    queue_size=None, log_period=5.0)``. Use ``async with``: entering subscribes to both
    topics and stores the latched static transforms before it returns (so a lookup right
    after sees them), then runs one task per topic in its own task group; leaving
    cancels the tasks and unregisters both subscriptions.

    Args:
        buffer: a ``BufferCore``, a ``Buffer``, or anything with their
            ``set_transform(ts, authority) -> bool`` and ``set_transform_static`` (see
            :class:`TransformSink`).
        bus: the bus to listen on (must be open).
        authority: the authority recorded with each transform (tf2_ros's Python
            listener uses ``"default_authority"``).
        clock: only used to rate-limit log messages (default: ``SystemClock()``).
        queue_size: queue capacity of each subscription (default: the bus's).
        log_period: seconds between two log messages for the same reason.
    """

    def __init__(
        self,
        buffer: TransformSink,
        bus: Bus,
        *,
        authority: str = "default_authority",
        clock: Clock | None = None,
        queue_size: int | None = None,
        log_period: float = 5.0,
    ) -> None:
        """Create a listener (not yet listening; use ``async with``)."""
        self._buffer = buffer
        # BufferCore and Buffer store a whole TFMessage in one compiled call.
        self._store_many: _StoreMany = getattr(buffer, "set_transforms", None) or _store_each(
            buffer
        )
        self._bus = bus
        self._authority = authority
        self._queue_size = queue_size
        self._log = _RateLimitedLog(clock if clock is not None else SystemClock(), log_period)
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
        """Subscribe, store the latched statics, start the listening tasks.

        Raises:
            RuntimeError: if the listener was already entered, or the bus is not open.
            anyio.ClosedResourceError: if the bus is closed.
        """
        if self._entered:
            raise RuntimeError("a TransformListener can be entered only once")
        self._entered = True
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
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        """Stop listening: cancel the tasks and unregister both subscriptions."""
        tg = self._task_group
        assert tg is not None
        try:
            tg.cancel_scope.cancel()
            return await tg.__aexit__(exc_type, exc, tb)
        finally:
            for sub in self._subs:
                sub.close()

    async def _run(self, sub: Subscription[Any], static: bool) -> None:
        async for message in sub:
            self._handle(message, static)
            self._drain(sub, static)

    def _drain(self, sub: Subscription[Any], static: bool) -> None:
        """Handle every message already queued, without yielding."""
        # Nothing else runs meanwhile, so the queue only shrinks: this terminates.
        while True:
            try:
                message = sub.receive_nowait()
            except (anyio.WouldBlock, anyio.EndOfStream, anyio.ClosedResourceError):
                return
            self._handle(message, static)

    def _handle(self, message: object, static: bool) -> None:
        self._messages += 1
        topic = TF_STATIC_TOPIC if static else TF_TOPIC
        if not isinstance(message, TFMessage):
            self._malformed += 1
            self._log.warn(
                "malformed",
                "ignoring a %s on %s: expected TFMessage",
                type(message).__name__,
                topic,
            )
            return
        try:
            transforms = iter(message.transforms)
        except TypeError:
            self._malformed += 1
            self._log.warn("malformed", "ignoring a TFMessage on %s: not iterable", topic)
            return
        stored, refused, errors = self._store_many(transforms, self._authority, static)
        self._stored += stored
        self._refused += refused
        for _, exc in errors:
            if isinstance(exc, TransformException):
                self._invalid += 1
                self._log.warn("invalid", "ignoring a transform on %s: %s", topic, exc)
            else:
                self._malformed += 1
                self._log.warn(
                    "malformed",
                    "ignoring a malformed transform on %s: %s: %s",
                    topic,
                    type(exc).__name__,
                    exc,
                )

    def statistics(self) -> ListenerStatistics:
        """A snapshot of the listener's counters."""
        return ListenerStatistics(
            messages=self._messages,
            stored=self._stored,
            refused=self._refused,
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
