"""``SystemClock``: wall-clock time, sleeping on anyio's monotonic clock."""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Callable
from contextlib import AbstractContextManager
from functools import partial
from heapq import heapify, heappop, heappush
from itertools import count
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:
    from asyncio import AbstractEventLoop, TimerHandle

_COMPACT_AFTER = 64  # cancelled entries tolerated before they may be swept at once


class _LoopTimers:
    """The pending :meth:`SystemClock.call_later` callbacks in one asyncio loop.

    A heap of ``[when, seq, callback]`` entries (loop time, as ``loop.call_at``) with one
    loop timer armed at the earliest. Cancelling an entry only clears its callback: no
    loop timer is cancelled per call (a ``TimerHandle`` per call, cancelled on every
    wake-up, was most of what a ``timeout=`` added to a Buffer wait's wake-up). Cleared
    entries are dropped when they reach the top of the heap, or all at once when they are
    most of it, so nothing they referenced is kept for long.
    """

    __slots__ = ("_armed", "_armed_at", "_dead", "_heap", "_seq", "loop_ref")

    def __init__(self, loop: AbstractEventLoop) -> None:
        self.loop_ref = weakref.ref(loop)
        self._heap: list[list[Any]] = []
        self._seq = count()
        self._armed: TimerHandle | None = None
        self._armed_at = math.inf
        self._dead = 0

    def add(
        self, loop: AbstractEventLoop, when: float, callback: Callable[[], object]
    ) -> Callable[[], None]:
        entry = [when, next(self._seq), callback]
        heappush(self._heap, entry)
        if when < self._armed_at:
            if self._armed is not None:
                self._armed.cancel()
            self._armed = loop.call_at(when, self._fire)
            self._armed_at = when
        return partial(self._cancel, entry)

    def _cancel(self, entry: list[Any]) -> None:
        if entry[2] is None:  # already ran or cancelled
            return
        entry[2] = None
        self._dead += 1
        heap = self._heap
        if self._dead > _COMPACT_AFTER and 2 * self._dead > len(heap):
            heap[:] = [e for e in heap if e[2] is not None]
            heapify(heap)
            self._dead = 0
            if not heap and self._armed is not None:
                self._armed.cancel()
                self._armed = None
                self._armed_at = math.inf

    def _fire(self) -> None:
        loop = self.loop_ref()
        assert loop is not None  # it is running this
        due_at = max(loop.time(), self._armed_at)
        self._armed = None
        self._armed_at = math.inf
        heap = self._heap
        due: list[Callable[[], object]] = []
        while heap and (heap[0][0] <= due_at or heap[0][2] is None):
            entry = heappop(heap)
            callback = entry[2]
            if callback is None:
                self._dead -= 1
            else:
                entry[2] = None
                due.append(callback)
        if heap:
            self._armed_at = heap[0][0]
            self._armed = loop.call_at(self._armed_at, self._fire)
        for callback in due:
            try:
                callback()
            except Exception as exc:  # reported as a loop callback's would be
                loop.call_exception_handler(
                    {"message": "SystemClock.call_later callback raised", "exception": exc}
                )


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
        self._timers: _LoopTimers | None = None  # call_later's, in the latest loop used

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
        """On asyncio, a callback at ``loop.time() + seconds`` (the loop's monotonic
        clock, as :meth:`move_on_after`'s deadline; one loop timer serves every pending
        call of this clock). Under trio, which has no timer callbacks, ``None``: use
        :meth:`move_on_after`. See :meth:`Clock.call_later`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        if type(seconds) is float and 0.0 < seconds < math.inf:
            delay = seconds  # the common case, already what the loop counts in
        else:
            ns = timeout_ns(seconds, name="seconds")
            delay = math.inf if ns is None else ns / NSEC_PER_SEC
        loop = running_asyncio_loop()
        if loop is None:
            return None
        if delay == math.inf:
            return _noop
        if delay <= 0:
            callback()
            return _noop
        timers = self._timers
        if timers is None or timers.loop_ref() is not loop:
            timers = self._timers = _LoopTimers(loop)
        return timers.add(loop, loop.time() + delay, callback)

    def on_jump(self, callback: JumpCallback) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when the wall clock is seen going back.

        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into the task that observed the jump.
        """
        return self._jump.add(callback)

    def __repr__(self) -> str:
        return "SystemClock()"
