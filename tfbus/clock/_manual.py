"""``ManualClock``: simulated time that tests and bag replay move by hand."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from contextlib import AbstractContextManager
from heapq import heapify, heappop, heappush
from itertools import count
from types import TracebackType
from typing import Final

import anyio
import anyio.lowlevel

from tfbus._aio import wait_all_tasks_blocked
from tfbus.clock._base import (
    JumpCallback,
    _JumpCallbacks,
    _noop,
    timeout_ns,
)
from tfbus.time import TIME_MAX_NS, Duration, Time, seconds_to_ns

_TIME_ZERO = Time(0)


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


class _ManualCall:
    """A callback filed among a :class:`ManualClock`'s sleepers by
    :meth:`ManualClock.call_later`; :meth:`cancel` forgets it (harmless once it ran)."""

    __slots__ = ("_callback", "_clock", "_seq")

    def __init__(self, clock: ManualClock, callback: Callable[[], object]) -> None:
        self._clock = clock
        self._callback = callback
        self._seq: int | None = None

    def fire(self) -> None:
        self._seq = None
        self._callback()

    def cancel(self) -> None:
        if self._seq is not None:
            self._clock._forget(self._seq)
            self._seq = None


class ManualClock:
    """Simulated time, moved only by :meth:`advance` and :meth:`set` (tests, bag replay).

    ``ManualClock(start=Time(0))``. Sleepers wake in deadline order (ties in the order
    they went to sleep). :meth:`advance` steps through pending sleepers one at a time:
    set ``now`` to the next deadline, wake that sleeper, let every task run until all are
    blocked, repeat; so a 100 Hz timer advanced by one second ticks 100 times, instantly.
    Like trio's ``MockClock(autojump_threshold=0)`` in spirit, for asyncio and trio alike.

    Deadlines (:meth:`move_on_after`, :meth:`fail_after`, :meth:`call_later`, and so every
    ``timeout=`` of a :class:`~tfbus.buffer.Buffer` on this clock) are sleepers too: when
    time reaches one, its cancel scope is cancelled (or its callback called) in the same
    step-by-step order. Nothing reads the wall
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

    def now_ns(self) -> int:
        """:meth:`now` as int nanoseconds."""
        return self._now_ns

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

    def on_jump(
        self, callback: JumpCallback, *, key: Hashable | None = None
    ) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when :meth:`set` moves time backwards.

        ``key``: one shared callback per key (:meth:`tfbus.clock.Clock.on_jump`).
        Returns a function that unregisters it (calling it twice is harmless). Exceptions
        from callbacks are logged, never raised into ``set``.
        """
        return self._jump.add(callback, key)

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

    def call_later(
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None]:
        """Call ``callback()`` in the :meth:`advance` step that reaches ``now + seconds``
        (a sleeper like any other: same order, counted in :attr:`pending`); at once if
        that is not after ``now``; never for ``inf`` or past ``TIME_MAX_NS``. Returns the
        function that cancels it. See :meth:`Clock.call_later`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        deadline = self._deadline_ns(timeout_ns(seconds, name="seconds"))
        if deadline <= self._now_ns:
            callback()
            return _noop
        if deadline >= _NEVER:
            return _noop
        call = _ManualCall(self, callback)
        call._seq = self._push(deadline, call.fire)
        return call.cancel

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

    def _next_deadline_ns(self) -> int:
        """The earliest deadline filed (a cancelled one may still count), or a time no
        clock reaches; safe to call from another thread (one read of the heap's top)."""
        try:
            return self._sleepers[0][0]
        except IndexError:
            return _NEVER

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
                await wait_all_tasks_blocked()

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
        await wait_all_tasks_blocked()
        sleepers = self._sleepers
        self._prune()
        while sleepers and sleepers[0][0] <= target_ns:
            # One sleeper per step, so ties wake in the order they went to sleep on every
            # backend (trio shuffles tasks woken in the same batch).
            self._now_ns = max(self._now_ns, sleepers[0][0])
            heappop(sleepers)[2]()
            await wait_all_tasks_blocked()
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
