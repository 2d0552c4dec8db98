"""``SystemClock``: wall-clock time, sleeping on anyio's monotonic clock."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import AbstractContextManager

import anyio
import anyio.lowlevel

from tfbus.clock._base import (
    JumpCallback,
    _JumpCallbacks,
    _noop,
    running_asyncio_loop,
    timeout_ns,
)
from tfbus.time import NSEC_PER_SEC, Duration, Time


class SystemClock:
    """Wall-clock time (``time.time_ns``), the default for live use.

    ``sleep_until`` sleeps on anyio's monotonic clock and re-reads the wall clock when it
    wakes, so it always returns at or after the wall-clock deadline even if the wall clock
    was adjusted meanwhile; it wakes at least every ``max_sleep`` seconds to notice such
    adjustments. ``sleep(seconds)`` is a plain relative ``anyio.sleep``, immune to wall
    clock adjustments.

    A backward jump is detected whenever it is observed: the first ``now()`` (by anyone,
    including a sleeping ``sleep_until``) that reads a time earlier than the latest time
    read before fires the ``on_jump`` callbacks with ``(latest, new)``.
    """

    def __init__(self, *, max_sleep: float = 1.0) -> None:
        """Create a wall clock.

        Raises:
            ValueError: if ``max_sleep`` is not positive.
        """
        if not max_sleep > 0:
            raise ValueError(f"max_sleep must be positive, got {max_sleep!r}")
        self._max_sleep = max_sleep
        self._latest_ns = 0
        self._jump = _JumpCallbacks()

    def now(self) -> Time:
        """The wall-clock time; fires the jump callbacks if it went backwards since last read."""
        ns = time.time_ns()
        latest = self._latest_ns
        self._latest_ns = ns
        if ns < latest:
            self._jump.fire(Time.from_ns(latest), Time.from_ns(ns))
        return Time.from_ns(ns)

    async def sleep_until(self, t: Time) -> None:
        """Return once the wall clock reads ``>= t``.

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
        """
        remaining = t.ns - self.now().ns
        if remaining <= 0:
            await anyio.lowlevel.checkpoint()
            return
        while remaining > 0:
            await anyio.sleep(min(remaining / NSEC_PER_SEC, self._max_sleep))
            remaining = t.ns - self.now().ns

    async def sleep(self, seconds: float | Duration) -> None:
        """Sleep ``seconds`` of monotonic time (``anyio.sleep``; ``inf``: until cancelled).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        ns = timeout_ns(seconds, name="seconds")
        if ns is None:
            await anyio.sleep_forever()
        else:
            await anyio.sleep(max(ns, 0) / NSEC_PER_SEC)

    def move_on_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> anyio.CancelScope:
        """``anyio.move_on_after(seconds)``: a cancel scope with an event-loop deadline.

        The deadline is on anyio's monotonic clock, as every ``SystemClock`` sleep;
        ``None`` / ``inf`` = none. See :meth:`Clock.move_on_after`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        ns = timeout_ns(seconds)
        return anyio.move_on_after(None if ns is None else ns / NSEC_PER_SEC, shield=shield)

    def fail_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """``anyio.fail_after(seconds)``: raises ``TimeoutError`` when the deadline ends
        the block. See :meth:`Clock.fail_after`.

        Raises:
            TimeoutError: on leaving the block, if the deadline cancelled it.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        ns = timeout_ns(seconds)
        return anyio.fail_after(None if ns is None else ns / NSEC_PER_SEC, shield=shield)

    def call_later(
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        """On asyncio, ``loop.call_later(seconds, callback)`` (the loop's monotonic clock,
        as :meth:`move_on_after`'s deadline); returns the handle's ``cancel``. Under trio,
        which has no timer callbacks, ``None``: use :meth:`move_on_after`. See
        :meth:`Clock.call_later`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        ns = timeout_ns(seconds, name="seconds")
        loop = running_asyncio_loop()
        if loop is None:
            return None
        if ns is None:
            return _noop
        if ns <= 0:
            callback()
            return _noop
        return loop.call_later(ns / NSEC_PER_SEC, callback).cancel

    def on_jump(self, callback: JumpCallback) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when the wall clock is seen going back.

        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into the task that observed the jump.
        """
        return self._jump.add(callback)

    def __repr__(self) -> str:
        return "SystemClock()"
