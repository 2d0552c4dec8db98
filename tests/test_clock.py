"""Tests for tfbus/clock.py: ManualClock, SystemClock, every()."""

from __future__ import annotations

import time

import anyio
import pytest

from tfbus.clock import Clock, ManualClock, PeriodicTimer, SystemClock, Tick, every
from tfbus.time import Duration, Time

pytestmark = pytest.mark.anyio


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


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


async def test_system_clock_sleep_until_past_returns_at_once() -> None:
    clock = SystemClock()
    with anyio.fail_after(5):
        await clock.sleep_until(Time(0))
        await clock.sleep(-1.0)


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
    clock = ManualClock(T0)
    with anyio.fail_after(5):
        await clock.sleep_until(Time(1))
        await clock.sleep(0)


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


async def test_advance_100_ticks_is_instant_on_both_backends() -> None:
    """No wall-clock sleeping inside advance (anyio's asyncio helper sleeps 0.1 s)."""
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

    started = time.monotonic()
    async with anyio.create_task_group() as tg:
        tg.start_soon(producer)
        tg.start_soon(consumer)
        await clock.advance(1.0)
        assert got == list(range(100))
        tg.cancel_scope.cancel()
    assert time.monotonic() - started < 3.0


async def test_many_cancelled_sleepers_are_cheap_and_forgotten() -> None:
    clock = ManualClock(T0)
    woke: list[int] = []

    async def sleeper(i: int) -> None:
        await clock.sleep(1.0 + i * 1e-6)
        woke.append(i)

    started = time.monotonic()
    async with anyio.create_task_group() as tg:
        async with anyio.create_task_group() as doomed:
            for _ in range(10_000):
                doomed.start_soon(clock.sleep, 5.0)
            await clock.advance(0)
            assert clock.pending == 10_000
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
    assert time.monotonic() - started < 5.0
