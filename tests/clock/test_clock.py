"""Tests for tfbus/clock.py: ManualClock, SystemClock, every()."""

from __future__ import annotations

import itertools
import math
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import anyio
import anyio.lowlevel
import numpy as np
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus.buffer import Buffer
from tfbus.clock import Clock, ManualClock, PeriodicTimer, SystemClock, Tick, every, timeout_ns
from tfbus.errors import TimeoutException
from tfbus.messages import Header, Transform, TransformStamped, Vector3
from tfbus.time import Duration, Time

pytestmark = pytest.mark.anyio


T0 = Time(100)
MS = 1_000_000


def test_clocks_satisfy_protocol() -> None:
    assert isinstance(ManualClock(), Clock)
    assert isinstance(SystemClock(), Clock)


def test_system_clock_reads_wall_time() -> None:
    before = time.time_ns()
    now = SystemClock().now().ns
    assert before <= now <= time.time_ns()


def test_system_clock_rejects_bad_max_sleep() -> None:
    with pytest.raises(ValueError):
        SystemClock(max_sleep=0)


def test_system_clock_detects_backward_jump(monkeypatch: pytest.MonkeyPatch) -> None:
    readings = iter([5_000, 6_000, 4_000, 7_000])
    monkeypatch.setattr(time, "time_ns", lambda: next(readings))
    clock = SystemClock()
    jumps: list[tuple[Time, Time]] = []
    unregister = clock.on_jump(lambda old, new: jumps.append((old, new)))
    assert clock.now() == Time.from_ns(5_000)
    assert clock.now() == Time.from_ns(6_000)
    assert clock.now() == Time.from_ns(4_000)
    assert jumps == [(Time.from_ns(6_000), Time.from_ns(4_000))]
    unregister()
    unregister()  # harmless twice
    clock.now()
    assert len(jumps) == 1


async def test_system_clock_sleep_until_past_returns_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A past deadline does not sleep at all, yet is a checkpoint (cancellation lands)."""
    slept: list[float] = []
    real_sleep = anyio.sleep

    async def recording_sleep(seconds: float) -> None:
        slept.append(seconds)
        await real_sleep(0)

    monkeypatch.setattr(anyio, "sleep", recording_sleep)
    clock = SystemClock()
    await clock.sleep_until(Time(0))
    assert slept == []  # no timer at all for a deadline already passed
    await clock.sleep(-1.0)
    assert slept == [0.0]  # a negative sleep is a zero-length one
    with anyio.CancelScope() as scope:
        scope.cancel()
        await clock.sleep_until(Time(0))
    assert scope.cancelled_caught  # it was a checkpoint: the pending cancel was delivered


async def test_system_clock_sleep_until_arms_one_timer_and_never_returns_early(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each ``sleep_until`` a few milliseconds ahead returns at or after its deadline,
    after at most two timers (one, and another when a timer fires a hair early), on every
    loop. On uvloop, whose timers count whole milliseconds, a timer armed for the exact
    rest fires up to a millisecond early, and the sub-millisecond rest rounds to a timer
    run at once: without the delay rounded up (``tfbus._aio.timer_delay``) each deadline
    ended in a busy loop of such timers."""
    armed: list[float] = []
    real_sleep = anyio.sleep

    async def counting_sleep(seconds: float) -> None:
        armed.append(seconds)
        await real_sleep(seconds)

    monkeypatch.setattr(anyio, "sleep", counting_sleep)
    clock = SystemClock()
    n = 20
    for k in range(n):
        deadline = Time.from_ns(clock.now().ns + 2_300_000 + 97_000 * k)  # 2.3 .. 4.1 ms
        await clock.sleep_until(deadline)
        assert clock.now() >= deadline
    assert len(armed) <= 2 * n, armed


async def test_manual_clock_now_and_advance() -> None:
    clock = ManualClock(T0)
    assert clock.now() == T0
    await clock.advance(1.5)
    assert clock.now() == T0 + Duration.from_sec(1.5)
    await clock.advance(Duration(0, 7))
    assert clock.now().ns == T0.ns + 1_500_000_007
    with pytest.raises(ValueError):
        await clock.advance(-1)


