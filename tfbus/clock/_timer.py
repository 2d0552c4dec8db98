"""Periodic timers: ``every()``, ``PeriodicTimer``, ``Tick`` (``ros::Rate``/``Timer``)."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import anyio

from tfbus._aio import Wakeup, running_asyncio_loop
from tfbus.clock._base import Clock
from tfbus.clock._system import SystemClock
from tfbus.time import NSEC_PER_SEC, Duration, Time, seconds_to_ns


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

    Each tick's wait is one deadline of the clock (``call_later`` and a one-shot wake-up;
    under trio on the wall clock one ``trio`` cancel scope with that deadline, as
    ``trio.sleep``) that the jump callback ends early; the clock is read with
    ``now_ns()``. No anyio cancel scope is entered per tick.
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

    def _deadline(self, index: int) -> int:
        assert self._anchor_ns is not None
        return self._anchor_ns + (index - self._anchor_index) * self._period_ns

    def _reanchor(self, now_ns: int) -> None:
        self._anchor_index = self._next_index
        self._anchor_ns = now_ns + self._period_ns

    async def __anext__(self) -> Tick:
        """Wait for the next deadline and return its tick.

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled.
        """
        clock = self._clock
        if self._anchor_ns is None:
            now_ns = clock.now_ns()
            self._last_seen_ns = now_ns
            self._anchor_index = 0
            self._anchor_ns = now_ns + (0 if self._immediate else self._period_ns)
        while True:
            now_ns = clock.now_ns()
            if now_ns < self._last_seen_ns or self._jumped:
                self._jumped = False
                self._reanchor(now_ns)
            self._last_seen_ns = now_ns
            deadline = self._deadline(self._next_index)
            if now_ns >= deadline:
                # Latest deadline already passed; skip the older ones.
                behind = (now_ns - deadline) // self._period_ns
                index = self._next_index + behind
                self._overruns += behind
                self._next_index = index + 1
                return Tick(
                    index=index,
                    expected=Time.from_ns(self._deadline(index)),
                    actual=Time.from_ns(now_ns),
                    overruns=self._overruns,
                )
            await self._wait(clock, now_ns, deadline)

    async def _wait(self, clock: Clock, now_ns: int, deadline: int) -> None:
        """Sleep until ``deadline`` (ns of ``clock``) or a backward jump of ``clock``,
        whichever comes first; the caller re-reads the clock after it.

        One deadline callback (:meth:`Clock.call_later <tfbus.clock.Clock.call_later>`)
        and one one-shot wake-up per tick, which the deadline and the jump callback both
        end: no cancel scope per tick (entering and leaving one cost most of a 100 Hz
        timer's CPU). A clock that cannot schedule callbacks (``call_later`` returns
        ``None``: a :class:`~tfbus.clock.SimClock` with a ``wall_timeout``, whose waits
        must raise :class:`~tfbus.errors.SimTimeStalled`) gets ``sleep_until`` in a
        cancel scope that the jump callback cancels.
        """
        remaining_ns = deadline - now_ns
        loop = running_asyncio_loop()
        if type(clock) is SystemClock:
            # Monotonic seconds (call_later's and trio's); waking at least every
            # max_sleep notices a wall-clock step, as SystemClock.sleep_until does.
            seconds = min(remaining_ns / NSEC_PER_SEC, clock._max_sleep)
            if loop is None and (trio := sys.modules.get("trio")) is not None:
                await self._trio_wait(trio, clock, seconds)
                return
            delay: float | Duration = seconds
        else:
            delay = Duration.from_ns(remaining_ns)  # exact: simulated deadlines are ns
        wakeup = Wakeup(loop)
        wake = wakeup.wake
        cancel = clock.call_later(delay, wake)
        if cancel is None:
            await self._scope_wait(clock, deadline)
            return

        def on_jump(old: Time, new: Time) -> None:
            self._jumped = True
            wake()

        unregister = clock.on_jump(on_jump)
        try:
            await wakeup.wait()
        finally:
            cancel()
            unregister()

    async def _scope_wait(self, clock: Clock, deadline: int) -> None:
        """``clock.sleep_until(deadline)`` in a cancel scope that a backward jump cancels
        (a clock whose ``call_later`` returns None)."""
        with anyio.CancelScope() as scope:

            def on_jump(old: Time, new: Time) -> None:
                self._jumped = True
                scope.cancel()

            unregister = clock.on_jump(on_jump)
            try:
                await clock.sleep_until(Time.from_ns(deadline))
            finally:
                unregister()

    async def _trio_wait(self, trio: Any, clock: Clock, delay: float) -> None:
        """A :class:`~tfbus.clock.SystemClock` wait under trio: one ``trio.CancelScope``
        with the deadline, which the jump callback cancels (``trio.sleep``'s own cost:
        the ``call_later`` path would wake its timer task and then this one)."""
        with trio.CancelScope(deadline=trio.current_time() + delay) as scope:

            def on_jump(old: Time, new: Time) -> None:
                self._jumped = True
                scope.cancel()

            unregister = clock.on_jump(on_jump)
            try:
                await trio.sleep_forever()
            finally:
                unregister()

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
