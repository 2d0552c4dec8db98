"""Awaited lookups under a policy (``Buffer.lookup_transform_async(..., policy=...)``), on
asyncio and trio, driven by ManualClock: ``Window(past, future_wait)`` answers from the
past at once, else waits up to ``future_wait`` (bounded by ``timeout`` too) for data at the
time; other policies wait until the policy can answer."""

from __future__ import annotations

import anyio
import pytest

from tfbus import (
    Buffer,
    ForwardExtrapolationException,
    Header,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.clock import ManualClock
from tfbus.core.policy import Clamp, Nearest, PolicyResult, Previous, Window

pytestmark = pytest.mark.anyio

NS = 1_000_000_000
T0 = Time(1000)


def at(seconds: float) -> Time:
    """T0 + seconds."""
    return Time.from_ns(T0.ns + round(seconds * NS))


def tf(parent: str, child: str, stamp: Time, x: float) -> TransformStamped:
    return TransformStamped(
        Header(stamp, parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion(0, 0, 0, 1))
    )


def _buffer() -> tuple[ManualClock, Buffer]:
    """odom <- base at T0 - 1 s (x 1) and T0 (x 2)."""
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    buf.set_transform(tf("odom", "base", at(-1.0), 1.0))
    buf.set_transform(tf("odom", "base", T0, 2.0))
    return clock, buf


async def test_window_answers_from_the_past_without_waiting() -> None:
    _, buf = _buffer()
    ts, report = await buf.lookup_transform_async(
        "odom", "base", at(0.25), timeout=5.0, policy=Window(past=0.5, future_wait=2.0)
    )
    assert ts.transform.translation.x == 2.0
    assert report.stamps_ns == (T0.ns,)
    assert report.max_abs_delta_ns == 250_000_000
    assert buf.pending_waits == 0


async def test_window_waits_for_data_at_the_time_up_to_future_wait() -> None:
    """At T0 + 1 s (beyond past = 0.5 s) the wait is set up; data at T0 + 2 s arrives
    0.5 s later: the interpolated, exact answer (x 2.5)."""
    clock, buf = _buffer()
    got: list[PolicyResult] = []

    async def waiter() -> None:
        got.append(
            await buf.lookup_transform_async(
                "odom", "base", at(1.0), timeout=10.0, policy=Window(0.5, 2.0)
            )
        )

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0.5)
        assert not got and buf.pending_waits == 1
        buf.set_transform(tf("odom", "base", at(2.0), 3.0))
    ts, report = got[0]
    assert ts.transform.translation.x == 2.5
    assert report.exact
    assert buf.pending_waits == 0


async def test_window_future_wait_bounds_the_wait_before_timeout() -> None:
    clock, buf = _buffer()
    errors: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.lookup_transform_async(
                "odom", "base", at(1.0), timeout=10.0, policy=Window(0.5, 2.0)
            )
        except TimeoutException as exc:
            errors.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(1.999)
        assert not errors
        await clock.advance(0.001)
    assert len(errors) == 1
    assert "Timed out after 2 s" in str(errors[0])
    assert buf.pending_waits == 0


async def test_the_shorter_of_timeout_and_future_wait_wins() -> None:
    clock, buf = _buffer()
    errors: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.lookup_transform_async(
                "odom", "base", at(1.0), timeout=0.75, policy=Window(0.5, 2.0)
            )
        except TimeoutException as exc:
            errors.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0.75)
    assert len(errors) == 1
    assert "Timed out after 0.75 s" in str(errors[0])


async def test_window_without_future_wait_raises_tf2s_error_at_once() -> None:
    _, buf = _buffer()
    with pytest.raises(ForwardExtrapolationException):
        await buf.lookup_transform_async("odom", "base", at(1.0), policy=Window(0.5))
    assert buf.pending_waits == 0


async def test_a_nearest_wait_ends_when_a_near_sample_arrives() -> None:
    """Nearest(0.1) at T0 + 1 s: nothing near; a sample at T0 + 1.05 s (x 7), held
    as is, not interpolated."""
    clock, buf = _buffer()
    got: list[PolicyResult] = []

    async def waiter() -> None:
        got.append(
            await buf.lookup_transform_async(
                "odom", "base", at(1.0), timeout=3.0, policy=Nearest(0.1)
            )
        )

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0.5)
        assert not got
        buf.set_transform(tf("odom", "base", at(1.05), 7.0))
    ts, report = got[0]
    assert ts.transform.translation.x == 7.0
    assert report.stamps_ns == ((at(1.05)).ns,)


async def test_sync_buffer_lookup_takes_the_policy() -> None:
    _, buf = _buffer()
    ts, report = buf.lookup_transform("odom", "base", at(0.5), policy=Clamp(1.0))
    assert ts.transform.translation.x == 2.0
    assert report.max_abs_delta_ns == NS // 2


async def test_wait_for_transform_takes_the_policy() -> None:
    """wait_for_transform(..., policy=Previous()) at T0 + 1 s: answered at once by the
    T0 sample (x 2), 1 s old."""
    _, buf = _buffer()
    ts, report = await buf.wait_for_transform("odom", "base", at(1.0), 1.0, policy=Previous())
    assert ts.transform.translation.x == 2.0
    assert report.max_abs_delta_ns == NS
