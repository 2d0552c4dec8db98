"""MessageFilter (``tfbus.filters``) on scripted sequences, against tf2_ros's documented
behaviour (``tf2_ros/message_filter.h``): a message that arrives before its transform is
released the moment the transform arrives, in order; one older than the cache is dropped
as out-the-back at once; queue overflow drops the oldest; an empty frame id is dropped;
a queued message whose time falls out of the cache is dropped as a transform failure.
Time is driven by ManualClock; every test runs on asyncio and trio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import anyio
import numpy as np
import pytest

from tfbus import (
    Bus,
    Duration,
    ExtrapolationException,
    Header,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.core._select import CoreBase
from tfbus.filters import FilterFailureReason, MessageFilter

pytestmark = pytest.mark.anyio


@dataclass
class Msg:
    header: Header
    name: str = ""
    payload: list[int] = field(default_factory=list)


def at(sec: float) -> Time:
    return Time.from_ns(round(sec * 1e9))


def msg(name: str, sec: float, frame: str = "laser") -> Msg:
    return Msg(Header(at(sec), frame), name)


def odom(sec: float, x: float | None = None) -> TransformStamped:
    x = sec if x is None else x
    q = Quaternion(0.0, 0.0, math.sin(sec / 4), math.cos(sec / 4))
    return TransformStamped(Header(at(sec), "odom"), "base_link", Transform(Vector3(x, 0, 0), q))


def make_buffer(cache_time: float = 10.0) -> tuple[Buffer, ManualClock]:
    clock = ManualClock(Time(100))
    buf = Buffer(cache_time, clock=clock)
    buf.set_transform_static(
        TransformStamped(Header(Time(0), "base_link"), "laser", Transform(Vector3(0.2, 0, 0)))
    )
    return buf, clock


async def settle() -> None:
    await ManualClock().advance(0)


class Feed:
    """A scripted source: messages are sent with ``send``; ``close`` ends it."""

    def __init__(self) -> None:
        self.tx, self.rx = anyio.create_memory_object_stream[Msg](100)

    async def send(self, *msgs: Msg) -> None:
        for m in msgs:
            await self.tx.send(m)
        await settle()


async def _collect(mf: MessageFilter[Msg], out: list[str]) -> None:
    async for m in mf:
        out.append(m.name)


async def test_ready_messages_pass_at_once_and_waiting_ones_on_arrival_in_order() -> None:
    buf, _ = make_buffer()
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    feed = Feed()
    out: list[str] = []
    async with MessageFilter(buf, "odom", feed.rx) as mf, anyio.create_task_group() as tg:
        tg.start_soon(_collect, mf, out)
        await feed.send(msg("now", 1.5))
        assert out == ["now"]
        await feed.send(msg("a", 2.5), msg("b", 2.7), msg("c", 3.5))
        assert out == ["now"] and mf.statistics().queued == 3 and buf.pending_waits == 3
        buf.set_transform(odom(2.6))  # covers a only
        await settle()
        assert out == ["now", "a"]
        buf.set_transform(odom(4.0))  # covers b and c: released together, in order
        await settle()
        assert out == ["now", "a", "b", "c"]
        stats = mf.statistics()
        assert (stats.incoming, stats.passed, stats.queued, stats.dropped_total) == (4, 4, 0, 0)
        assert buf.pending_waits == 0
        feed.tx.close()
    assert out == ["now", "a", "b", "c"]


async def test_out_the_back_empty_frame_and_queue_full_are_counted_and_reported() -> None:
    buf, _ = make_buffer(cache_time=10.0)
    buf.set_transform(odom(5.0))
    buf.set_transform(odom(20.0))
    feed = Feed()
    failures: list[tuple[str, FilterFailureReason]] = []
    out: list[str] = []
    async with MessageFilter(
        buf, ["odom", "base_link"], feed.rx, queue_size=2,
        on_failure=lambda m, r: failures.append((m.name, r)),
    ) as mf, anyio.create_task_group() as tg:  # fmt: skip
        tg.start_soon(_collect, mf, out)
        await feed.send(msg("old", 9.9))  # 9.9 + 10 < 20: can never be answered
        assert failures == [("old", FilterFailureReason.OUT_THE_BACK)]
        await feed.send(msg("noframe", 21.0, frame=""))
        assert failures[-1] == ("noframe", FilterFailureReason.EMPTY_FRAME_ID)
        await feed.send(msg("q1", 21.0), msg("q2", 22.0), msg("q3", 23.0))
        assert failures[-1] == ("q1", FilterFailureReason.QUEUE_FULL)
        assert mf.statistics().queued == 2 and buf.pending_waits == 2
        buf.set_transform(odom(30.0))
        await settle()
        assert out == ["q2", "q3"]
        s = mf.statistics()
        assert s.dropped == {
            FilterFailureReason.EMPTY_FRAME_ID: 1,
            FilterFailureReason.OUT_THE_BACK: 1,
            FilterFailureReason.TRANSFORM_FAILURE: 0,
            FilterFailureReason.QUEUE_FULL: 1,
            FilterFailureReason.MALFORMED: 0,
        }
        assert s.incoming == s.passed + s.dropped_total + s.queued + s.ready == 5
        tg.cancel_scope.cancel()


async def test_a_queued_message_that_falls_out_of_the_cache_is_a_transform_failure() -> None:
    buf, _ = make_buffer(cache_time=10.0)
    buf.set_transform(odom(1.0))
    feed = Feed()
    failures: list[tuple[str, FilterFailureReason]] = []
    out: list[str] = []
    # A gap: data at 1.0 and then only from 20.0 on; the message at 5.0 stays unanswerable
    # (no data at 5 once 1.0 is pruned) and its time is out of the window.
    async with (
        MessageFilter(
            buf, "odom", feed.rx, on_failure=lambda m, r: failures.append((m.name, r))
        ) as mf,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(_collect, mf, out)
        await feed.send(msg("gap", 5.0))
        assert mf.statistics().queued == 1
        buf.set_transform(odom(20.0))
        await settle()
        assert failures == [("gap", FilterFailureReason.TRANSFORM_FAILURE)]
        assert out == [] and mf.statistics().queued == 0 and buf.pending_waits == 0
        tg.cancel_scope.cancel()


async def test_tolerance_waits_for_stamp_plus_tolerance() -> None:
    buf, _ = make_buffer()
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    feed = Feed()
    out: list[str] = []
    tol = Duration.from_sec(0.5)
    async with MessageFilter(buf, "odom", feed.rx, tolerance=tol) as mf, \
            anyio.create_task_group() as tg:  # fmt: skip
        tg.start_soon(_collect, mf, out)
        await feed.send(msg("scan", 1.8))  # 1.8 is there, 2.3 is not
        assert out == []
        buf.set_transform(odom(2.2))
        await settle()
        assert out == []
        buf.set_transform(odom(2.4))
        await settle()
        assert out == ["scan"]
        tg.cancel_scope.cancel()


async def test_target_frames_can_change_while_running() -> None:
    buf, _ = make_buffer()
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    feed = Feed()
    out: list[str] = []
    async with MessageFilter(buf, "map", feed.rx) as mf, anyio.create_task_group() as tg:
        tg.start_soon(_collect, mf, out)
        await feed.send(msg("m", 1.5))
        assert out == [] and mf.statistics().queued == 1  # "map" is not known yet
        mf.set_target_frames(["odom", "base_link"])
        await settle()
        assert out == ["m"] and mf.target_frames == ("odom", "base_link")
        with pytest.raises(ValueError, match="non-empty"):
            mf.set_target_frames([""])
        tg.cancel_scope.cancel()


async def test_source_end_ends_iteration_and_a_bus_subscription_is_a_source() -> None:
    buf, _ = make_buffer()
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    async with Bus() as bus:
        sub = bus.subscribe("/scan", queue_size=10)
        got: list[str] = []
        async with MessageFilter(buf, "odom", sub) as mf, anyio.create_task_group() as tg:
            tg.start_soon(_collect, mf, got)
            await bus.publish("/scan", msg("s1", 1.2))
            await bus.publish("/scan", msg("s2", 2.5))
            await settle()
            assert got == ["s1"]
            buf.set_transform(odom(3.0))
            await settle()
            assert got == ["s1", "s2"]
            tg.cancel_scope.cancel()
    feed = Feed()
    out: list[str] = []
    async with MessageFilter(buf, "odom", feed.rx) as mf:
        await feed.send(msg("x", 1.1), msg("y", 1.2))
        feed.tx.close()
        await _collect(mf, out)
    assert out == ["x", "y"]


async def test_bad_arguments() -> None:
    buf, _ = make_buffer()
    feed = Feed()
    with pytest.raises(ValueError, match="queue_size"):
        MessageFilter(buf, "odom", feed.rx, queue_size=-1)
    with pytest.raises(ValueError, match="at least one"):
        MessageFilter(buf, [], feed.rx)
    with pytest.raises(ValueError, match="tolerance"):
        MessageFilter(buf, "odom", feed.rx, tolerance=Duration.from_sec(-1.0))


# --------------------------------------------------------------------------- batch twins


async def test_lookup_transforms_async_waits_for_the_latest_time() -> None:
    buf, clock = make_buffer()
    buf.set_transform(odom(1.0))
    times = np.array([at(1.0).ns, at(1.5).ns, at(2.5).ns])
    got = []

    async def look() -> None:
        got.append(await buf.lookup_transforms_async("odom", "laser", times))

    async with anyio.create_task_group() as tg:
        tg.start_soon(look)
        await settle()
        buf.set_transform(odom(2.0))
        await settle()
        assert not got
        buf.set_transform(odom(3.0))
        await settle()
        assert len(got) == 1
    ref = buf.lookup_transforms("odom", "laser", times)
    assert got[0].translations.tolist() == ref.translations.tolist()
    pts = await buf.transform_points_async(np.ones((3, 3)), "odom", "laser", times)
    np.testing.assert_allclose(pts, buf.transform_points(np.ones((3, 3)), "odom", "laser", times))

    async def late() -> None:
        with pytest.raises(TimeoutException):
            await buf.lookup_transforms_async("odom", "laser", [at(9.0).ns], timeout=1.0)

    async with anyio.create_task_group() as tg:
        tg.start_soon(late)
        await settle()
        await clock.advance(2.0)
    buf.set_transform(odom(30.0))
    with pytest.raises(ExtrapolationException):
        await buf.lookup_transforms_async("odom", "laser", [at(1.0).ns, at(3.0).ns])


async def test_buffer_has_the_awaitable_batched_lookups() -> None:
    assert Buffer.__mro__[1:3] == (BufferCore, CoreBase)  # one class, no mixins
    clock = ManualClock(Time(100))
    buf = Buffer(clock=clock)
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    times = [at(1.2).ns, at(1.8).ns]
    got = await buf.lookup_transforms_async("odom", "base_link", times, timeout=1.0)
    assert got.translations.tolist() == buf.lookup_transforms(
        "odom", "base_link", times
    ).translations.tolist()
    pts = await buf.transform_points_async(np.zeros((2, 3)), "odom", "base_link", times)
    assert pts[:, 0].tolist() == got.translations[:, 0].tolist()


# --------------------------------------------------------------------------- malformed messages


async def test_malformed_messages_are_dropped_and_counted() -> None:
    """One bad message (frame id None, an int stamp, no header, stamp + tolerance past
    int64) ended the whole filter with its exception; each is now dropped and counted
    as MALFORMED, reported to on_failure, and the good messages around it pass."""
    buf, _ = make_buffer()
    buf.set_transform(odom(1.0))
    buf.set_transform(odom(2.0))
    feed = anyio.create_memory_object_stream[object](100)
    failures: list[tuple[object, FilterFailureReason]] = []
    out: list[str] = []
    bad: list[object] = [
        Msg(Header(at(1.5), None)),  # type: ignore[arg-type]
        Msg(Header(5, "laser")),  # type: ignore[arg-type]
        Msg(Header(at(1.5), 7)),  # type: ignore[arg-type]
        "no header",
        None,
        Msg(Header(Time.from_ns(2**63 - 1), "laser")),
    ]
    async with MessageFilter(buf, "odom", feed[1], tolerance=Duration(0, 1000),
                             on_failure=lambda m, r: failures.append((m, r))) as mf, \
            anyio.create_task_group() as tg:
        tg.start_soon(_collect, mf, out)  # type: ignore[arg-type]
        await feed[0].send(msg("before", 1.5))
        for b in bad:
            await feed[0].send(b)
        await feed[0].send(msg("after", 1.6))
        await settle()
        assert out == ["before", "after"]
        stats = mf.statistics()
        assert stats.dropped[FilterFailureReason.MALFORMED] == len(bad)
        assert (stats.incoming, stats.passed, stats.dropped_total) == (2 + len(bad), 2,
                                                                       len(bad))
        assert failures == [(b, FilterFailureReason.MALFORMED) for b in bad]
        feed[0].close()
    assert out == ["before", "after"]
