"""Waits that fail fast (``fail_fast=True``): a wait gives up at once when its answer can
never come — a link of the path can no longer accept data at the time asked (older than
its newest stamp minus cache_time: tf2 ``TimeCache::insertData`` refuses it as
TF_OLD_DATA), or the two frames are known and in different trees — instead of waiting for
its whole timeout, which stays the default (tf2_ros's behaviour). On asyncio and trio,
driven by ManualClock; the rule checked against a brute-force oracle (hypothesis): insert
a sample at the time asked on every link and see whether the lookup then succeeds."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable

import anyio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import (
    BackwardExtrapolationException,
    ConnectivityException,
    Header,
    PointStamped,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.filters import FilterFailureReason, MessageFilter
from tfbus.messages import Point

S = 1_000_000_000


def tf(parent: str, child: str, sec: float, x: float = 0.0) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_sec(sec), parent),
        child,
        Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)),
    )


async def settle() -> None:
    """Let every task run until blocked."""
    await ManualClock().advance(0)


def stale_parent_buffer() -> Buffer:
    """map -> odom last at 100 s (stale); odom -> base at 111, 115, 120 s; cache 10 s.
    base at 105 s: the path's latest common time is 100 s, so tf2's transformable-request
    test (105 < 100 - 10?) keeps waiting, but base's link holds nothing before 110 s and
    refuses anything older (120 - 10): it can never answer 105 s."""
    buf = Buffer(cache_time=10.0, clock=ManualClock(Time.from_sec(120)))
    buf.set_transform(tf("map", "odom", 100.0))
    for sec in (111.0, 115.0, 120.0):
        buf.set_transform(tf("odom", "base", sec, x=sec))
    return buf


PAST_105 = (
    "Lookup would require extrapolation 6.000000000s into the past.  Requested time "
    "105.000000000 but the earliest data is at time 111.000000000, when looking up "
    "transform from frame [base] to frame [map]"
)


@pytest.mark.anyio
async def test_a_time_the_failing_link_can_no_longer_accept_fails_at_once() -> None:
    buf = stale_parent_buffer()
    with pytest.raises(BackwardExtrapolationException) as err:
        await buf.wait_for_transform("map", "base", Time.from_sec(105), timeout=5.0,
                                     fail_fast=True)
    assert str(err.value) == PAST_105
    assert buf.pending_waits == 0
    assert buf.clock.now() == Time.from_sec(120)  # no time passed: it did not wait


@pytest.mark.anyio
async def test_without_fail_fast_the_same_wait_takes_its_whole_timeout() -> None:
    buf = stale_parent_buffer()
    clock = buf.clock
    assert isinstance(clock, ManualClock)
    hopeless = buf.check_transform("map", "base", Time.from_sec(105), fail_fast=True)
    assert isinstance(hopeless, BackwardExtrapolationException)
    assert buf.check_transform("map", "base", Time.from_sec(105)) is None  # tf2_ros: wait
    outcome: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.wait_for_transform("map", "base", Time.from_sec(105), timeout=5.0)
        except TransformException as e:
            outcome.append(e)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert not outcome and buf.pending_waits == 1
        await clock.advance(5.0)
    assert isinstance(outcome[0], TimeoutException)


@pytest.mark.anyio
async def test_a_link_further_up_the_path_that_can_no_longer_answer_fails_the_wait() -> None:
    # map -> odom at 195 and 200 s (cache 10 s: nothing before 190 s is ever accepted);
    # odom -> base one sample at 150 s. The walk fails on base's link (data at 185 s may
    # still come for it), but odom's link can never answer 185 s.
    buf = Buffer(cache_time=10.0, clock=ManualClock(Time.from_sec(200)))
    buf.set_transform(tf("map", "odom", 195.0))
    buf.set_transform(tf("map", "odom", 200.0))
    buf.set_transform(tf("odom", "base", 150.0))
    assert buf.check_transform("map", "base", Time.from_sec(185)) is None
    with pytest.raises(BackwardExtrapolationException) as err:
        await buf.lookup_transform_async("map", "base", Time.from_sec(185), timeout=1.0,
                                         fail_fast=True)
    assert str(err.value) == (
        "Lookup would require extrapolation 10.000000000s into the past.  Requested time "
        "185.000000000 but the earliest data is at time 195.000000000, when looking up "
        "transform from frame [base] to frame [map]"
    )


@pytest.mark.anyio
async def test_one_later_sample_is_reported_as_backward_with_tf2s_message() -> None:
    # One sample at 120 s: rolling calls a lookup at 105 s NoDataForExtrapolation, but
    # nothing before 110 s can ever be stored: the wait fails as backward extrapolation.
    buf = Buffer(cache_time=10.0, clock=ManualClock(Time.from_sec(120)))
    buf.set_transform(tf("map", "odom", 100.0))
    buf.set_transform(tf("odom", "base", 120.0))
    with pytest.raises(BackwardExtrapolationException) as err:
        await buf.wait_for_transform("map", "base", Time.from_sec(105), timeout=1.0,
                                     fail_fast=True)
    assert str(err.value) == (
        "Lookup would require extrapolation at time 105.000000000, but only time "
        "120.000000000 is in the buffer, when looking up transform from frame [base] to "
        "frame [map]"
    )


@pytest.mark.anyio
async def test_frames_known_in_two_trees_fail_at_once_only_with_fail_fast() -> None:
    clock = ManualClock(Time.from_sec(10))
    buf = Buffer(clock=clock)
    buf.set_transform(tf("map", "odom", 10.0))
    buf.set_transform(tf("a", "b", 10.0))
    with pytest.raises(ConnectivityException) as err:
        await buf.wait_for_transform("map", "b", Time.from_sec(10), timeout=3.0,
                                     fail_fast=True)
    assert str(err.value) == (
        "Could not find a connection between 'map' and 'b' because they are not part of "
        "the same tree.Tf has two or more unconnected trees."
    )
    assert await buf.can_transform_async("map", "b", Time.from_sec(10), 3.0,
                                         fail_fast=True) is False
    assert clock.now() == Time.from_sec(10)
    # The default waits: the trees may still be joined, and here they are.
    got: list[TransformStamped] = []

    async def waiter() -> None:
        got.append(await buf.wait_for_transform("map", "b", Time.from_sec(10), 3.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert buf.pending_waits == 1
        buf.set_transform(tf("odom", "a", 10.0, x=2.0))
    assert got[0].transform.translation.x == 2.0


@pytest.mark.anyio
async def test_fail_fast_still_waits_for_what_can_come() -> None:
    # An unknown frame, a time after the newest data, a time the link still accepts:
    # each may arrive, so each waits and is answered by the insert that brings it.
    clock = ManualClock(Time.from_sec(120))
    buf = stale_parent_buffer()
    buf.clock = clock
    got: dict[str, TransformStamped] = {}

    async def wait(name: str, target: str, source: str, sec: float) -> None:
        got[name] = await buf.wait_for_transform(target, source, Time.from_sec(sec), 5.0,
                                                 fail_fast=True)

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait, "unknown", "base", "laser", 0.0)
        tg.start_soon(wait, "future", "odom", "base", 125.0)
        tg.start_soon(wait, "accepted", "odom", "base", 110.0)
        await settle()
        assert buf.pending_waits == 3 and not got
        buf.set_transform(tf("base", "laser", 100.0, x=0.5))
        buf.set_transform(tf("odom", "base", 110.0, x=110.0))
        buf.set_transform(tf("odom", "base", 130.0, x=130.0))
    assert got["unknown"].transform.translation.x == 0.5
    assert got["accepted"].transform.translation.x == 110.0
    assert got["future"].transform.translation.x == 125.0


@pytest.mark.anyio
async def test_a_pending_wait_fails_on_the_insert_that_makes_it_hopeless() -> None:
    clock = ManualClock(Time.from_sec(100))
    buf = Buffer(cache_time=10.0, clock=clock)
    buf.set_transform(tf("map", "odom", 100.0))
    buf.set_transform(tf("odom", "base", 100.0))
    outcome: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.wait_for_transform("map", "base", Time.from_sec(105), 60.0,
                                         fail_fast=True)
        except TransformException as e:
            outcome.append(e)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        buf.set_transform(tf("odom", "base", 115.0))  # 105 s is still accepted
        await settle()
        assert not outcome and buf.pending_waits == 1
        buf.set_transform(tf("odom", "base", 116.0))  # no longer: before 106 s
    assert isinstance(outcome[0], BackwardExtrapolationException)
    assert "Requested time 105.000000000 but the earliest data is at time 115.000000000" in (
        str(outcome[0])
    )
    assert clock.now() == Time.from_sec(100)


Call = Callable[[Buffer], Awaitable[object]]

CALLS: dict[str, Call] = {
    "lookup_transform_async": lambda b: b.lookup_transform_async(
        "map", "base", Time.from_sec(105), 5.0, fail_fast=True),
    "lookup_transform_full_async": lambda b: b.lookup_transform_full_async(
        "map", Time.from_sec(120), "base", Time.from_sec(105), "map", 5.0, fail_fast=True),
    "transform": lambda b: b.transform(
        PointStamped(Header(Time.from_sec(105), "base"), Point(1.0, 0.0, 0.0)), "map", 5.0,
        fail_fast=True),
    "transform_full": lambda b: b.transform_full(
        PointStamped(Header(Time.from_sec(105), "base"), Point(1.0, 0.0, 0.0)), "map",
        Time.from_sec(120), "map", 5.0, fail_fast=True),
    "lookup_transforms_async": lambda b: b.lookup_transforms_async(
        "map", "base", [100 * S, 105 * S], 5.0, fail_fast=True),
    "transform_points_async": lambda b: b.transform_points_async(
        [[1.0, 0.0, 0.0]], "map", "base", [105 * S], 5.0, fail_fast=True),
}


@pytest.mark.anyio
@pytest.mark.parametrize("name", sorted(CALLS))
async def test_every_awaited_lookup_takes_fail_fast(name: str) -> None:
    buf = stale_parent_buffer()
    with pytest.raises(BackwardExtrapolationException) as err:
        await CALLS[name](buf)
    assert str(err.value) == PAST_105
    assert buf.pending_waits == 0 and buf.clock.now() == Time.from_sec(120)


async def _stamped(*stamps: float) -> AsyncIterator[PointStamped]:
    for sec in stamps:
        yield PointStamped(Header(Time.from_sec(sec), "base"), Point(sec, 0.0, 0.0))


@pytest.mark.anyio
async def test_message_filter_drops_what_can_never_be_transformed_at_once() -> None:
    buf = stale_parent_buffer()
    buf.set_transform(tf("a", "b", 120.0))
    dropped: list[tuple[float, FilterFailureReason]] = []

    def on_failure(msg: PointStamped, reason: FilterFailureReason) -> None:
        dropped.append((msg.point.x, reason))

    async def run(fail_fast: bool, target: str) -> tuple[int, int]:
        mf = MessageFilter(buf, target, _stamped(105.0, 115.0), on_failure=on_failure,
                           fail_fast=fail_fast)
        async with mf:
            await settle()
            stats = mf.statistics()
            return stats.queued, stats.dropped_total

    # 105 s can never be answered (base's link holds 111..120 s, cache 10 s); 115 s
    # waits for map -> odom data at 115 s, which may still come.
    assert await run(True, "map") == (1, 1)
    assert dropped == [(105.0, FilterFailureReason.OUT_THE_BACK)]
    dropped.clear()
    assert await run(True, "a") == (0, 2)  # base and a: two trees
    assert dropped == [(105.0, FilterFailureReason.TRANSFORM_FAILURE),
                       (115.0, FilterFailureReason.TRANSFORM_FAILURE)]
    dropped.clear()
    assert await run(False, "map") == (2, 0)  # tf2_ros: both stay queued
    assert await run(False, "a") == (2, 0)
    assert not dropped


def test_check_transform_keeps_tf2s_answer_without_fail_fast() -> None:
    core = BufferCore(cache_time=10.0)
    core.set_transform(tf("map", "odom", 100.0))
    for sec in (111.0, 115.0, 120.0):
        core.set_transform(tf("odom", "base", sec))
    core.set_transform(tf("a", "b", 120.0))
    assert core.check_transform("map", "base", Time.from_sec(105)) is None
    assert core.check_transform("map", "b", Time.from_sec(105)) is None
    assert isinstance(core.check_transform("map", "b", Time.from_sec(105), fail_fast=True),
                      ConnectivityException)
    # Time(0) (the latest common time) is never hopeless for want of data: newer data
    # moves it.
    assert core.check_transform("map", "base", Time(0), fail_fast=True) is None


# ---------------------------------------------------------------------- brute force


@st.composite
def worlds(draw: st.DrawFn) -> tuple[int, list[int], list[list[int]], int, int, int]:
    """A random tree of up to 6 frames (parent of frame i is a frame < i, -1 = another
    tree's root), each link's stamps (s), the cache time (s), a query pair and time."""
    n = draw(st.integers(2, 6))
    parents = [draw(st.integers(-1, i - 1)) if i else -1 for i in range(n)]
    stamps = [draw(st.lists(st.integers(1, 40), max_size=4)) if parents[i] >= 0 else []
              for i in range(n)]
    cache = draw(st.integers(1, 15))
    a = draw(st.integers(0, n - 1))
    b = draw(st.integers(0, n - 1))
    t = draw(st.integers(1, 45))
    return cache, parents, stamps, a, b, t


def _name(i: int) -> str:
    return f"f{i}"


def _fill(cache: int, parents: list[int], stamps: list[list[int]]) -> BufferCore:
    core = BufferCore(cache_time=float(cache))
    for i, p in enumerate(parents):
        if p >= 0:
            for sec in stamps[i]:
                core.set_transform(tf(_name(p), _name(i), float(sec), x=float(i)))
    return core


@settings(max_examples=400, deadline=None)
@given(worlds())
def test_fail_fast_gives_up_exactly_when_no_insert_can_answer(
    world: tuple[int, list[int], list[list[int]], int, int, int],
) -> None:
    cache, parents, stamps, a, b, t = world
    core = _fill(cache, parents, stamps)
    target, source, when = _name(a), _name(b), Time.from_sec(t)
    if not (core.frame_exists(target) and core.frame_exists(source)):
        return
    now = core.check_transform(target, source, when, fail_fast=True)
    if isinstance(now, TransformStamped):
        return
    default = core.check_transform(target, source, when)
    assert default is None or type(default) is type(now)  # fail_fast only adds failures
    # The oracle: the best any future could do is a sample at t on every link.
    oracle = _fill(cache, parents, stamps)
    for i, p in enumerate(parents):
        if p >= 0 and oracle.frame_exists(_name(i)):
            oracle.set_transform(tf(_name(p), _name(i), float(t), x=float(i)))
    answer = oracle.check_transform(target, source, when)
    connected = core.frame_path(source, target) is not None
    if now is None:  # still waiting: data at t on every link must answer it
        assert connected and isinstance(answer, TransformStamped), (now, answer)
    elif isinstance(now, ConnectivityException):
        assert not connected
    else:  # given up: not even data at t on every link answers it
        assert isinstance(now, BackwardExtrapolationException | type(default))
        assert connected and not isinstance(answer, TransformStamped), (now, answer)
