"""``every()`` without a clock runs on the system clock, as Buffer and TransformListener do."""

from __future__ import annotations

import time

import anyio
import pytest

from tfbus import Time, every


@pytest.mark.anyio
async def test_every_defaults_to_the_system_clock(anyio_backend: str) -> None:
    before = Time.from_ns(time.time_ns())
    ticks = []
    with anyio.fail_after(30):  # three 10 ms ticks; the bound only ends a hung loop
        async for tick in every(0.01, immediate=True):
            ticks.append(tick)
            if len(ticks) == 3:
                break
    after = Time.from_ns(time.time_ns())
    # Deadlines on wall time (a ManualClock would start at its own time, not now).
    assert before <= ticks[0].expected <= after
    # The schedule is first + k * period on that clock: 0, 10, 20 ms after the first
    # (or later indices if a loaded machine skipped one, the first tick's included: the
    # process preempted between the timer's first two clock reads; the phase is kept).
    for tick in ticks:
        assert (tick.expected - ticks[0].expected).ns == (tick.index - ticks[0].index) * 10_000_000
        assert before <= tick.actual <= after
        assert tick.actual >= tick.expected
