"""Periodic timers: ``every()``, ``PeriodicTimer``, ``Tick`` (``ros::Rate``/``Timer``)."""

from __future__ import annotations

import math
import sys
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio

from tfbus._aio import MILLISECOND_TIMERS, Wakeup, running_asyncio_loop, timer_delay
from tfbus.clock._base import Clock
from tfbus.clock._system import SystemClock
from tfbus.time import NSEC_PER_SEC, TIME_MAX_NS, Duration, Time, seconds_to_ns

if TYPE_CHECKING:
    from asyncio import AbstractEventLoop, Future, TimerHandle

_new_time = Time.__new__


def _wake_future(future: Future[None]) -> None:
    """End a timer's wait on ``future`` (idempotent; harmless once it is cancelled)."""
    if not future.done():
        future.set_result(None)


@dataclass(frozen=True, slots=True)
class Tick:
    """One firing of a :class:`PeriodicTimer`.

    Attributes:
        index: the number of the deadline this tick is for, from 0. Skipped deadlines
            use up their numbers, so ticks delivered so far = ``index + 1 - overruns``.
        expected: the deadline (``first + index * period`` since the last re-anchor).
        actual: the clock's time when the tick was delivered (``>= expected``).
        overruns: deadlines skipped so far because the loop was too late for them.
    """

    index: int
    expected: Time
    actual: Time
    overruns: int

    @property
    def lateness(self) -> Duration:
        """``actual - expected``: how late this tick was delivered (timer jitter)."""
        return self.actual - self.expected


