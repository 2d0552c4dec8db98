"""``SystemClock``: wall-clock time, sleeping on anyio's monotonic clock."""

from __future__ import annotations

import logging
import math
import sys
import time
import weakref
from collections.abc import Callable, Hashable
from contextlib import AbstractContextManager
from functools import partial
from heapq import heapify, heappop, heappush
from itertools import count
from operator import setitem
from typing import TYPE_CHECKING, Any

import anyio
import anyio.lowlevel

from tfbus._aio import MILLISECOND_TIMERS, running_asyncio_loop, timer_delay
from tfbus.clock._base import (
    JumpCallback,
    _JumpCallbacks,
    _noop,
    timeout_ns,
)
from tfbus.time import NSEC_PER_SEC, Duration, Time

if TYPE_CHECKING:
    from asyncio import AbstractEventLoop, TimerHandle

_SWEEP_MIN = 128  # heap size below which cancelled entries are never swept at once

_log = logging.getLogger("tfbus.clock")


class _Timers:
    """The pending :meth:`SystemClock.call_later` callbacks of one clock in one run.

    A heap of ``[when, seq, callback]`` entries (the event loop's monotonic time) with
    one wake-up armed at the earliest (:meth:`_arm`: a loop timer on asyncio, the
    deadline of a timer task's cancel scope on trio). Cancelling an entry only clears its
    callback (``entry[2] = None``, no Python frame: it runs on every wake-up of a timed
    Buffer wait): nothing is cancelled in the event loop per call (a loop timer or a
    cancel scope per call, torn down on every wake-up, was most of what a ``timeout=``
    added to a wake-up). Cleared entries are dropped when they reach the top of the heap,
    and swept all at once whenever the heap has doubled since the last sweep, so the heap
    stays within twice its live entries (plus ``_SWEEP_MIN``) and a cancelled callback
    is never kept.
    """

    __slots__ = ("_armed_at", "_heap", "_seq", "_sweep_at")

    def __init__(self) -> None:
        self._heap: list[list[Any]] = []
        self._seq = count()
        self._armed_at = math.inf
        self._sweep_at = _SWEEP_MIN

    def add(self, when: float, callback: Callable[[], object]) -> Callable[[], None]:
        heap = self._heap
        if len(heap) >= self._sweep_at:
            heap[:] = [e for e in heap if e[2] is not None]
            heapify(heap)
            self._sweep_at = max(_SWEEP_MIN, 2 * len(heap))
        entry = [when, next(self._seq), callback]
        heappush(heap, entry)
        if when < self._armed_at:
            self._armed_at = when
            self._arm(when)
        return partial(setitem, entry, 2, None)

    def _arm(self, when: float) -> None:
        """Wake :meth:`_take_due` at ``when`` (``inf``: not at all), instead of before."""
        raise NotImplementedError

    def _take_due(self, now: float) -> list[Callable[[], object]]:
        """Pop the entries due by ``now`` (and cleared ones on top); the callbacks to run.
        ``_armed_at`` becomes the next entry's time: the caller arms it."""
        heap = self._heap
        due: list[Callable[[], object]] = []
        while heap and (heap[0][0] <= now or heap[0][2] is None):
            callback = heappop(heap)[2]
            if callback is not None:
                due.append(callback)
        self._armed_at = heap[0][0] if heap else math.inf
        return due


class _AsyncioTimers(_Timers):
    """:class:`_Timers` of one asyncio loop: one ``loop.call_at`` handle."""

    __slots__ = ("_handle", "loop_ref")

    def __init__(self, loop: AbstractEventLoop) -> None:
        super().__init__()
        self.loop_ref = weakref.ref(loop)
        self._handle: TimerHandle | None = None

    def _arm(self, when: float) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        loop = self.loop_ref()
        if when < math.inf and loop is not None:
            self._handle = loop.call_at(when, self._fire)

    def _fire(self) -> None:
        loop = self.loop_ref()
        assert loop is not None  # it is running this
        self._handle = None
        due = self._take_due(max(loop.time(), self._armed_at))
        if self._armed_at < math.inf:
            self._arm(self._armed_at)
        for callback in due:
            try:
                callback()
            except Exception as exc:  # reported as a loop callback's would be
                loop.call_exception_handler(
                    {"message": "SystemClock.call_later callback raised", "exception": exc}
                )


