"""A ``SimClock`` fed mutated ``/clock`` samples (hypothesis, derandomized, bounded), on
asyncio and trio.

Each example is a run of samples as the three middlewares carry them (tfbus's Zenoh wire
format, CDR, ROS 1), valid ones at edge times (0, the int32 and uint32 second limits,
steps back, repeats, stalls) among mutated ones (bits flipped, cut, extended); what decodes
is published on ``/clock`` of a bus, with objects that are not a Clock at all. Whatever
comes, the clock never raises into the publisher, its time is always that of the last
accepted sample (``Time(0)`` before any), every sample is counted as accepted or dropped,
a step back is counted as a jump (rclpy's ``TimeSource`` reports it to jump callbacks),
and a task sleeping on simulated time still wakes when a later valid sample arrives.
"""

from __future__ import annotations

from typing import Any

import anyio
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tfbus import Bus, SimClock
from tfbus.codecs import cdr, native, ros1
from tfbus.errors import WireError
from tfbus.messages import Clock
from tfbus.time import TIME_MAX_NS, Time
from tfbus.topics import CLOCK_TOPIC

CODECS = {"native": native, "cdr": cdr, "ros1": ros1}
EDGE_SECONDS = [0, 1, 2, 59, 60, 2**31 - 2, 2**31 - 1, 2**32 - 1]


@st.composite
def sample(draw: st.DrawFn) -> tuple[str, bytes]:
    """One ``/clock`` sample on the wire of one codec: valid or mutated."""
    name = draw(st.sampled_from(sorted(CODECS)))
    codec = CODECS[name]
    sec = draw(st.sampled_from(EDGE_SECONDS) | st.integers(0, 2**31 - 1))
    nsec = draw(st.sampled_from([0, 1, 999_999_999]) | st.integers(0, 999_999_999))
    try:
        raw = bytearray(codec.encode_clock(Clock(Time(sec, nsec))))
    except WireError:  # a time this middleware cannot carry
        raw = bytearray(ros1.encode_clock(Clock(Time(sec % 2**31, nsec))))
        name = "ros1"
    for _ in range(draw(st.integers(0, 2))):
        op = draw(st.sampled_from(["flip", "cut", "extend", "byte"]))
        if op == "cut":
            del raw[draw(st.integers(0, len(raw))):]
        elif op == "extend":
            raw += draw(st.binary(max_size=8))
        elif raw:
            at = draw(st.integers(0, len(raw) - 1))
            if op == "flip":
                raw[at] ^= 1 << draw(st.integers(0, 7))
            else:
                raw[at] = draw(st.sampled_from([0, 0x7F, 0x80, 0xFF]))
    return name, bytes(raw)


JUNK: list[Any] = [None, 5, "1.5", Clock(None), Clock(12.5), object()]  # type: ignore[arg-type]


async def _run(samples: list[tuple[str, bytes] | int]) -> None:
    async with Bus() as bus, SimClock(bus) as clock:
        last: Time | None = None
        jumps = 0
        for item in samples:
            if isinstance(item, int):  # an object that is not a Clock
                before = (clock.accepted, clock.now())
                bus.publish_nowait(CLOCK_TOPIC, JUNK[item])
                assert (clock.accepted, clock.now()) == before
                continue
            name, raw = item
            try:
                message = CODECS[name].decode_clock(raw)
            except WireError:
                continue  # counted by the transport that read it; never reaches the bus
            accepted = clock.accepted
            bus.publish_nowait(CLOCK_TOPIC, message)
            if clock.accepted == accepted + 1:
                if last is not None and message.clock < last:
                    jumps += 1
                last = message.clock
            assert clock.now() == (last if last is not None else Time(0))
            assert 0 <= clock.now_ns() <= TIME_MAX_NS
        assert clock.received == clock.accepted + clock.dropped
        assert clock.jumps == jumps
        # After any of it, a task sleeping on simulated time wakes at a later sample.
        now = clock.now_ns()
        wake = Time.from_ns(min(now + 1_000_000_000, TIME_MAX_NS - 1))
        woke = anyio.Event()

        async def sleeper() -> None:
            await clock.sleep_until(wake)
            woke.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            await anyio.wait_all_tasks_blocked()
            bus.publish_nowait(CLOCK_TOPIC, Clock(wake))
            with anyio.fail_after(10):
                await woke.wait()
        assert clock.now() == wake


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@settings(max_examples=60, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(samples=st.lists(sample() | st.integers(0, len(JUNK) - 1), max_size=30))
def test_any_run_of_clock_samples_keeps_the_clock_consistent(
    backend: str, samples: list[tuple[str, bytes] | int]
) -> None:
    anyio.run(_run, samples, backend=backend)