class PeriodicTimer:
    """An async iterator of :class:`Tick` at absolute deadlines (``ros::Rate``/``Timer``).

    Made by :func:`every`. Deadlines are ``first + k * period``, where ``first`` is the
    time of the first iteration plus ``period`` (or plus 0 with ``immediate=True``).

    Overrun policy (``rcl_timer``'s): when the loop asks for the next tick and one or more
    deadlines have already passed, the timer fires at once for the *latest* passed
    deadline (``actual > expected``) and skips the older ones, adding them to
    ``overruns``. The schedule never drifts: a slow body costs ticks, not phase.

    A backward clock jump (``clock.on_jump``, or ``now()`` found below the previous
    reading) re-anchors the schedule: the next deadline becomes ``new_now + period``.

    Each tick's wait is one deadline of the clock (on the wall clock under asyncio one
    ``loop.call_at`` timer and one future; under trio on the wall clock one ``trio``
    cancel scope with that deadline, as ``trio.sleep``; otherwise ``call_later`` and a
    one-shot wake-up) that the jump callback ends early; the clock is read with
    ``now_ns()``. No anyio cancel scope is entered per tick, and the jump callback is
    registered with the clock once per timer (on its first wait; unregistered when the
    timer is collected), not per tick.
    """

    def __init__(
        self, period: float | Duration, *, clock: Clock | None = None, immediate: bool = False
    ) -> None:
        """See :func:`every` (``clock=None``: a :class:`~tfbus.clock.SystemClock`).

        Raises:
            ValueError: if ``period`` is not positive, or not finite.
            TypeError: if ``period`` is not a number of seconds nor a Duration.
        """
        period_ns = seconds_to_ns(period, name="period")
        if period_ns <= 0:
            raise ValueError(f"period must be positive, got {period!r}")
        self._period_ns = period_ns
        if clock is None:
            clock = SystemClock()
        self._clock = clock
        self._immediate = immediate
        self._anchor_ns: int | None = None  # deadline of index _anchor_index
        self._anchor_index = 0
        self._next_index = 0
        self._overruns = 0
        self._last_seen_ns = 0
        self._jumped = False
        self._wake: Callable[[], object] | None = None  # ends the wait in progress
        self._future: Future[None] | None = None  # or the asyncio wall-clock wait's
        self._handle: TimerHandle | None = None  # and its loop timer
        self._jump_clock: Clock | None = None  # the clock on_jump was registered with

    @property
    def period(self) -> Duration:
        """The period."""
        return Duration.from_ns(self._period_ns)

    @property
    def overruns(self) -> int:
        """Deadlines skipped so far."""
        return self._overruns

    def __aiter__(self) -> PeriodicTimer:
        return self

    def _reanchor(self, now_ns: int) -> None:
        self._anchor_index = self._next_index
        self._anchor_ns = now_ns + self._period_ns

    def _watch_jumps(self, clock: Clock) -> None:
        """Register this timer's one backward-jump callback with ``clock`` (on its first
        wait; unregistered when the timer is collected). It wakes the wait in progress
        (:attr:`_future` or :attr:`_wake`), if any, and marks the schedule for
        re-anchoring; a jump while no wait is in progress is left to the ``now_ns``
        comparison, as before."""
        ref = weakref.ref(self)

        def on_jump(old: Time, new: Time) -> None:
            timer = ref()
            if timer is None:
                return
            if (future := timer._future) is not None:
                timer._jumped = True
                if (handle := timer._handle) is not None:
                    handle.cancel()
                _wake_future(future)
            elif (wake := timer._wake) is not None:
                timer._jumped = True
                wake()

        self._jump_clock = clock
        weakref.finalize(self, clock.on_jump(on_jump))

    async def __anext__(self) -> Tick:
        """Wait for the next deadline and return its tick.

        Per tick on a :class:`~tfbus.clock.SystemClock` under asyncio: two clock reads,
        one loop timer (``loop.call_at``) and one bare future; the jump callback is
        registered once per timer, not per tick.

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled.
        """
        clock = self._clock
        period_ns = self._period_ns
        if self._anchor_ns is None:
            now_ns = clock.now_ns()
            self._last_seen_ns = now_ns
            self._anchor_index = 0
            self._anchor_ns = now_ns + (0 if self._immediate else period_ns)
        if self._jump_clock is not clock:
            self._watch_jumps(clock)
        while True:
            now_ns = clock.now_ns()
            if now_ns < self._last_seen_ns or self._jumped:
                self._jumped = False
                self._reanchor(now_ns)
            self._last_seen_ns = now_ns
            anchor_ns = self._anchor_ns
            assert anchor_ns is not None
            deadline = anchor_ns + (self._next_index - self._anchor_index) * period_ns
            if now_ns >= deadline:
                # Latest deadline already passed; skip the older ones.
                behind = (now_ns - deadline) // period_ns
                index = self._next_index + behind
                self._overruns += behind
                self._next_index = index + 1
                expected_ns = deadline + behind * period_ns
                if not 0 <= expected_ns <= now_ns <= TIME_MAX_NS:
                    Time.from_ns(expected_ns), Time.from_ns(now_ns)  # raises the range error
                # Time.from_ns without its call (both checked in range just above).
                expected = _new_time(Time)
                expected._ns = expected_ns
                actual = _new_time(Time)
                actual._ns = now_ns
                return Tick(index, expected, actual, self._overruns)
            # The wait (see _wait), inline on the wall clock (the demo's): under asyncio
            # one loop timer straight to an idempotent wake of one future (no entry in
            # the clock's timer queue, no closure): a cancellation handled in the same
            # pass of the loop, before the timer, leaves a done future to it. The
            # timer fires once and is done; it is cancelled only when the wait ends
            # otherwise (the jump callback cancels it; a cancellation), so that no
            # stale timer wakes the loop for nothing. Under trio one cancel scope with
            # the deadline (no coroutine of ours around it).
            loop = running_asyncio_loop()
            if type(clock) is SystemClock:
                seconds = min((deadline - now_ns) / NSEC_PER_SEC, clock._max_sleep)
                if loop is not None:
                    if MILLISECOND_TIMERS.get(type(loop), True):  # uvloop's timers: rounded up
                        seconds = timer_delay(loop, seconds)
                    future = loop.create_future()
                    self._handle = handle = loop.call_at(
                        loop.time() + seconds, _wake_future, future
                    )
                    self._future = future
                    try:
                        await future
                    except BaseException:
                        handle.cancel()
                        raise
                    finally:
                        self._future = None
                    continue
                if (trio := sys.modules.get("trio")) is not None:
                    with trio.CancelScope(deadline=trio.current_time() + seconds) as scope:
                        self._wake = scope.cancel
                        try:
                            await trio.sleep_forever()
                        finally:
                            self._wake = None
                    continue
            await self._wait(clock, loop, now_ns, deadline)

    async def _wait(
        self, clock: Clock, loop: AbstractEventLoop | None, now_ns: int, deadline: int
    ) -> None:
        """Sleep until ``deadline`` (ns of ``clock``) or a backward jump of ``clock``,
        whichever comes first; the caller re-reads the clock after it. (A
        :class:`~tfbus.clock.SystemClock` under asyncio or trio waits inline in
        :meth:`__anext__` instead.)

        One deadline callback (:meth:`Clock.call_later <tfbus.clock.Clock.call_later>`)
        and one one-shot wake-up per tick, which the deadline and the jump callback both
        end: no cancel scope per tick (entering and leaving one cost most of a 100 Hz
        timer's CPU). A clock that cannot schedule callbacks (``call_later`` returns
        ``None``: a :class:`~tfbus.clock.SimClock` with a ``wall_timeout``, whose waits
        must raise :class:`~tfbus.errors.SimTimeStalled`) gets ``sleep_until`` in a
        cancel scope that the jump callback cancels.
        """
        remaining_ns = deadline - now_ns
        if type(clock) is SystemClock:
            # Monotonic seconds (call_later's and trio's); waking at least every
            # max_sleep notices a wall-clock step, as SystemClock.sleep_until does.
            seconds = min(remaining_ns / NSEC_PER_SEC, clock._max_sleep)
            delay: float | Duration = seconds
        else:
            delay = Duration.from_ns(remaining_ns)  # exact: simulated deadlines are ns
        wakeup = Wakeup(loop)
        wake = wakeup.wake
        cancel = clock.call_later(delay, wake)
        if cancel is None:
            await self._scope_wait(clock, deadline)
            return
        self._wake = wake
        try:
            await wakeup.wait()
        finally:
            self._wake = None
            cancel()

    async def _scope_wait(self, clock: Clock, deadline: int) -> None:
        """``clock.sleep_until(deadline)`` in a cancel scope that a backward jump cancels
        (a clock whose ``call_later`` returns None). A deadline past the end of
        :class:`~tfbus.time.Time` (``TIME_MAX_NS``: a clock within one period of it, as
        a ``/clock`` of 2**63 - 1 ns sets a SimClock) is never reached: the wait lasts
        until a jump back (or the clock's own bound, a SimClock's ``wall_timeout``), as
        :meth:`ManualClock.sleep <tfbus.clock.ManualClock.sleep>` past the end does."""
        with anyio.CancelScope() as scope:
            self._wake = scope.cancel
            try:
                if deadline > TIME_MAX_NS:
                    await clock.sleep(math.inf)
                else:
                    await clock.sleep_until(Time.from_ns(deadline))
            finally:
                self._wake = None

    def __repr__(self) -> str:
        return (
            f"PeriodicTimer(period={self.period!r}, next_index={self._next_index}, "
            f"overruns={self._overruns})"
        )


def every(
    period: float | Duration, *, clock: Clock | None = None, immediate: bool = False
) -> PeriodicTimer:
    """A periodic timer: ``async for tick in every(0.01, clock=clock): ...`` (100 Hz).

    Args:
        period: seconds (float) or a :class:`~tfbus.time.Duration` between deadlines.
        clock: the time source to read and sleep on; default a
            :class:`~tfbus.clock.SystemClock` (wall time), as every other component's
            (``Buffer``, ``TransformListener``) default.
        immediate: fire the first tick at once (deadline ``start``) rather than one
            period after the first iteration starts (``ros::Timer`` behaviour, default).

    Returns a :class:`PeriodicTimer` (see it for the overrun and jump policies).

    Raises:
        ValueError: if ``period`` is not positive, or not finite.
        TypeError: if ``period`` is not a number of seconds nor a Duration (a ``str``
            is refused before any arithmetic).
    """
    return PeriodicTimer(period, clock=clock, immediate=immediate)
