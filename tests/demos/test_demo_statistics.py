"""The demo broadcaster's statistics keep a bounded window of tick lateness."""

from __future__ import annotations

from collections import deque

import anyio
import pytest

from tfbus import Bus, ManualClock, Time
from tfbus.demos.tutorial import LATENESS_WINDOW, BroadcasterStatistics, broadcaster_node

pytestmark = pytest.mark.anyio


def test_the_default_window_is_bounded() -> None:
    stats = BroadcasterStatistics()
    assert isinstance(stats.lateness_ns, deque)
    assert stats.lateness_ns.maxlen == LATENESS_WINDOW == 100_000


async def test_a_long_running_broadcaster_keeps_only_the_latest_lateness(
    anyio_backend: str,
) -> None:
    """1100 ticks (1.1 s at 1 kHz of ManualClock time) into a window of 100: every one
    sent, the latest 100 lateness values kept, all 0 on a ManualClock."""
    clock = ManualClock(Time(1000))
    stats = BroadcasterStatistics(lateness_ns=deque(maxlen=100))
    async with Bus() as bus, anyio.create_task_group() as tg:
        tg.start_soon(broadcaster_node, bus, clock, 1000.0, stats)
        await clock.advance(0)
        await clock.advance(1.1 - 1e-6)
        tg.cancel_scope.cancel()
    assert stats.sent == 1100
    assert list(stats.lateness_ns) == [0] * 100
    assert stats.rate() == pytest.approx(1000.0)


class _CountingClock(ManualClock):
    """A ManualClock that counts the reads that build a Time (``now()``)."""

    def __init__(self, start: Time) -> None:
        super().__init__(start)
        self.now_calls = 0

    def now(self) -> Time:
        self.now_calls += 1
        return super().now()


async def test_each_tick_is_stamped_with_the_time_the_timer_read(anyio_backend: str) -> None:
    """100 ticks at 1 kHz: each transform's stamp is its tick's time (the one clock read
    that fired the tick, 1 ms apart from 1000 s on), with no second read of the clock per
    tick; the lateness window holds those stamps minus their deadlines (0 here)."""
    clock = _CountingClock(Time(1000))
    stats = BroadcasterStatistics()
    stamps: list[int] = []
    async with Bus() as bus, anyio.create_task_group() as tg:
        with bus.subscribe_callback(
            "/tf", lambda m: stamps.extend(t.header.stamp.ns for t in m.transforms)
        ):
            tg.start_soon(broadcaster_node, bus, clock, 1000.0, stats)
            await clock.advance(0)
            await clock.advance(0.1 - 1e-6)
            tg.cancel_scope.cancel()
    assert stamps == [1000 * 10**9 + k * 10**6 for k in range(100)]
    assert clock.now_calls == 0
    assert (stats.sent, stats.first_ns, stats.last_ns) == (100, stamps[0], stamps[-1])
    assert list(stats.lateness_ns) == [0] * 100
