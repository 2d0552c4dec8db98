"""Benchmark tfbus's time layer: ManualClock stepping, deadlines, Time/Duration values.

    .venv/bin/python benchmarks/bench_clock.py [--quick] [--backend asyncio|trio|both]

Prints, on this machine (medians over repeats; other work may share the cores):

1. **ManualClock.advance, 100 ticks**: a 100 Hz ``every()`` timer feeding a consumer
   through a memory stream, advanced by one simulated second: wall time per advance.
   (The tests check that ``advance`` never calls anyio's asyncio
   ``wait_all_tasks_blocked``, which sleeps 0.1 s of wall time per runnable task; this
   shows what it costs instead.)
2. **10 000 cancelled sleepers**: start 10 000 ``clock.sleep(5)``, cancel them all, then
   advance: wall time (the heap is compacted, not scanned per sleeper).
3. **A Buffer wait that times out on a ManualClock**: ``lookup_transform_async(...,
   timeout=1)`` then ``advance(1)``: the clock's deadline scope
   (``ManualClock.move_on_after``) against the previous mechanism, a timer task in a
   task group that sleeps on the clock and cancels the group, measured the same way.
4. **Entering and leaving a deadline scope** with nothing to wait for:
   ``SystemClock().move_on_after(1)`` vs ``anyio.move_on_after(1)`` (the cost of the
   timeout checks), and ``ManualClock().move_on_after(1)``.
5. **Time / Duration** (synchronous, ns per operation): construction, ``from_ns``,
   ``<``, ``==``, ``hash``, against the same one-int type written as
   ``@dataclass(order=True, frozen=True, slots=True)`` (the alternative tfbus.time explains it does
   not use), and ``seconds_to_ns`` (exact integer rounding) against
   ``round(Fraction(s) * 10**9)``.

Figures only: nothing here asserts a timing.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import timeit
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import anyio
import anyio.lowlevel

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tfbus.buffer import Buffer
from tfbus.clock import ManualClock, SystemClock, every
from tfbus.errors import TimeoutException
from tfbus.time import Duration, Time, seconds_to_ns

T0 = Time(1000)


def _median_ms(samples: list[float]) -> str:
    return f"{statistics.median(samples) * 1e3:8.2f} ms"


async def _advance_100_ticks() -> float:
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
        await clock.advance(0)
        started = time.perf_counter()
        await clock.advance(1.0)
        elapsed = time.perf_counter() - started
        tg.cancel_scope.cancel()
    assert got == list(range(100)), got[:5]
    return elapsed


async def _cancelled_sleepers(n: int = 10_000) -> float:
    clock = ManualClock(T0)
    started = time.perf_counter()
    async with anyio.create_task_group() as doomed:
        for _ in range(n):
            doomed.start_soon(clock.sleep, 5.0)
        await clock.advance(0)
        doomed.cancel_scope.cancel()
    await clock.advance(10.0)
    elapsed = time.perf_counter() - started
    assert clock.pending == 0
    return elapsed


async def _buffer_timeout_scope(waits: int) -> float:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    timeouts = 0

    async def waiter() -> None:
        nonlocal timeouts
        try:
            await buf.lookup_transform_async("a", "b", Time(0), timeout=1.0)
        except TimeoutException:
            timeouts += 1

    started = time.perf_counter()
    async with anyio.create_task_group() as tg:
        for _ in range(waits):
            tg.start_soon(waiter)
        await clock.advance(1.0)
    elapsed = time.perf_counter() - started
    assert timeouts == waits
    return elapsed / waits


async def _buffer_timeout_timer_task(waits: int) -> float:
    """The previous mechanism, rebuilt here for comparison: a timer task per wait."""
    clock = ManualClock(T0)
    timeouts = 0

    async def waiter() -> None:
        nonlocal timeouts
        event = anyio.Event()
        async with anyio.create_task_group() as tg:

            async def expire() -> None:
                await clock.sleep(1.0)
                tg.cancel_scope.cancel()

            tg.start_soon(expire)
            await event.wait()
            tg.cancel_scope.cancel()
        if not event.is_set():
            timeouts += 1

    started = time.perf_counter()
    async with anyio.create_task_group() as tg:
        for _ in range(waits):
            tg.start_soon(waiter)
        await clock.advance(1.0)
    elapsed = time.perf_counter() - started
    assert timeouts == waits
    return elapsed / waits


async def _scope_cost(make: Callable[[], object], n: int) -> float:
    started = time.perf_counter()
    for _ in range(n):
        with make():  # type: ignore[attr-defined]
            pass
    return (time.perf_counter() - started) / n


@dataclass(order=True, frozen=True, slots=True)
class _DataclassTime:
    """The rejected alternative: a one-int dataclass with generated ordering."""

    _ns: int


def _ns_per_op(stmt: str, env: dict[str, object], number: int) -> float:
    return min(timeit.repeat(stmt, globals=env, number=number, repeat=7)) / number * 1e9


def _values(number: int) -> None:
    a, b = Time.from_ns(5), Time.from_ns(6)
    ha, hb = _DataclassTime(5), _DataclassTime(6)
    env: dict[str, object] = {
        "Time": Time,
        "Duration": Duration,
        "a": a,
        "b": b,
        "ha": ha,
        "hb": hb,
        "seconds_to_ns": seconds_to_ns,
        "Fraction": Fraction,
    }
    rows = [
        ("Time.from_ns(123456789)", "Time.from_ns(123456789)", None),
        ("Time(1, 5)", "Time(1, 5)", None),
        ("a < b", "a < b", "ha < hb"),
        ("a == b", "a == b", "ha == hb"),
        ("hash(a)", "hash(a)", "hash(ha)"),
        ("Duration(1) * 1.5", "Duration(1) * 1.5", None),
        ("seconds_to_ns(1.7e9 + 0.1)", "seconds_to_ns(1700000000.1)", None),
        ("round(Fraction(s) * 10**9)", "round(Fraction(1700000000.1) * 10**9)", None),
    ]
    print("\n5. Time / Duration, ns per operation (min of 7 repeats)")
    print(f"   {'operation':32s} {'tfbus':>9s} {'dataclass':>13s}")
    for label, stmt, ref in rows:
        ours = _ns_per_op(stmt, env, number)
        theirs = f"{_ns_per_op(ref, env, number):10.0f} ns" if ref else ""
        print(f"   {label:32s} {ours:6.0f} ns {theirs:>13s}")


def _run(backend: str, repeats: int) -> None:
    print(f"\n== {backend}")

    def sample(fn: Callable[[], Awaitable[float]], n: int) -> list[float]:
        return [anyio.run(fn, backend=backend) for _ in range(n)]

    ticks = sample(_advance_100_ticks, repeats)
    print(f"1. advance(1 s) through 100 ticks:      {_median_ms(ticks)}")
    cancelled = sample(_cancelled_sleepers, max(1, repeats // 3))
    print(f"2. 10 000 cancelled sleepers:           {_median_ms(cancelled)}")
    waits = 1000
    scope = sample(lambda: _buffer_timeout_scope(waits), repeats)
    task = sample(lambda: _buffer_timeout_timer_task(waits), repeats)
    print(
        f"3. Buffer wait timing out (per wait, {waits} waits): clock deadline scope "
        f"{statistics.median(scope) * 1e6:7.1f} µs, timer task "
        f"{statistics.median(task) * 1e6:7.1f} µs"
    )
    n = 20_000
    system = SystemClock()
    manual = ManualClock(T0)
    for label, make in (
        ("anyio.move_on_after(1)", lambda: anyio.move_on_after(1)),
        ("SystemClock().move_on_after(1)", lambda: system.move_on_after(1)),
        ("ManualClock().move_on_after(1)", lambda: manual.move_on_after(1)),
    ):
        costs = sample(lambda make=make: _scope_cost(make, n), repeats)  # type: ignore[misc]
        print(f"4. enter+leave {label:32s} {statistics.median(costs) * 1e9:7.0f} ns")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--backend", choices=["asyncio", "trio", "both"], default="both")
    args = parser.parse_args()
    repeats = 3 if args.quick else 9
    backends = ["asyncio", "trio"] if args.backend == "both" else [args.backend]
    for backend in backends:
        _run(backend, repeats)
    _values(20_000 if args.quick else 200_000)


if __name__ == "__main__":
    main()
