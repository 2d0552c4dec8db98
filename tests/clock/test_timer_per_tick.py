"""``every()`` per tick: one deadline wait, no anyio cancel scope; jumps still re-anchor."""

from __future__ import annotations

import itertools
import time
from typing import Any

import anyio
import pytest
from event_loops import UVLOOP, anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import Bus, SimClock
from tfbus.clock import Clock, ManualClock, PeriodicTimer, SystemClock, Tick, every
from tfbus.errors import SimTimeStalled
from tfbus.messages import Clock as ClockMessage
from tfbus.time import Duration, Time
from tfbus.topics import CLOCK_TOPIC

pytestmark = pytest.mark.anyio

T0 = Time(100)


def _assert_on_grid(ticks: list[Tick], period_ns: int) -> None:
    """Each tick's deadline is the first tick's plus whole periods, one per index, and
    no tick comes before its deadline. A loaded machine may skip deadlines, the
    immediate first tick's too (the process preempted between the timer's first two
    clock reads): the indices then jump, and the phase is kept."""
    first = ticks[0]
    for tick in ticks:
        assert (tick.expected - first.expected).ns == (tick.index - first.index) * period_ns
        assert tick.actual >= tick.expected


def _count_cancel_scopes(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count ``anyio.CancelScope(...)`` made from now on (tfbus code calls it through the
    ``anyio`` module)."""
    made = [0]
    real = anyio.CancelScope

    def counting(*args: Any, **kwargs: Any) -> anyio.CancelScope:
        made[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(anyio, "CancelScope", counting)
    return made


async def test_manual_clock_ticks_enter_no_cancel_scope(
    monkeypatch: pytest.MonkeyPatch, anyio_backend: str
) -> None:
    """100 ticks of a 100 Hz timer: the deadline wait of each is a callback of the clock
    (``call_later``) and a one-shot wake-up, not a cancel scope entered and left per
    tick; the ticks are still exactly on the grid."""
    clock = ManualClock(T0)
    ticks: list[Tick] = []

    async def run() -> None:
        async for tick in every(0.01, clock=clock):
            ticks.append(tick)

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(0)
        made = _count_cancel_scopes(monkeypatch)
        await clock.advance(1.0)
        assert made[0] == 0
        monkeypatch.undo()
        tg.cancel_scope.cancel()
    assert [t.index for t in ticks] == list(range(100))
    assert [t.expected for t in ticks] == [T0 + Duration.from_ns((i + 1) * 10_000_000)
                                           for i in range(100)]
    assert all(t.actual == t.expected for t in ticks)


async def test_system_clock_ticks_enter_no_anyio_cancel_scope(
    monkeypatch: pytest.MonkeyPatch, anyio_backend: str
) -> None:
    """On the wall clock too (asyncio: a loop timer and a future; trio: one trio cancel
    scope with the deadline, ``trio.sleep``'s own cost)."""
    made = _count_cancel_scopes(monkeypatch)
    ticks: list[Tick] = []
    timer = every(0.002, clock=SystemClock(), immediate=True)
    async for tick in timer:
        ticks.append(tick)
        if len(ticks) == 5:
            break
    assert made[0] == 0
    monkeypatch.undo()
    _assert_on_grid(ticks, 2_000_000)


class _SteppedWallClock:
    """``time.time_ns`` plus an offset the test moves (a wall-clock step)."""

    def __init__(self) -> None:
        self.offset = 0
        self.real = time.time_ns

    def __call__(self) -> int:
        return self.real() + self.offset


async def _ticks_with_a_step_back(
    clock: Clock, wall: _SteppedWallClock, period: float, n: int, stepped_at: list[int]
) -> list[Tick]:
    """The first ``n`` ticks of ``every(period, clock=clock, immediate=True)`` while
    another task steps ``wall`` back by 100 s once the first tick is in (the clock reading
    that sees the step, which runs the jump callbacks, appended to ``stepped_at``)."""
    ticks: list[Tick] = []
    first = anyio.Event()

    async def step_back() -> None:
        await first.wait()
        wall.offset -= 100 * 10**9
        stepped_at.append(clock.now_ns())  # this reading sees the step: jump callbacks

    with anyio.fail_after(30):  # ends a hung loop only
        async with anyio.create_task_group() as tg:
            tg.start_soon(step_back)
            async for tick in every(period, clock=clock, immediate=True):
                ticks.append(tick)
                first.set()
                if len(ticks) == n:
                    break
    return ticks


async def test_system_clock_backward_step_seen_elsewhere_reanchors_a_sleeping_timer(
    monkeypatch: pytest.MonkeyPatch, anyio_backend: str
) -> None:
    """A backward step of the wall clock that another task observes wakes the sleeping
    timer, which re-anchors: the next deadline is one period after the time it read on
    waking (``PeriodicTimer``'s jump policy), not the old schedule 100 s ahead."""
    wall = _SteppedWallClock()
    monkeypatch.setattr(time, "time_ns", wall)
    clock: Clock = SystemClock(max_sleep=60.0)
    period = 0.2
    stepped_at: list[int] = []

    ticks = await _ticks_with_a_step_back(clock, wall, period, 2, stepped_at)
    (stepped,) = stepped_at
    before, after = ticks
    assert after.expected.ns < before.expected.ns - 99 * 10**9  # on the stepped-back clock
    assert after.expected.ns >= stepped + int(period * 1e9)
    assert after.expected.ns - stepped < int(period * 1e9) + 5 * 10**9
    assert after.index == before.index + 1
    assert after.overruns == 0


async def test_a_jump_during_a_wall_clock_wait_leaves_no_timer_behind(
    monkeypatch: pytest.MonkeyPatch, anyio_backend_name: str
) -> None:
    """A backward step that wakes a sleeping timer also takes its deadline off the
    loop (asyncio: the jump callback cancels the loop timer before it sets the tick's
    future), so that the old deadline, reached later, neither sets that future a second
    time (an ``InvalidStateError`` reported by the loop) nor wakes anything: the loop's
    exception handler is never called while three more ticks pass the old deadline."""
    import asyncio

    errors: list[dict[str, Any]] = []
    if anyio_backend_name == "asyncio":
        asyncio.get_running_loop().set_exception_handler(lambda _loop, ctx: errors.append(ctx))
    wall = _SteppedWallClock()
    monkeypatch.setattr(time, "time_ns", wall)
    clock: Clock = SystemClock(max_sleep=60.0)
    period = 0.05

    ticks = await _ticks_with_a_step_back(clock, wall, period, 5, [])
    assert ticks[1].expected.ns < ticks[0].expected.ns - 99 * 10**9  # re-anchored once
    for before, after in itertools.pairwise(ticks[1:]):  # then on the new grid
        assert (after.expected - before.expected).ns == (after.index - before.index) * 50_000_000
    assert errors == []


async def test_a_cancellation_in_the_ticks_loop_pass_leaves_its_deadline_harmless(
    anyio_backend_name: str,
) -> None:
    """A cancel scope's deadline and the tick's deadline handled in one pass of the
    loop (both overdue when the loop wakes, the scope's first): the cancellation
    cancels the tick's future, then the tick's deadline comes due in that same pass;
    it must find the future done and leave it (no ``InvalidStateError`` reported to the
    loop's exception handler), and the loop ends as cancelled."""
    import asyncio

    errors: list[dict[str, Any]] = []
    if anyio_backend_name == "asyncio":
        asyncio.get_running_loop().set_exception_handler(lambda _loop, ctx: errors.append(ctx))
    ticks: list[Tick] = []
    waiting = anyio.Event()

    async def run() -> None:
        with anyio.move_on_after(0.05):
            async for tick in every(0.1, clock=SystemClock(), immediate=True):
                ticks.append(tick)
                waiting.set()

    with anyio.fail_after(30):  # ends a hung loop only
        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            await waiting.wait()
            # Hold the loop past both deadlines, so that one pass handles both: the
            # condition under test, not a wait for a result.
            time.sleep(0.3)
    assert len(ticks) == 1
    assert errors == []


async def test_every_on_a_sim_clock_with_a_wall_timeout_raises_sim_time_stalled(
    anyio_backend: str,
) -> None:
    """A SimClock with a ``wall_timeout`` schedules no callbacks (its waits must notice a
    stalled ``/clock``): the timer sleeps on it, and the stall ends the loop."""
    async with Bus() as bus, SimClock(bus, wall_timeout=0.3) as clock:
        bus.publish_nowait(CLOCK_TOPIC, ClockMessage(Time.from_sec(1.0)))
        ticks: list[Tick] = []
        with anyio.fail_after(30):  # the wall guard, not this bound, must end the wait
            with pytest.raises(SimTimeStalled):
                async for tick in every(0.5, clock=clock, immediate=True):
                    ticks.append(tick)
        assert [t.expected for t in ticks] == [Time.from_sec(1.0)]


async def test_system_clock_tick_costs_at_most_six_tfbus_calls(anyio_backend: str) -> None:
    """A waited tick of ``every()`` on the wall clock makes at most 6 Python calls into
    tfbus (two clock reads, the loop lookup, the timer coroutine's start and resume;
    on asyncio the one wake of its future by a loop timer): no entry in the clock's
    timer queue (add, arm, fire, take due: 4 more calls a tick on asyncio) and no inner
    wait coroutine (2 more on trio). On uvloop one more: the timer's delay rounded up to
    uvloop's whole milliseconds (``tfbus._aio.timer_delay``), where without it a deadline
    woken early re-arms a timer for the rest, which uvloop runs at once, until the
    deadline passes (19 calls a tick). The jump callback
    is registered once per timer, not per tick, and the tick's stamps are built without
    ``Time.from_ns``. The ticks keep their grid."""
    import sys
    from pathlib import Path

    import tfbus

    root = str(Path(tfbus.__file__).parent)
    calls = [0]

    def profile(frame: Any, event: str, arg: object) -> None:
        if event == "call" and frame.f_code.co_filename.startswith(root):
            calls[0] += 1

    n = 40
    ticks: list[Tick] = []
    timer = every(0.002, clock=SystemClock(), immediate=True)
    ticks.append(await timer.__anext__())  # the first (immediate) tick: not counted
    sys.setprofile(profile)
    try:
        for _ in range(n):
            ticks.append(await timer.__anext__())
    finally:
        sys.setprofile(None)
    # A loaded machine may find a deadline already passed (no wait: fewer calls); +10
    # for what runs once while the profiler is on (setting it up and off).
    per_tick = 7 if anyio_backend == UVLOOP else 6
    assert calls[0] <= per_tick * n + 10, calls[0] / n
    _assert_on_grid(ticks, 2_000_000)
    assert ticks[-1].index == n + ticks[-1].overruns


async def test_jump_callback_is_registered_once_per_timer_and_dropped_with_it(
    monkeypatch: pytest.MonkeyPatch, anyio_backend: str
) -> None:
    """The timer's backward-jump callback is registered with the clock on its first
    wait and kept across ticks (one entry, not one per tick); collecting the timer
    unregisters it, so abandoned timers do not pile up callbacks on a shared clock."""
    import gc

    clock = ManualClock(T0)
    registered = clock._jump  # the clock's jump callbacks (a len()-able registry)
    registrations = [0]
    real_on_jump = clock.on_jump

    def counting_on_jump(*args: Any, **kwargs: Any) -> Any:
        registrations[0] += 1
        return real_on_jump(*args, **kwargs)

    monkeypatch.setattr(clock, "on_jump", counting_on_jump)
    timer = every(0.01, clock=clock)

    async def run(periodic: PeriodicTimer, count: int) -> list[Tick]:
        got: list[Tick] = []
        async for tick in periodic:
            got.append(tick)
            if len(got) == count:
                break
        return got

    async with anyio.create_task_group() as tg:
        tg.start_soon(run, timer, 50)
        await clock.advance(0)
        assert len(registered) == 1
        await clock.advance(0.5)
    assert len(registered) == 1
    assert registrations[0] == 1  # 50 ticks, one registration
    del timer, tg
    gc.collect()
    assert len(registered) == 0
