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
