"""Time sources and periodic timers: ``SystemClock``, ``ManualClock``, ``every()``.

Every async component of tfbus takes a :class:`Clock`; nothing else in tfbus reads the
wall clock. :class:`SystemClock` follows wall time (``time.time_ns``), as ROS time does
without ``/clock``. :class:`ManualClock` is simulated time that tests and bag replay
drive by hand: ``await clock.advance(1.0)`` steps through every pending deadline in
order, letting woken tasks run until they block again before taking the next step, so a
100 Hz timer ticks exactly 100 times per simulated second, instantly and
deterministically (the role trio's ``MockClock(autojump_threshold=0)`` plays for trio).

:func:`every` is the periodic timer (``ros::Rate`` / ``ros::Timer``)::

    async for tick in every(0.01, clock=clock):    # 100 Hz, absolute deadlines
        ...

Timer deadlines are ``first + index * period`` (no drift). A body that runs late does not
shift the schedule: the timer fires once for the most recent deadline that has passed
and skips older missed ones, counting them as overruns (as ``rcl_timer`` does; see
:class:`Tick`). A backward clock jump re-anchors the schedule at the new time (as
``ros::Rate::sleep`` does).

Deadlines and timeouts on a clock's time are cancel scopes: ``clock.move_on_after(s)``
and ``clock.fail_after(s)`` are ``anyio.move_on_after`` / ``anyio.fail_after`` on a
:class:`SystemClock`, and scopes that :meth:`ManualClock.advance` cancels when simulated
time reaches the deadline on a :class:`ManualClock`::

    with clock.move_on_after(2.0) as scope:     # 2 s of this clock's time
        await something()
    if scope.cancelled_caught:
        ...                                      # timed out

    with clock.fail_after(Duration(2)):         # TimeoutError when it expires
        await something()

Timeouts (``timeout=`` arguments anywhere in tfbus, and these scopes) mean the same on
both clocks: ``None`` or ``math.inf`` = no deadline; a negative or zero timeout expires
at the first checkpoint; a deadline beyond the end of :class:`~tfbus.time.Time`
(``TIME_MAX_NS``, year 2262) never expires; ``nan`` is a ``ValueError``; a ``str`` or a
``bool`` is a ``TypeError`` (checked before any arithmetic).
"""

from __future__ import annotations

import logging
import math
import numbers
import sys
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from heapq import heapify, heappop, heappush
from itertools import count
from types import TracebackType
from typing import Final, Protocol, runtime_checkable

import anyio
import anyio.lowlevel

from tfbus.time import NSEC_PER_SEC, TIME_MAX_NS, Duration, Time, seconds_to_ns

__all__ = [
    "Clock",
    "JumpCallback",
    "ManualClock",
    "PeriodicTimer",
    "SystemClock",
    "Tick",
    "every",
    "timeout_ns",
]

_log = logging.getLogger(__name__)
_TIME_ZERO = Time(0)

JumpCallback = Callable[[Time, Time], None]
"""Called as ``callback(old, new)`` when a clock jumps backwards from ``old`` to ``new``."""


@runtime_checkable
class Clock(Protocol):
    """A time source: what every async tfbus component reads time from and sleeps on."""

    def now(self) -> Time:
        """The current time of this clock."""
        ...

    async def sleep_until(self, t: Time) -> None:
        """Return once ``now() >= t`` (at once, after a checkpoint, if it already is).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
        """
        ...

    async def sleep(self, seconds: float | Duration) -> None:
        """Sleep for ``seconds`` of this clock's time (``<= 0``: just a checkpoint;
        ``math.inf``: until cancelled).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        ...

    def on_jump(self, callback: JumpCallback) -> Callable[[], None]:
        """Register ``callback(old, new)`` for backward jumps; returns an unregister function."""
        ...

    def move_on_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """A context manager that cancels its block after ``seconds`` of this clock's time.

        Entering it gives the ``anyio.CancelScope`` of the block: after the block,
        ``scope.cancelled_caught`` tells whether the deadline ended it. ``seconds``:
        ``None`` or ``inf`` = no deadline, ``<= 0`` = at the first checkpoint. The
        deadline is counted from the call.

        Raises:
            ValueError: ``seconds`` is NaN (at the call, before entering).
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        ...

    def fail_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """As :meth:`move_on_after`, but raises ``TimeoutError`` when the deadline ends the
        block (``anyio.fail_after`` on this clock's time).

        Raises:
            TimeoutError: on leaving the block, if the deadline cancelled it.
            ValueError, TypeError: as :meth:`move_on_after`.
        """
        ...