class _TrioTimers(_Timers):
    """:class:`_Timers` of one trio run: a system task sleeps in a cancel scope whose
    deadline is the earliest entry's (trio has no timer callbacks)."""

    __slots__ = ("_scope", "_trio")

    def __init__(self, trio: Any) -> None:
        super().__init__()
        self._trio = trio
        self._scope: Any = None  # trio.CancelScope while the task sleeps

    def _arm(self, when: float) -> None:
        if self._scope is not None:
            self._scope.deadline = when

    async def run(self) -> None:
        """The timer task (a trio system task: cancelled when the run ends)."""
        trio = self._trio
        while True:
            with trio.CancelScope(deadline=self._armed_at) as scope:
                self._scope = scope
                await trio.sleep_forever()
            self._scope = None
            for callback in self._take_due(trio.current_time()):
                try:
                    callback()
                except Exception:  # a system task must not raise
                    _log.exception("SystemClock.call_later callback %r raised", callback)


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
        self._timers: _AsyncioTimers | None = None  # call_later's, in the latest loop used
        self._trio_timers: Any = None  # trio.lowlevel.RunVar of this clock's _TrioTimers

    def now(self) -> Time:
        """The wall-clock time; fires the jump callbacks if it went backwards since last read."""
        return Time.from_ns(self.now_ns())

    def now_ns(self) -> int:
        """:meth:`now` as int nanoseconds, without building a Time (a listener reads the
        clock on every message)."""
        ns = time.time_ns()
        latest = self._latest_ns
        self._latest_ns = ns
        if ns < latest:
            self._jump.fire(Time.from_ns(latest), Time.from_ns(ns))
        return ns

    async def sleep_until(self, t: Time) -> None:
        """Return once the wall clock reads ``>= t`` (on uvloop, whose timers count
        whole milliseconds, up to 3 ms after: :func:`tfbus._aio.timer_delay`).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
        """
        remaining = t.ns - self.now().ns
        if remaining <= 0:
            await anyio.lowlevel.checkpoint()
            return
        loop = running_asyncio_loop()
        coarse = loop is not None and MILLISECOND_TIMERS.get(type(loop), True)
        while remaining > 0:
            seconds = min(remaining / NSEC_PER_SEC, self._max_sleep)
            if coarse:  # uvloop's timers: rounded up, not a busy loop at the end
                assert loop is not None
                seconds = timer_delay(loop, seconds)
            await anyio.sleep(seconds)
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
        """Call ``callback()`` at the event loop's monotonic time ``now + seconds`` (the
        clock of :meth:`move_on_after`'s deadlines): on asyncio one loop timer, on trio
        (no timer callbacks there) one system task sleeping in a cancel scope, serves
        every pending call of this clock in that loop. ``None`` outside asyncio and trio
        tasks. See :meth:`Clock.call_later`.

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
            return self._trio_call_later(delay, callback)
        if delay == math.inf:
            return _noop
        if delay <= 0:
            callback()
            return _noop
        timers = self._timers
        if timers is None or timers.loop_ref() is not loop:
            timers = self._asyncio_timers(loop)
        return timers.add(loop.time() + delay, callback)

    def _asyncio_timers(self, loop: AbstractEventLoop) -> _AsyncioTimers:
        """The :class:`_AsyncioTimers` of ``loop`` (made anew when the loop changed)."""
        timers = self._timers
        if timers is None or timers.loop_ref() is not loop:
            timers = self._timers = _AsyncioTimers(loop)
        return timers

    def _trio_call_later(
        self, delay: float, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        trio = sys.modules.get("trio")
        if trio is None:
            return None
        try:
            trio.lowlevel.current_task()
        except RuntimeError:  # not in a trio task either
            return None
        if delay == math.inf:
            return _noop
        if delay <= 0:
            callback()
            return _noop
        var = self._trio_timers
        if var is None:
            var = self._trio_timers = trio.lowlevel.RunVar("tfbus.SystemClock.call_later")
        timers: _TrioTimers | None = var.get(None)
        if timers is None:
            timers = _TrioTimers(trio)
            trio.lowlevel.spawn_system_task(timers.run, name="tfbus SystemClock timers")
            var.set(timers)
        return timers.add(trio.current_time() + delay, callback)

    def on_jump(
        self, callback: JumpCallback, *, key: Hashable | None = None
    ) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when the wall clock is seen going back.

        ``key``: one shared callback per key (:meth:`tfbus.clock.Clock.on_jump`).
        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into the task that observed the jump.
        """
        return self._jump.add(callback, key)

    def __repr__(self) -> str:
        return "SystemClock()"