async def test_sleepers_wake_in_deadline_order_at_their_deadlines() -> None:
    clock = ManualClock(T0)
    woke: list[tuple[str, Time]] = []

    async def sleeper(name: str, seconds: float) -> None:
        await clock.sleep(seconds)
        woke.append((name, clock.now()))

    async with anyio.create_task_group() as tg:
        for name, seconds in [("c", 0.3), ("a", 0.1), ("b", 0.2), ("a2", 0.1), ("late", 5.0)]:
            tg.start_soon(sleeper, name, seconds)
            await clock.advance(0)  # let it fall asleep: ties wake first-asleep-first
        await clock.advance(1.0)
        assert woke == [
            ("a", T0 + Duration.from_sec(0.1)),
            ("a2", T0 + Duration.from_sec(0.1)),
            ("b", T0 + Duration.from_sec(0.2)),
            ("c", T0 + Duration.from_sec(0.3)),
        ]
        assert clock.pending == 1
        assert clock.next_deadline() == T0 + Duration.from_sec(5.0)
        await clock.set(T0 + Duration.from_sec(5.0))
    assert woke[-1] == ("late", T0 + Duration.from_sec(5.0))
    assert clock.pending == 0


async def test_sleep_until_past_is_a_checkpoint() -> None:
    """Sleeping until a past time (or for <= 0 s) returns with no time moving and is a
    checkpoint: a cancelled scope around it is honoured."""
    clock = ManualClock(T0)
    done: list[Time] = []

    async def sleeper() -> None:
        await clock.sleep_until(Time(1))
        await clock.sleep(0)
        await clock.sleep(-3.0)
        done.append(clock.now())

    async with anyio.create_task_group() as tg:
        tg.start_soon(sleeper)
        await clock.advance(0)  # runs every task until blocked; time does not move
        assert done == [T0]
        assert clock.pending == 0
    with anyio.CancelScope() as scope:
        scope.cancel()
        await clock.sleep_until(Time(1))
    assert scope.cancelled_caught
    with anyio.CancelScope() as scope:
        scope.cancel()
        await clock.sleep(0)
    assert scope.cancelled_caught


async def test_cancelled_sleeper_is_forgotten() -> None:
    clock = ManualClock(T0)
    with anyio.move_on_after(0):
        await clock.sleep(10.0)
    async with anyio.create_task_group() as tg:
        for _ in range(50):
            tg.start_soon(clock.sleep, 10.0)
        await clock.advance(0)
        assert clock.pending == 50
        tg.cancel_scope.cancel()
    assert clock.pending == 0


async def test_chained_wakeups_complete_within_one_advance() -> None:
    """A sleeper that wakes another task (via an event) lets that one run too."""
    clock = ManualClock(T0)
    log: list[str] = []
    ev = anyio.Event()

    async def first() -> None:
        await clock.sleep(0.5)
        log.append("first")
        ev.set()

    async def second() -> None:
        await ev.wait()
        log.append("second")
        await clock.sleep(0.25)
        log.append(f"second again at {clock.now().ns - T0.ns}")

    async with anyio.create_task_group() as tg:
        tg.start_soon(first)
        tg.start_soon(second)
        await clock.advance(1.0)
        assert log == ["first", "second", f"second again at {750 * MS}"]


async def test_backward_set_fires_jump_callbacks() -> None:
    clock = ManualClock(T0 + Duration(10))
    jumps: list[tuple[Time, Time]] = []
    unregister = clock.on_jump(lambda old, new: jumps.append((old, new)))

    def bad(old: Time, new: Time) -> None:
        raise RuntimeError("callback errors are logged, not raised")

    clock.on_jump(bad)
    await clock.set(T0 + Duration(20))  # forward: no jump
    assert jumps == []
    await clock.set(T0)
    assert jumps == [(T0 + Duration(20), T0)]
    assert clock.now() == T0
    clock.set_nowait(Time(1))
    assert jumps[-1] == (T0, Time(1))
    unregister()
    clock.set_nowait(Time(0))
    assert len(jumps) == 2