def timeout_ns(seconds: float | Duration | None, *, name: str = "timeout") -> int | None:
    """A timeout in nanoseconds, or ``None`` for "no deadline", the same on every clock.

    ``None``, ``math.inf`` -> ``None``; ``-math.inf`` -> ``0``; a finite number of seconds
    or a Duration -> exact nanoseconds (:func:`tfbus.time.seconds_to_ns`; negative
    values are kept: the caller expires them at once).

    Raises:
        ValueError: NaN.
        TypeError: not a number, Duration or None (a ``str`` or ``bool`` included),
            checked before any arithmetic.
    """
    if seconds is None:
        return None
    if isinstance(seconds, float) or (
        isinstance(seconds, numbers.Real) and not isinstance(seconds, numbers.Rational)
    ):
        value = float(seconds)
        if math.isnan(value):
            raise ValueError(f"{name} must not be NaN")
        if math.isinf(value):
            return None if value > 0 else 0
    return seconds_to_ns(seconds, name=name)



class _JumpCallbacks:
    """A registry of backward-jump callbacks shared by both clocks."""

    __slots__ = ("_callbacks", "_ids")

    def __init__(self) -> None:
        self._callbacks: dict[int, JumpCallback] = {}
        self._ids = count()

    def add(self, callback: JumpCallback) -> Callable[[], None]:
        key = next(self._ids)
        self._callbacks[key] = callback

        def unregister() -> None:
            self._callbacks.pop(key, None)

        return unregister

    def fire(self, old: Time, new: Time) -> None:
        # A list copy: a callback may unregister itself (or others) while we iterate.
        for callback in list(self._callbacks.values()):
            try:
                callback(old, new)
            except Exception:
                _log.exception("clock jump callback %r raised", callback)

    def __len__(self) -> int:
        return len(self._callbacks)


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

    def on_jump(self, callback: JumpCallback) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when the wall clock is seen going back.

        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into the task that observed the jump.
        """
        return self._jump.add(callback)

    def __repr__(self) -> str:
        return "SystemClock()"


async def _wait_all_tasks_blocked() -> None:
    """Let every other task run until it is blocked, without touching the wall clock.

    On trio this is ``trio.testing.wait_all_tasks_blocked`` via anyio, which is exact
    and instant. anyio's asyncio version sleeps 0.1 s of *wall time* each time it finds a
    runnable task, which would make every woken chain of tasks (timer -> bus ->
    subscriber) cost 100 ms; so on asyncio we do the same check with zero-length
    checkpoints instead. ``asyncio`` is looked up in ``sys.modules`` (it is necessarily
    loaded when an asyncio loop is running), never imported by tfbus.
    """
    asyncio = sys.modules.get("asyncio")
    loop = None
    if asyncio is not None:
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
    if asyncio is None or loop is None:
        await anyio.wait_all_tasks_blocked()
        return
    this_task = asyncio.current_task()
    await anyio.lowlevel.checkpoint()
    while True:
        for task in asyncio.all_tasks(loop):
            if task is this_task:
                continue
            waiter = getattr(task, "_fut_waiter", None)
            if waiter is None or waiter.done():
                break
        else:
            return
        await anyio.lowlevel.checkpoint()


_NEVER: Final = TIME_MAX_NS + 1
"""A deadline no ManualClock can reach (time ends at TIME_MAX_NS)."""


class _ManualDeadline:
    """The context manager of :meth:`ManualClock.move_on_after` / ``fail_after``.

    Entering opens an ``anyio.CancelScope`` and files its deadline among the clock's
    sleepers; when simulated time reaches it, the clock cancels the scope (one step of
    :meth:`ManualClock.advance`, like waking a sleeper). Leaving forgets the deadline.
    """

    __slots__ = ("_clock", "_deadline_ns", "_fail", "_fired", "_scope", "_seq")

    def __init__(self, clock: ManualClock, deadline_ns: int, fail: bool, shield: bool) -> None:
        self._clock = clock
        self._deadline_ns = deadline_ns
        self._fail = fail
        self._fired = False
        self._scope = anyio.CancelScope(shield=shield)
        self._seq: int | None = None

    def __enter__(self) -> anyio.CancelScope:
        scope = self._scope.__enter__()
        if self._deadline_ns <= self._clock._now_ns:
            self._fire()
        elif self._deadline_ns < _NEVER:
            self._seq = self._clock._push(self._deadline_ns, self._fire)
        return scope

    def _fire(self) -> None:
        self._fired = True
        self._seq = None
        self._scope.cancel()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool:
        if self._seq is not None:
            self._clock._forget(self._seq)
            self._seq = None
        suppressed = bool(self._scope.__exit__(exc_type, exc, tb))
        if self._fail and self._fired and self._scope.cancelled_caught:
            raise TimeoutError
        return suppressed


class ManualClock:
    """Simulated time, moved only by :meth:`advance` and :meth:`set` (tests, bag replay).

    ``ManualClock(start=Time(0))``. Sleepers wake in deadline order (ties in the order
    they went to sleep). :meth:`advance` steps through pending sleepers one at a time:
    set ``now`` to the next deadline, wake that sleeper, let every task run until all are
    blocked, repeat; so a 100 Hz timer advanced by one second ticks 100 times, instantly.
    Like trio's ``MockClock(autojump_threshold=0)`` in spirit, for asyncio and trio alike.

    Deadlines (:meth:`move_on_after`, :meth:`fail_after`, and every ``timeout=`` of a
    :class:`~tfbus.buffer.Buffer` on this clock) are sleepers too: when time reaches one,
    its cancel scope is cancelled in the same step-by-step order. Nothing reads the wall
    clock: a ManualClock can drive bag replay, timers and timeouts in zero wall time.

    A ``ManualClock`` must be used from one event loop; ``advance`` calls are serialised.
    """

    def __init__(self, start: Time = _TIME_ZERO) -> None:
        """Create a clock reading ``start``.

        Raises:
            TypeError: ``start`` is not a :class:`~tfbus.time.Time`.
        """
        if not isinstance(start, Time):
            raise TypeError(f"start must be a Time, got {start!r} ({type(start).__name__})")
        self._now_ns = start.ns
        # Heap of (deadline_ns, sequence, wake). A cancelled sleeper's sequence goes into
        # _dead and its entry is skipped when it surfaces (O(log n) cancellation).
        self._sleepers: list[tuple[int, int, Callable[[], object]]] = []
        self._dead: set[int] = set()
        self._seq = count()
        self._jump = _JumpCallbacks()
        self._lock: anyio.Lock | None = None

    # -- Clock protocol -------------------------------------------------------------

    def now(self) -> Time:
        """The simulated current time."""
        return Time.from_ns(self._now_ns)

    async def sleep_until(self, t: Time) -> None:
        """Return once the clock has been moved to ``t`` or later.

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile
                (the sleeper is then forgotten).
        """
        await self._sleep_until_ns(t.ns)

    async def _sleep_until_ns(self, deadline_ns: int) -> None:
        if deadline_ns <= self._now_ns:
            await anyio.lowlevel.checkpoint()
            return
        event = anyio.Event()
        seq = self._push(deadline_ns, event.set)
        try:
            await event.wait()
        finally:
            if not event.is_set():
                self._forget(seq)

    async def sleep(self, seconds: float | Duration) -> None:
        """Sleep ``seconds`` (or a :class:`~tfbus.time.Duration`) of simulated time.

        ``<= 0`` is a checkpoint; ``math.inf``, or a wake-up time past ``TIME_MAX_NS``,
        sleeps until cancelled (counted in :attr:`pending`).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        await self._sleep_until_ns(self._deadline_ns(timeout_ns(seconds, name="seconds")))

    def on_jump(self, callback: JumpCallback) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when :meth:`set` moves time backwards.

        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into ``set``.
        """
        return self._jump.add(callback)

    def move_on_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """A cancel scope that this clock cancels ``seconds`` of simulated time from now.

        Use as ``with clock.move_on_after(1.0) as scope:``; the scope is cancelled in
        the :meth:`advance` step that reaches ``now + seconds`` (or at once if that is
        not after ``now``). ``None``/``inf``/past ``TIME_MAX_NS``: never. The deadline is
        absolute: a backward :meth:`set` leaves it where it is. See
        :meth:`Clock.move_on_after`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        deadline = self._deadline_ns(timeout_ns(seconds))
        return _ManualDeadline(self, deadline, fail=False, shield=shield)

    def fail_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """As :meth:`move_on_after`, raising ``TimeoutError`` if the deadline ends the block.

        Raises:
            TimeoutError: on leaving the block, if this clock's deadline cancelled it.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        deadline = self._deadline_ns(timeout_ns(seconds))
        return _ManualDeadline(self, deadline, fail=True, shield=shield)

    # -- driving time ---------------------------------------------------------------

    @property
    def pending(self) -> int:
        """How many sleepers and deadlines are waiting on this clock."""
        return len(self._sleepers) - len(self._dead)

    def next_deadline(self) -> Time | None:
        """The earliest pending sleeper's or deadline's time, or ``None`` when there is
        none this clock can reach."""
        self._prune()
        if not self._sleepers or self._sleepers[0][0] >= _NEVER:
            return None
        return Time.from_ns(self._sleepers[0][0])

    def _advance_ns(self, d: float | Duration) -> int:
        ns = seconds_to_ns(d, name="d")
        if ns < 0:
            raise ValueError(f"cannot advance by a negative duration: {d!r}")
        if self._now_ns + ns > TIME_MAX_NS:
            raise ValueError(f"cannot advance by {d!r}: past the end of Time (TIME_MAX_NS)")
        return ns

    async def advance(self, d: float | Duration) -> None:
        """Move time forward by ``d`` seconds (or a Duration), stepping through deadlines.

        First lets every task run until blocked (so tasks just started can go to sleep),
        then repeatedly: set ``now`` to the next pending deadline within reach, wake the
        earliest sleeper or cancel the earliest deadline's scope (ties: first registered
        first), and let every task run until blocked. Ends at exactly ``now + d``, with
        all tasks blocked.

        Raises:
            ValueError: if ``d`` is negative (use :meth:`set` to jump backwards), infinite,
                NaN, or would move time past ``TIME_MAX_NS``.
            TypeError: if ``d`` is not a number nor a Duration (checked first).
        """
        ns = self._advance_ns(d)
        async with self._get_lock():
            await self._run_to(min(self._now_ns + ns, TIME_MAX_NS))

    async def set(self, t: Time) -> None:
        """Set the time to ``t``.

        Forward, this is :meth:`advance` by ``t - now`` (stepping through deadlines).
        Backward, it is a jump: ``now`` becomes ``t``, the ``on_jump`` callbacks get
        ``(old, t)``, then every task runs until blocked. Sleepers and deadlines keep
        their absolute times (they now have longer to wait); timers re-anchor via
        ``on_jump``.

        Raises:
            TypeError: ``t`` is not a :class:`~tfbus.time.Time`.
        """
        if not isinstance(t, Time):
            raise TypeError(f"t must be a Time, got {t!r} ({type(t).__name__})")
        async with self._get_lock():
            if t.ns >= self._now_ns:
                await self._run_to(t.ns)
            else:
                self._jump_to(t.ns)
                await _wait_all_tasks_blocked()

    def advance_nowait(self, d: float | Duration) -> None:
        """Move time forward by ``d`` at once, waking every sleeper due by then.

        Unlike :meth:`advance`, no task runs in between: all due sleepers wake (and due
        deadlines' scopes are cancelled) together, in deadline order, when the caller next
        yields, and a periodic timer sees the deadlines it missed as overruns.

        Raises:
            ValueError, TypeError: as :meth:`advance`.
        """
        self._now_ns += self._advance_ns(d)
        self._wake_due()

    def set_nowait(self, t: Time) -> None:
        """Set the time to ``t`` at once (see :meth:`advance_nowait`; backward: a jump).

        Raises:
            TypeError: ``t`` is not a :class:`~tfbus.time.Time`.
        """
        if not isinstance(t, Time):
            raise TypeError(f"t must be a Time, got {t!r} ({type(t).__name__})")
        if t.ns >= self._now_ns:
            self._now_ns = t.ns
            self._wake_due()
        else:
            self._jump_to(t.ns)

    # -- internals ------------------------------------------------------------------

    def _deadline_ns(self, ns: int | None) -> int:
        """``now + ns`` as an absolute deadline; ``_NEVER`` for no deadline or past the
        end of Time."""
        if ns is None:
            return _NEVER
        return min(self._now_ns + max(ns, 0), _NEVER)

    def _push(self, deadline_ns: int, wake: Callable[[], object]) -> int:
        seq = next(self._seq)
        heappush(self._sleepers, (deadline_ns, seq, wake))
        return seq

    def _get_lock(self) -> anyio.Lock:
        if self._lock is None:
            self._lock = anyio.Lock()
        return self._lock

    async def _run_to(self, target_ns: int) -> None:
        await _wait_all_tasks_blocked()
        sleepers = self._sleepers
        self._prune()
        while sleepers and sleepers[0][0] <= target_ns:
            # One sleeper per step, so ties wake in the order they went to sleep on every
            # backend (trio shuffles tasks woken in the same batch).
            self._now_ns = max(self._now_ns, sleepers[0][0])
            heappop(sleepers)[2]()
            await _wait_all_tasks_blocked()
            self._prune()
        self._now_ns = target_ns
        # Deadlines at exactly the target have already been woken above.

    def _wake_due(self) -> None:
        now = self._now_ns
        sleepers = self._sleepers
        self._prune()
        while sleepers and sleepers[0][0] <= now:
            heappop(sleepers)[2]()
            self._prune()

    def _jump_to(self, ns: int) -> None:
        old = self._now_ns
        self._now_ns = ns
        self._jump.fire(Time.from_ns(old), Time.from_ns(ns))

    def _forget(self, seq: int) -> None:
        self._dead.add(seq)
        if len(self._dead) > 64 and 2 * len(self._dead) > len(self._sleepers):
            dead = self._dead
            self._sleepers[:] = [e for e in self._sleepers if e[1] not in dead]
            heapify(self._sleepers)
            dead.clear()

    def _prune(self) -> None:
        # Drop cancelled sleepers from the top of the heap.
        sleepers, dead = self._sleepers, self._dead
        while sleepers and sleepers[0][1] in dead:
            dead.discard(heappop(sleepers)[1])

    def __repr__(self) -> str:
        return f"ManualClock(now={self.now()!r}, pending={self.pending})"


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
    """

    def __init__(self, period: float | Duration, *, clock: Clock, immediate: bool = False) -> None:
        """See :func:`every`.

        Raises:
            ValueError: if ``period`` is not positive, or not finite.
            TypeError: if ``period`` is not a number of seconds nor a Duration.
        """
        period_ns = seconds_to_ns(period, name="period")
        if period_ns <= 0:
            raise ValueError(f"period must be positive, got {period!r}")
        self._period_ns = period_ns
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
            now_ns = clock.now().ns
            self._last_seen_ns = now_ns
            self._anchor_index = 0
            self._anchor_ns = now_ns + (0 if self._immediate else self._period_ns)
        while True:
            now_ns = clock.now().ns
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
            with anyio.CancelScope() as scope:

                def on_jump(old: Time, new: Time, scope: anyio.CancelScope = scope) -> None:
                    self._jumped = True
                    scope.cancel()

                unregister = clock.on_jump(on_jump)
                try:
                    await clock.sleep_until(Time.from_ns(deadline))
                finally:
                    unregister()

    def __repr__(self) -> str:
        return (
            f"PeriodicTimer(period={self.period!r}, next_index={self._next_index}, "
            f"overruns={self._overruns})"
        )


def every(period: float | Duration, *, clock: Clock, immediate: bool = False) -> PeriodicTimer:
    """A periodic timer: ``async for tick in every(0.01, clock=clock): ...`` (100 Hz).

    Args:
        period: seconds (float) or a :class:`~tfbus.time.Duration` between deadlines.
        clock: the time source to read and sleep on.
        immediate: fire the first tick at once (deadline ``start``) rather than one
            period after the first iteration starts (``ros::Timer`` behaviour, default).

    Returns a :class:`PeriodicTimer` (see it for the overrun and jump policies).

    Raises:
        ValueError: if ``period`` is not positive, or not finite.
        TypeError: if ``period`` is not a number of seconds nor a Duration (a ``str``
            is refused before any arithmetic).
    """
    return PeriodicTimer(period, clock=clock, immediate=immediate)
