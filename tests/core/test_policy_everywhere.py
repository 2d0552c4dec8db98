"""``policy=`` on the rest of the lookups: ``BufferCore.can_transform``,
``Buffer.can_transform_async``, ``lookup_transform_full_async``, ``transform`` and
``transform_full`` (asyncio and trio, ManualClock). A non-exact policy's answer always
carries its :class:`~tfbus.core.policy.PolicyReport`; ``Exact()`` is tf2's rule."""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest

from tfbus import (
    Buffer,
    ForwardExtrapolationException,
    Header,
    Point,
    PointStamped,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.core.policy import Clamp, Exact, Nearest, PolicyResult, Previous, Window
from tfbus.filters import FilterFailureReason, MessageFilter

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
    """map <- odom static (x 10); odom <- base at T0 - 1 s (x 1) and T0 (x 2)."""
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    buf.set_transform_static(tf("map", "odom", Time(0), 10.0))
    buf.set_transform(tf("odom", "base", at(-1.0), 1.0))
    buf.set_transform(tf("odom", "base", T0, 2.0))
    return clock, buf


def test_can_transform_takes_the_policy() -> None:
    core = BufferCore()
    core.set_transform(tf("odom", "base", at(-1.0), 1.0))
    core.set_transform(tf("odom", "base", T0, 2.0))
    assert core.can_transform("odom", "base", at(0.5)) is False
    assert core.can_transform("odom", "base", at(0.5), policy=Exact()) is False
    assert core.can_transform("odom", "base", at(0.5), policy=Clamp(1.0)) is True
    assert core.can_transform("odom", "base", at(0.5), policy=Nearest(0.25)) is False
    ok, msg = core.can_transform("odom", "base", at(0.5), True, policy=Nearest(0.25))
    assert ok is False
    assert msg.startswith("Lookup would require extrapolation 0.500000000s into the future.")
    assert core.can_transform("odom", "base", at(5.0), True, policy=Previous()) == (True, "")
    ok, msg = core.can_transform("odom", "ghost", at(0.5), True, policy=Previous())
    assert (ok, msg) == (False, "canTransform: source_frame ghost does not exist.")
    with pytest.raises(TypeError, match="policy must be Exact"):
        core.can_transform("odom", "base", at(0.5), policy="nearest")  # type: ignore[arg-type]


@pytest.mark.anyio
async def test_can_transform_async_waits_under_the_policy() -> None:
    """Nearest(0.1) at T0 + 1 s: no sample within 0.1 s; one at T0 + 1.05 s arrives after
    0.5 s of the clock: True. At T0 + 3 s nothing comes: False at the timeout."""
    clock, buf = _buffer()
    got: list[bool] = []

    async def ask(time: Time) -> None:
        got.append(await buf.can_transform_async("odom", "base", time, 2.0, policy=Nearest(0.1)))

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(ask, at(1.0))
            await clock.advance(0.5)
            assert not got and buf.pending_waits == 1
            buf.set_transform(tf("odom", "base", at(1.05), 3.0))
        assert got == [True]
        async with anyio.create_task_group() as tg:
            tg.start_soon(ask, at(3.0))
            await clock.advance(1.9)
            assert got == [True]
            await clock.advance(0.2)
    assert got == [True, False]
    assert await buf.can_transform_async("odom", "base", at(0.5), 0.0, policy=Clamp(1.0))


@pytest.mark.anyio
async def test_lookup_transform_full_async_under_a_policy_reports_both_legs() -> None:
    _, buf = _buffer()
    found = await buf.lookup_transform_full_async(
        "base", at(0.5), "base", at(-1.0), "map", 1.0, policy=Clamp(1.0)
    )
    assert isinstance(found, PolicyResult)
    ts, report = found
    assert ts.transform.translation.x == pytest.approx(-1.0)  # base moved +1 m (x 1 -> 2)
    assert report.frames == ("base", "odom", "odom", "base")
    assert report.stamps_ns == (at(-1.0).ns, at(-1.0).ns, at(0.5).ns, T0.ns)
    assert report.max_abs_delta_ns == NS // 2
    exact = await buf.lookup_transform_full_async("base", T0, "base", at(-1.0), "map", 1.0)
    assert isinstance(exact, TransformStamped)
    assert exact.transform.translation.x == pytest.approx(-1.0)


@pytest.mark.anyio
async def test_lookup_transform_full_async_waits_for_a_leg_under_the_policy() -> None:
    clock, buf = _buffer()
    got: list[PolicyResult] = []

    async def ask() -> None:
        got.append(
            await buf.lookup_transform_full_async(
                "base", at(2.0), "base", T0, "map", 5.0, policy=Nearest(0.1)
            )
        )

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await clock.advance(1.0)
            assert not got and buf.pending_waits == 1
            buf.set_transform(tf("odom", "base", at(2.05), 4.0))
    ts, report = got[0]
    assert ts.transform.translation.x == -2.0  # x 2 at T0, x 4 at the sample near T0 + 2 s
    assert report.frames == ("base", "odom", "odom", "base")  # static links at the time
    assert report.stamps_ns == (T0.ns, T0.ns, at(2.0).ns, at(2.05).ns)
    assert report.max_abs_delta_ns == 50_000_000


@pytest.mark.anyio
async def test_a_full_window_wait_is_bounded_by_future_wait() -> None:
    clock, buf = _buffer()
    errors: list[BaseException] = []

    async def ask() -> None:
        try:
            await buf.lookup_transform_full_async(
                "base", at(3.0), "base", T0, "map", 30.0, policy=Window(0.5, 2.0)
            )
        except TimeoutException as exc:
            errors.append(exc)

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await clock.advance(1.9)
            assert not errors
            await clock.advance(0.2)
    assert len(errors) == 1 and "Timed out after 2 s" in str(errors[0])
    with pytest.raises(ForwardExtrapolationException):
        await buf.lookup_transform_full_async(
            "base", at(3.0), "base", T0, "map", 30.0, policy=Window(0.5, 0.0)
        )


@pytest.mark.anyio
async def test_transform_under_a_policy_returns_the_report() -> None:
    _, buf = _buffer()
    p = PointStamped(Header(at(0.75), "base"), Point(1.0, 0.0, 0.0))
    moved, report = await buf.transform(p, "map", 1.0, policy=Clamp(1.0))
    assert moved.header.frame_id == "map" and moved.header.stamp == at(0.75)
    assert moved.point == Point(13.0, 0.0, 0.0)  # base x 2 (held), odom x 10
    assert report.stamps_ns == (T0.ns, at(0.75).ns)
    assert report.max_abs_delta_ns == 750_000_000
    exact = await buf.transform(PointStamped(Header(T0, "base"), Point()), "map", 1.0)
    assert exact.point == Point(12.0, 0.0, 0.0)
    with pytest.raises(TimeoutException, match=r"extrapolation 0\.750000000s into the future"):
        await buf.transform(p, "map", 0.0, policy=Nearest(0.5))


@pytest.mark.anyio
async def test_transform_full_under_a_policy_returns_the_report() -> None:
    _, buf = _buffer()
    p = PointStamped(Header(at(-1.0), "base"), Point(0.0, 0.0, 0.0))
    moved, report = await buf.transform_full(p, "base", at(0.5), "map", 1.0, policy=Previous())
    assert moved.header.frame_id == "base" and moved.header.stamp == at(0.5)
    assert moved.point == Point(-1.0, 0.0, 0.0)
    assert report.stamps_ns == (at(-1.0).ns, at(-1.0).ns, at(0.5).ns, T0.ns)
    assert report.max_abs_delta_ns == NS // 2


async def _points(*seconds: float) -> AsyncIterator[PointStamped]:
    for sec in seconds:
        yield PointStamped(Header(at(sec), "base"), Point(sec, 0.0, 0.0))


@pytest.mark.anyio
async def test_message_filter_passes_what_the_policy_can_answer() -> None:
    """Data up to T0. Clamp(1.0): messages at T0 + 0.5 s pass at once (held edge sample),
    at T0 + 1.5 s wait until data within 1 s of them arrives; tf2's rule (no policy)
    holds both."""
    clock, buf = _buffer()
    dropped: list[tuple[float, FilterFailureReason]] = []

    def on_failure(msg: PointStamped, reason: FilterFailureReason) -> None:
        dropped.append((msg.point.x, reason))

    passed: list[float] = []
    with anyio.fail_after(10):
        async with MessageFilter(buf, "map", _points(0.5, 1.5), policy=Clamp(1.0)) as mf:
            await clock.advance(0)
            assert mf.statistics().queued == 1
            passed.append((await mf.__anext__()).point.x)
            buf.set_transform(tf("odom", "base", at(0.6), 3.0))  # 1.5 - 0.6 <= 1 s
            passed.extend([m.point.x async for m in mf])
        assert passed == [0.5, 1.5]
        async with MessageFilter(buf, "map", _points(1.7, 1.8)) as exact:
            await clock.advance(0)
            assert exact.statistics().queued == 2
        # A Window's wait ends at future_wait: the message is dropped, not held forever.
        async with MessageFilter(
            buf, "map", _points(5.0), policy=Window(0.5, 1.0), on_failure=on_failure
        ) as mf:
            await clock.advance(0)
            assert mf.statistics().queued == 1
            await clock.advance(1.5)
            assert [m async for m in mf] == []
    assert dropped == [(5.0, FilterFailureReason.TRANSFORM_FAILURE)]
    with pytest.raises(TypeError, match="policy must be Exact"):
        MessageFilter(buf, "map", _points(), policy=0.5)  # type: ignore[arg-type]