async def test_jump_callbacks_under_one_key_run_once_until_the_last_owner_leaves(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``on_jump(callback, key=k)``: owners registering under one key share the first
    callback (it runs once per jump); it goes with the last owner's unregister. Unkeyed
    callbacks are each their own; all run in registration order. The same on a
    SystemClock, whose jumps are seen when it is read."""
    clock = ManualClock(T0)
    calls: list[str] = []
    first = clock.on_jump(lambda old, new: calls.append("a"), key="clear")
    second = clock.on_jump(lambda old, new: calls.append("b"), key="clear")
    plain = clock.on_jump(lambda old, new: calls.append("p"))
    plain_too = clock.on_jump(lambda old, new: calls.append("p"))
    clock.set_nowait(Time(1))
    assert calls == ["a", "p", "p"]
    first()
    first()  # idempotent: the second owner still holds the key
    plain()
    clock.set_nowait(Time(0))
    assert calls == ["a", "p", "p", "a", "p"]
    second()
    plain_too()
    clock.set_nowait(T0)
    clock.set_nowait(Time(0))
    assert calls == ["a", "p", "p", "a", "p"]
    again = clock.on_jump(lambda old, new: calls.append("c"), key="clear")
    clock.set_nowait(Time(T0.sec))
    clock.set_nowait(Time(0))
    assert calls[-1] == "c"
    again()

    wall = iter([5_000, 6_000, 2_000, 1_000])
    monkeypatch.setattr(time, "time_ns", lambda: next(wall))
    system = SystemClock()
    seen: list[tuple[int, int]] = []
    stops = [system.on_jump(lambda old, new: seen.append((old.ns, new.ns)), key=("k", 1))
             for _ in range(3)]
    assert [system.now_ns() for _ in range(4)] == [5_000, 6_000, 2_000, 1_000]
    assert seen == [(6_000, 2_000), (2_000, 1_000)]
    for stop in stops:
        stop()


async def test_advance_nowait_wakes_all_due_at_once() -> None:
    clock = ManualClock(T0)
    woke: list[Time] = []

    async def sleeper(seconds: float) -> None:
        await clock.sleep(seconds)
        woke.append(clock.now())

    async with anyio.create_task_group() as tg:
        tg.start_soon(sleeper, 0.1)
        tg.start_soon(sleeper, 0.2)
        await clock.advance(0)
        clock.advance_nowait(0.5)
        with pytest.raises(ValueError):
            clock.advance_nowait(-0.5)
    assert woke == [T0 + Duration.from_sec(0.5)] * 2


async def test_timer_ticks_exactly_100_times_per_simulated_second() -> None:
    clock = ManualClock(T0)
    ticks: list[Tick] = []

    async def run() -> None:
        async for tick in every(0.01, clock=clock):
            ticks.append(tick)

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(1.0)
        assert len(ticks) == 100
        await clock.advance(Duration(2))
        assert len(ticks) == 300
        tg.cancel_scope.cancel()
    for i, tick in enumerate(ticks):
        assert tick.index == i
        assert tick.expected == T0 + Duration.from_ns((i + 1) * 10 * MS)  # absolute, no drift
        assert tick.actual == tick.expected
        assert tick.lateness == Duration(0)
        assert tick.overruns == 0


async def test_timer_immediate_first_tick() -> None:
    clock = ManualClock(T0)
    ticks: list[Tick] = []

    async def run() -> None:
        async for tick in every(Duration.from_sec(0.5), clock=clock, immediate=True):
            ticks.append(tick)

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(1.0)
        tg.cancel_scope.cancel()
    assert [t.expected for t in ticks] == [
        T0,
        T0 + Duration.from_sec(0.5),
        T0 + Duration.from_sec(1.0),
    ]


async def test_timer_overruns_skip_missed_deadlines_and_count_them() -> None:
    clock = ManualClock(T0)
    ticks: list[Tick] = []
    timer = every(0.01, clock=clock)
    assert isinstance(timer, PeriodicTimer)

    async def run() -> None:
        async for tick in timer:
            ticks.append(tick)
            if tick.index == 4:
                await clock.sleep(0.025)  # body overruns by 2.5 periods
            if tick.index == 20:
                await clock.sleep(0.015)  # 1.5 periods

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(1.0)
        tg.cancel_scope.cancel()
    indices = [t.index for t in ticks]
    # Tick 4 ends at 75 ms: deadlines 60 ms (idx 5) and 70 ms (idx 6) passed; 5 skipped,
    # 6 fires late at 75 ms. Tick 20 ends at 225 ms: idx 21 (220 ms) fires late.
    assert 5 not in indices
    by_index = {t.index: t for t in ticks}
    t6 = by_index[6]
    assert t6.expected == T0 + Duration.from_ns(70 * MS)
    assert t6.actual == T0 + Duration.from_ns(75 * MS)
    assert t6.lateness == Duration.from_ns(5 * MS)
    assert t6.overruns == 1
    t21 = by_index[21]
    assert t21.lateness == Duration.from_ns(5 * MS)
    assert t21.overruns == 1
    assert by_index[22].actual == by_index[22].expected  # back on the grid
    assert timer.overruns == 1
    assert indices[-1] == 99  # schedule did not drift: deadline 99 is at exactly 1 s
    assert len(ticks) == 100 - 1
    assert all(t.index + 1 - t.overruns == n + 1 for n, t in enumerate(ticks))


async def test_timer_reanchors_on_backward_jump() -> None:
    clock = ManualClock(T0 + Duration(10))
    ticks: list[Tick] = []

    async def run() -> None:
        async for tick in every(0.1, clock=clock):
            ticks.append(tick)

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(0.25)
        assert len(ticks) == 2
        await clock.set(T0)  # jump back 10.25 s while the timer sleeps
        await clock.advance(0.2)
        tg.cancel_scope.cancel()
    assert [t.expected for t in ticks[2:]] == [
        T0 + Duration.from_sec(0.1),
        T0 + Duration.from_sec(0.2),
    ]
    assert [t.index for t in ticks] == [0, 1, 2, 3]


def test_every_rejects_bad_period() -> None:
    with pytest.raises(ValueError):
        every(0, clock=ManualClock())
    with pytest.raises(ValueError):
        every(Duration.from_sec(-1), clock=ManualClock())


async def test_timer_on_system_clock_ticks() -> None:
    clock = SystemClock()
    ticks: list[Tick] = []
    with anyio.fail_after(5):
        async for tick in every(0.001, clock=clock):
            ticks.append(tick)
            if len(ticks) == 3:
                break
    assert all(t.actual >= t.expected for t in ticks)
    assert ticks[1].expected - ticks[0].expected == Duration.from_ns(MS) * (
        ticks[1].index - ticks[0].index
    )


async def test_advance_100_ticks_never_uses_anyios_sleeping_helper(
    monkeypatch: pytest.MonkeyPatch, anyio_backend_name: str
) -> None:
    """No wall-clock sleeping inside advance: anyio's asyncio ``wait_all_tasks_blocked``
    sleeps 0.1 s per runnable task, so on asyncio the clock must not call it (the wall
    time of this is printed by benchmarks/bench_clock.py)."""
    if anyio_backend_name == "asyncio":

        async def forbidden() -> None:
            raise AssertionError("anyio.wait_all_tasks_blocked sleeps on asyncio")

        monkeypatch.setattr(anyio, "wait_all_tasks_blocked", forbidden)
    clock = ManualClock(T0)
    send, receive = anyio.create_memory_object_stream[int](1000)
    got: list[int] = []

    async def producer() -> None:
        async with send:
            async for tick in every(0.01, clock=clock):
                await send.send(tick.index)

    async def consumer() -> None:
        async with receive:
            async for i in receive:
                got.append(i)

    async with anyio.create_task_group() as tg:
        tg.start_soon(producer)
        tg.start_soon(consumer)
        await clock.advance(1.0)
        assert got == list(range(100))
        tg.cancel_scope.cancel()


async def test_many_cancelled_sleepers_are_forgotten() -> None:
    """Cancelled sleepers leave the heap (compaction past 64 dead entries); their cost is
    printed by benchmarks/bench_clock.py."""
    clock = ManualClock(T0)
    woke: list[int] = []

    async def sleeper(i: int) -> None:
        await clock.sleep(1.0 + i * 1e-6)
        woke.append(i)

    async with anyio.create_task_group() as tg:
        async with anyio.create_task_group() as doomed:
            for _ in range(1_000):
                doomed.start_soon(clock.sleep, 5.0)
            await clock.advance(0)
            assert clock.pending == 1_000
            doomed.cancel_scope.cancel()
        assert clock.pending == 0
        tg.start_soon(sleeper, 1)
        tg.start_soon(sleeper, 2)
        await clock.advance(0)
        assert clock.pending == 2
        assert clock.next_deadline() == T0 + Duration.from_ns(1_000_001_000)
        await clock.advance(10.0)
    assert sorted(woke) == [1, 2]
    assert clock.pending == 0
    assert not clock._dead and not clock._sleepers  # nothing left behind


# --------------------------------------------------------------------------- deadlines


async def test_manual_move_on_after_is_cancelled_by_advance() -> None:
    clock = ManualClock(T0)
    log: list[tuple[str, Time]] = []

    async def waiter() -> None:
        with clock.move_on_after(0.5) as scope:
            await anyio.sleep_forever()
        log.append(("timed out" if scope.cancelled_caught else "done", clock.now()))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0)
        assert clock.pending == 1
        assert clock.next_deadline() == T0 + Duration.from_sec(0.5)
        await clock.advance(0.499_999_999)
        assert log == []
        await clock.advance(Duration(0, 1))
        assert log == [("timed out", T0 + Duration.from_sec(0.5))]
    assert clock.pending == 0


async def test_manual_deadline_left_early_is_forgotten() -> None:
    clock = ManualClock(T0)
    ev = anyio.Event()
    result: list[bool] = []

    async def waiter() -> None:
        with clock.move_on_after(Duration(10)) as scope:
            await ev.wait()
        result.append(scope.cancelled_caught)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(1.0)
        ev.set()
    assert result == [False]
    assert clock.pending == 0
    await clock.advance(20.0)  # nothing fires into a scope that has been left
    assert clock.pending == 0


async def test_manual_fail_after_raises_timeout_error() -> None:
    clock = ManualClock(T0)
    caught: list[Time] = []

    async def waiter() -> None:
        try:
            with clock.fail_after(2):
                await anyio.sleep_forever()
        except TimeoutError:
            caught.append(clock.now())

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(5.0)
    assert caught == [T0 + Duration(2)]


async def test_manual_fail_after_not_raised_when_the_block_ends_in_time() -> None:
    clock = ManualClock(T0)
    with clock.fail_after(1.0) as scope:
        await clock.advance(0.5)
    assert not scope.cancelled_caught


async def test_manual_deadline_zero_or_negative_expires_at_first_checkpoint() -> None:
    clock = ManualClock(T0)
    for seconds in (0, -1.0, -math.inf, Duration(-5)):
        with clock.move_on_after(seconds) as scope:
            await anyio.lowlevel.checkpoint()
            pytest.fail("the checkpoint should have been cancelled")  # pragma: no cover
        assert scope.cancelled_caught
    with pytest.raises(TimeoutError), clock.fail_after(0):
        await anyio.lowlevel.checkpoint()
    assert clock.pending == 0


async def test_outer_cancellation_is_not_a_timeout() -> None:
    clock = ManualClock(T0)
    with anyio.CancelScope() as outer:
        with clock.fail_after(10.0) as inner:
            outer.cancel()
            await anyio.lowlevel.checkpoint()
    assert outer.cancelled_caught and not inner.cancelled_caught
    assert clock.pending == 0


async def test_deadlines_and_sleepers_fire_in_time_order() -> None:
    clock = ManualClock(T0)
    log: list[str] = []

    async def sleeper(name: str, seconds: float) -> None:
        await clock.sleep(seconds)
        log.append(name)

    async def deadline(name: str, seconds: float) -> None:
        with clock.move_on_after(seconds):
            await anyio.sleep_forever()
        log.append(name)

    async with anyio.create_task_group() as tg:
        tg.start_soon(deadline, "d0.3", 0.3)
        tg.start_soon(sleeper, "s0.1", 0.1)
        tg.start_soon(deadline, "d0.2", 0.2)
        tg.start_soon(sleeper, "s0.4", 0.4)
        await clock.advance(1.0)
    assert log == ["s0.1", "d0.2", "d0.3", "s0.4"]


async def test_system_clock_deadlines_are_anyios(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[str, float | None, bool]] = []
    real_move_on_after, real_fail_after = anyio.move_on_after, anyio.fail_after

    def move_on_after(delay: float | None, shield: bool = False) -> anyio.CancelScope:
        calls.append(("move_on_after", delay, shield))
        return real_move_on_after(delay, shield=shield)

    def fail_after(delay: float | None, shield: bool = False) -> Any:
        calls.append(("fail_after", delay, shield))
        return real_fail_after(delay, shield=shield)

    monkeypatch.setattr(anyio, "move_on_after", move_on_after)
    monkeypatch.setattr(anyio, "fail_after", fail_after)
    clock = SystemClock()
    with clock.move_on_after(0) as scope:
        await anyio.lowlevel.checkpoint()
    assert scope.cancelled_caught
    with pytest.raises(TimeoutError), clock.fail_after(Duration(0, -1)):
        await anyio.lowlevel.checkpoint()
    with clock.move_on_after(math.inf, shield=True) as scope:
        await anyio.lowlevel.checkpoint()
    assert not scope.cancelled_caught
    with clock.fail_after(None):
        await anyio.lowlevel.checkpoint()
    assert calls == [
        ("move_on_after", 0.0, False),
        ("fail_after", -1e-9, False),
        ("move_on_after", None, True),
        ("fail_after", None, False),
    ]


def test_timeout_meaning_is_the_same_on_every_clock() -> None:
    """Inf is no timeout, NaN a ValueError, on both clocks."""
    assert timeout_ns(None) is None
    assert timeout_ns(math.inf) is None
    assert timeout_ns(np.float32("inf")) is None  # type: ignore[arg-type]
    assert timeout_ns(-math.inf) == 0
    assert timeout_ns(1e10) == 10**19
    assert timeout_ns(0.1) == 100_000_000
    assert timeout_ns(Duration(0, 7)) == 7
    with pytest.raises(ValueError, match="timeout must not be NaN"):
        timeout_ns(math.nan)
    for clock in (ManualClock(T0), SystemClock()):
        with pytest.raises(ValueError, match="NaN"):
            clock.move_on_after(math.nan)
        with pytest.raises(ValueError, match="NaN"):
            clock.fail_after(np.float64("nan"))
        for bad in ("1", True, [1.0], 1j):
            with pytest.raises(TypeError, match="timeout must be a number of seconds"):
                clock.move_on_after(bad)  # type: ignore[arg-type]


async def test_manual_clock_huge_and_infinite_timeouts_never_fire() -> None:
    """A ManualClock wait with timeout inf or 1e10 s (past the end of
    Time) is a wait with no deadline, not an error; NaN is a ValueError."""
    clock = ManualClock(Time(1_700_000_000))
    ev = anyio.Event()
    results: list[bool] = []

    async def waiter(seconds: float) -> None:
        with clock.move_on_after(seconds) as scope:
            await ev.wait()
        results.append(scope.cancelled_caught)

    async with anyio.create_task_group() as tg:
        for seconds in (math.inf, 1e10, 1e300):
            tg.start_soon(waiter, seconds)
        tg.start_soon(clock.sleep, math.inf)
        tg.start_soon(clock.sleep, 1e10)
        await clock.advance(10**9)
        assert clock.next_deadline() is None  # none of them can ever come due
        assert clock.pending == 2  # the two sleeps (no-deadline scopes are not filed)
        ev.set()
        await clock.advance(0)
        assert results == [False, False, False]
        tg.cancel_scope.cancel()
    assert clock.pending == 0
    with pytest.raises(ValueError, match="NaN"):
        await clock.sleep(math.nan)
    with pytest.raises(ValueError, match="NaN"):
        await SystemClock().sleep(math.nan)


class _NoMultiply(str):
    """A str that fails the test if anything multiplies it (``'0.01' * 10**9`` is 4 GB)."""

    __slots__ = ()

    def __mul__(self, other: object) -> str:
        raise AssertionError(f"{self!r} was multiplied before its type was checked")

    __rmul__ = __mul__


async def test_str_durations_are_type_errors_before_any_arithmetic() -> None:
    """``every('0.01')`` and ``advance('1')`` allocated 1-4 GB (the
    string repeated 10^9 times) before the TypeError: types are checked first."""
    clock = ManualClock(T0)
    for text in ("0.01", "1"):
        probe = _NoMultiply(text)
        with pytest.raises(TypeError, match="period must be a number of seconds"):
            every(probe, clock=clock)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="must be a number of seconds"):
            await clock.advance(probe)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="must be a number of seconds"):
            clock.advance_nowait(probe)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="must be a number of seconds"):
            await clock.sleep(probe)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="must be a number of seconds"):
            await SystemClock().sleep(probe)  # type: ignore[arg-type]
    tracemalloc.start()
    try:
        with pytest.raises(TypeError):
            every("0.01", clock=clock)  # type: ignore[arg-type]
        with pytest.raises(TypeError):
            await clock.advance("1")  # type: ignore[arg-type]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000  # bytes: nothing near the gigabytes of a repeated string
    assert clock.now() == T0


async def test_advance_rejects_infinite_nan_and_past_the_end_of_time() -> None:
    clock = ManualClock(T0)
    for bad in (math.inf, math.nan):
        with pytest.raises(ValueError, match="finite"):
            await clock.advance(bad)
    with pytest.raises(ValueError, match="TIME_MAX_NS"):
        await clock.advance(1e10)
    with pytest.raises(TypeError):
        await clock.advance(True)
    with pytest.raises(TypeError, match="must be a Time"):
        await clock.set(5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="must be a Time"):
        ManualClock(5)  # type: ignore[arg-type]
    assert clock.now() == T0


async def test_manual_clock_paces_a_replay_loop_in_zero_wall_time() -> None:
    """What ``bag.replay`` needs from a clock: ``now()`` to anchor, ``sleep_until`` to
    pace; on a ManualClock each message goes out exactly at its scaled bag time."""
    pace = ManualClock(T0)
    bag_stamps = [Time(1000), Time(1000, 250_000_000), Time(1001), Time(1003)]
    rate = 2.0
    sent: list[tuple[Time, Time]] = []

    async def replay() -> None:
        start = pace.now()
        for stamp in bag_stamps:
            offset = Duration.from_ns(stamp.ns - bag_stamps[0].ns) * (1 / rate)
            await pace.sleep_until(start + offset)
            sent.append((stamp, pace.now()))

    async with anyio.create_task_group() as tg:
        tg.start_soon(replay)
        for step in (0.1, 0.4, 0.9):
            await pace.advance(step)
        assert [s for s, _ in sent] == bag_stamps[:3]
        await pace.advance(0.1)
    assert sent == [
        (bag_stamps[0], T0),
        (bag_stamps[1], T0 + Duration.from_sec(0.125)),
        (bag_stamps[2], T0 + Duration.from_sec(0.5)),
        (bag_stamps[3], T0 + Duration.from_sec(1.5)),
    ]



# --------------------------------------------------------------------------- Buffer timeouts


def _ts(stamp: Time) -> TransformStamped:
    return TransformStamped(Header(stamp, "a"), "b", Transform(Vector3(1.0, 0.0, 0.0)))


async def _until_waiting(buf: Buffer, n: int) -> None:
    """Let the waiters register (bounded in checkpoints, no wall time)."""
    for _ in range(10_000):
        if buf.pending_waits == n:
            return
        await anyio.lowlevel.checkpoint()
    raise AssertionError(f"{buf.pending_waits} waits registered, expected {n}")


@pytest.mark.parametrize("clock_kind", ["manual", "system"])
async def test_buffer_wait_with_infinite_or_huge_timeout_waits_for_the_data(
    clock_kind: str,
) -> None:
    """``timeout=inf`` or ``1e10`` on a ManualClock raised an
    ExceptionGroup (OverflowError / ValueError from the timer task); on both clocks it is
    now a wait with no deadline that ends when the data arrives."""
    clock: ManualClock | SystemClock = ManualClock(T0) if clock_kind == "manual" else SystemClock()
    buf = Buffer(clock=clock)
    got: list[float] = []

    async def waiter(timeout: float) -> None:
        ts = await buf.lookup_transform_async("a", "b", Time(0), timeout=timeout)
        got.append(ts.transform.translation.x)

    async with anyio.create_task_group() as tg:
        for timeout in (math.inf, 1e10, 1e300):
            tg.start_soon(waiter, timeout)
        await _until_waiting(buf, 3)
        if isinstance(clock, ManualClock):
            await clock.advance(1e9)  # 31 simulated years: no deadline fires
            assert got == [] and buf.pending_waits == 3
        buf.set_transform(_ts(T0))
    assert got == [1.0, 1.0, 1.0]
    assert buf.pending_waits == 0


@pytest.mark.parametrize("clock_kind", ["manual", "system"])
async def test_buffer_wait_with_nan_timeout_is_a_value_error(clock_kind: str) -> None:
    """NaN is a ValueError, up front, on both clocks (also when the
    data is already there), and nothing stays registered."""
    clock: ManualClock | SystemClock = ManualClock(T0) if clock_kind == "manual" else SystemClock()
    buf = Buffer(clock=clock)
    with pytest.raises(ValueError, match="timeout must not be NaN"):
        await buf.lookup_transform_async("a", "b", Time(0), timeout=math.nan)
    buf.set_transform(_ts(T0))
    with pytest.raises(ValueError, match="timeout must not be NaN"):
        await buf.lookup_transform_async("a", "b", Time(0), timeout=math.nan)
    with pytest.raises(TypeError, match="timeout must be a number of seconds"):
        await buf.lookup_transform_async("a", "b", Time(0), timeout="1")  # type: ignore[arg-type]
    assert buf.pending_waits == 0


async def test_buffer_timeout_on_a_manual_clock_is_a_clock_deadline() -> None:
    """The Buffer's timeout is the clock's deadline primitive: it shows in
    ``pending``/``next_deadline`` and fires in the step that reaches it."""
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    errors: list[str] = []

    async def waiter() -> None:
        try:
            await buf.lookup_transform_async("a", "b", Time(0), timeout=Duration(2))
        except TimeoutException as exc:
            errors.append(f"{clock.now().ns - T0.ns} {exc}")

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0)
        assert clock.pending == 1 and clock.next_deadline() == T0 + Duration(2)
        await clock.advance(1.999_999_999)
        assert errors == []
        await clock.advance(5.0)
    assert len(errors) == 1
    assert errors[0].startswith("2000000000 Timed out after 2 s waiting for transform from [b]")
    assert clock.pending == 0 and buf.pending_waits == 0


# -- Clock.call_later (the deadline of a Buffer wait, with no cancel scope) ---------------


async def test_manual_call_later_runs_in_deadline_order_among_sleepers() -> None:
    clock = ManualClock(T0)
    log: list[tuple[str, Time]] = []

    async def sleeper() -> None:
        await clock.sleep(0.2)
        log.append(("sleeper", clock.now()))

    async with anyio.create_task_group() as tg:
        tg.start_soon(sleeper)
        await clock.advance(0)
        clock.call_later(0.3, lambda: log.append(("b", clock.now())))
        clock.call_later(Duration.from_sec(0.1), lambda: log.append(("a", clock.now())))
        cancel = clock.call_later(0.15, lambda: log.append(("cancelled", clock.now())))
        assert clock.pending == 4
        cancel()
        assert clock.pending == 3
        await clock.advance(1.0)
    ms = Duration.from_sec(0.001)
    assert log == [("a", T0 + ms * 100), ("sleeper", T0 + ms * 200), ("b", T0 + ms * 300)]
    assert clock.pending == 0


async def test_manual_call_later_edges() -> None:
    clock = ManualClock(T0)
    calls: list[str] = []
    clock.call_later(0, lambda: calls.append("zero"))  # due now: called at once
    clock.call_later(-1.0, lambda: calls.append("negative"))
    assert calls == ["zero", "negative"]
    never = clock.call_later(math.inf, lambda: calls.append("inf"))
    assert clock.pending == 0
    never()
    cancel = clock.call_later(1.0, lambda: calls.append("one"))
    await clock.advance(1.0)
    assert calls[-1] == "one"
    cancel()  # after it ran: harmless, and the count stays right
    cancel()
    assert clock.pending == 0
    assert clock.call_later(1.0, lambda: None) is not None
    with pytest.raises(ValueError):
        clock.call_later(math.nan, lambda: None)
    with pytest.raises(TypeError):
        clock.call_later("1", lambda: None)  # type: ignore[arg-type]


def _system_entries(clock: SystemClock) -> int:
    """How many entries (live or cancelled) the clock's timer heap of this run holds."""
    timers: Any = clock._timers
    if clock._trio_timers is not None:
        try:
            timers = clock._trio_timers.get()
        except LookupError:
            timers = None
    return 0 if timers is None else len(timers._heap)


async def test_system_call_later_fires_in_order_and_cancelled_calls_never_run() -> None:
    """Calls scheduled out of order fire in the order of their deadlines. Each deadline
    is known to lie between the loop's time read just before and just after its
    ``call_later`` plus the delay (the process may be preempted between two calls on a
    loaded machine, which moves the later-scheduled deadlines): every call must come
    no later than any call whose deadline is surely after its own."""
    clock = SystemClock()
    calls: list[str] = []
    done = anyio.Event()
    deadlines: dict[str, tuple[float, float]] = {}  # earliest, latest (the loop's time)

    def call(name: str) -> None:
        calls.append(name)
        if len(calls) == 3:
            done.set()

    def schedule(delay: float | Duration, name: str) -> Callable[[], None] | None:
        seconds = delay.to_sec() if isinstance(delay, Duration) else delay
        before = anyio.current_time()
        cancel = clock.call_later(delay, lambda: call(name))
        deadlines[name] = (before + seconds, anyio.current_time() + seconds)
        return cancel

    schedule(0.003, "last")
    schedule(0.002, "second")
    cancel = schedule(0.001, "cancelled")
    schedule(Duration.from_sec(0.0015), "first")
    assert cancel is not None
    cancel()
    with anyio.fail_after(5):  # a bound, not a sleep: the callbacks end the wait
        await done.wait()
    assert sorted(calls) == ["first", "last", "second"]  # each once; the cancelled never
    for earlier, later in itertools.pairwise(calls):
        assert deadlines[earlier][0] <= deadlines[later][1], (calls, deadlines)
    if all(deadlines[a][1] < deadlines[b][0] for a, b in (("first", "second"),
                                                        ("second", "last"))):  # fmt: skip
        assert calls == ["first", "second", "last"]  # not preempted: the exact order
    clock.call_later(0, lambda: calls.append("now"))  # due now: called at once
    assert calls[-1] == "now"
    assert clock.call_later(math.inf, lambda: calls.append("never")) is not None
    with pytest.raises(ValueError):
        clock.call_later(math.nan, lambda: None)


async def test_system_call_later_sweeps_cancelled_entries() -> None:
    clock = SystemClock()
    for _ in range(10_000):
        clock.call_later(1000.0, lambda: None)()  # scheduled, then cancelled at once
    assert _system_entries(clock) <= 128  # not 10 000 entries kept for 1000 s


async def test_system_call_later_reports_a_failing_callback_and_runs_the_rest(
    anyio_backend_name: str, caplog: pytest.LogCaptureFixture
) -> None:
    clock = SystemClock()
    reported: list[BaseException] = []
    if anyio_backend_name == "asyncio":
        import asyncio

        asyncio.get_running_loop().set_exception_handler(
            lambda loop, context: reported.append(context["exception"])
        )
    done = anyio.Event()

    def fail() -> None:
        raise RuntimeError("boom")

    clock.call_later(0.001, fail)
    clock.call_later(0.002, done.set)
    with anyio.fail_after(5):
        await done.wait()
    if anyio_backend_name == "asyncio":
        assert [str(e) for e in reported] == ["boom"]
    else:
        assert "boom" in caplog.text


def test_system_call_later_outside_an_event_loop_is_none() -> None:
    assert SystemClock().call_later(1.0, lambda: None) is None


async def test_running_asyncio_loop_only_in_asyncio_tasks(anyio_backend_name: str) -> None:
    from tfbus._aio import running_asyncio_loop

    loop = running_asyncio_loop()
    if anyio_backend_name == "asyncio":
        import asyncio

        assert loop is asyncio.get_running_loop()
    else:
        assert loop is None
