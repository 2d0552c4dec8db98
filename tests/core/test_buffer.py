"""Awaitable Buffer: event-driven waits, timeouts on the buffer's clock, cancellation,
clock jumps; on asyncio and trio (anyio's pytest plugin), driven by ManualClock."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import pytest

import tfbus.buffer
import tfbus.core
from tfbus import (
    ExtrapolationException,
    Header,
    InvalidArgumentException,
    LookupException,
    Point,
    PointStamped,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)
from tfbus.buffer import Buffer, _Waiter
from tfbus.clock import ManualClock, SystemClock
from tfbus.core import MAX_GRAPH_DEPTH, SetResult
from tfbus.time import Duration

pytestmark = pytest.mark.anyio


T0 = Time(1000)


async def settle() -> None:
    """Let every task run until blocked (ManualClock.advance(0) does exactly that)."""
    await ManualClock().advance(0)


def tf(parent: str, child: str, stamp: Time, x: float = 0.0, yaw: float = 0.0) -> TransformStamped:
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return TransformStamped(Header(stamp, parent), child, Transform(Vector3(x, 0.0, 0.0), q))


async def test_wait_before_any_data_returns_when_data_arrives() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    result: list[TransformStamped] = []

    async def waiter() -> None:
        result.append(await buf.lookup_transform_async("base_link", "base_laser", Time(0)))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert not result and buf.pending_waits == 1
        buf.set_transform(tf("odom", "base_link", T0, x=5.0))  # unrelated to the path
        await settle()
        assert not result
        buf.set_transform(tf("base_link", "base_laser", T0, x=0.1))
    assert result[0].transform.translation.x == pytest.approx(0.1)
    assert result[0].header.stamp == T0
    assert buf.pending_waits == 0


class _CountedWaiter(_Waiter[object]):
    """A Buffer's wait that counts the reads of its ``exact`` (the recheck reads it once
    per walk of the wait's lookup, in the compiled core's C code as in Python)."""

    reads = 0

    @property  # type: ignore[override]
    def exact(self) -> tuple[str, str, Time, bool] | None:
        type(self).reads += 1
        return self._exact  # type: ignore[no-any-return]

    @exact.setter
    def exact(self, value: tuple[str, str, Time, bool] | None) -> None:
        self._exact = value


async def test_a_batch_insert_wakes_the_waits_it_completes_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    result: list[TransformStamped] = []
    monkeypatch.setattr(tfbus.buffer, "_Waiter", _CountedWaiter)

    async def waiter() -> None:
        result.append(await buf.lookup_transform_async("map", "laser", T0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert buf.pending_waits == 1
        _CountedWaiter.reads = 0
        report = buf.set_transforms(
            [
                tf("map", "odom", T0, x=1.0),
                tf("odom", "base", T0, x=2.0),
                tf("odom", "bad", T0, x=math.nan),  # reported, does not stop the batch
                tf("base", "laser", T0, x=0.5),
            ],
            "test",
        )
        assert (report.stored, report.refused, len(report.errors)) == (3, 0, 1)
    assert _CountedWaiter.reads == 1  # rechecked once, after the whole batch, not per transform
    assert result[0].transform.translation.x == pytest.approx(3.5)
    assert buf.pending_waits == 0


@pytest.mark.parametrize("insert", ["set_transform", "set_transform_static", "insert_transform"])
async def test_each_single_insert_wakes_the_waits_on_its_frames(insert: str) -> None:
    """The single inserts store through the core's one-transform path (no batch result);
    the Buffer still re-checks the waits on the two frames: here a wait whose path the
    insert completes by linking a new frame (the tree's shape changed)."""
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("map", "odom", T0, x=1.0))
    result: list[TransformStamped] = []

    async def waiter() -> None:
        result.append(await buf.lookup_transform_async("map", "base", T0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert buf.pending_waits == 1
        stored = getattr(buf, insert)(tf("odom", "base", T0, x=2.0), "test")
        assert stored in (True, SetResult.STORED)
        await settle()
        assert buf.pending_waits == 0 and result, "the insert did not wake the wait"
    assert result[0].transform.translation.x == pytest.approx(3.0)


async def test_future_time_resolves_with_interpolation_once_bracketed() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    buf.set_transform(tf("a", "b", Time(1000), x=0.0, yaw=0.0))
    target = Time(1000, 500_000_000)  # 1000.5 s: in the future of the data
    got: list[TransformStamped] = []

    async def waiter() -> None:
        got.append(await buf.lookup_transform_async("a", "b", target, timeout=5.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert not got
        buf.set_transform(tf("a", "b", Time(1001), x=2.0, yaw=math.pi / 2))
    ts = got[0]
    assert ts.header.stamp == target
    assert ts.transform.translation.x == pytest.approx(1.0)
    # halfway along the geodesic: yaw pi/4
    q = ts.transform.rotation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(math.pi / 4)


async def test_timeout_on_the_buffer_clock_names_what_is_missing() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    buf.set_transform(tf("a", "b", T0))
    errors: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.lookup_transform_async("a", "c", Time(0), timeout=2.0)
        except TimeoutException as exc:
            errors.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(1.999)
        assert not errors
        await clock.advance(0.001)
    assert len(errors) == 1
    message = str(errors[0])
    assert "Timed out after 2 s" in message
    assert "canTransform: source_frame c does not exist." in message
    assert buf.pending_waits == 0


async def test_cancel_scopes_work_and_leave_nothing_registered() -> None:
    buf = Buffer(clock=ManualClock(T0))
    for _ in range(10_000):
        with anyio.CancelScope() as scope:
            scope.cancel()
            await buf.wait_for_transform("map", "base_link", Time(0))
        assert scope.cancelled_caught
    assert buf.pending_waits == 0
    assert not buf._index

    # and cancellation of a wait that is really pending
    async with anyio.create_task_group() as tg:
        tg.start_soon(buf.wait_for_transform, "map", "base_link", Time(0))
        await settle()
        assert buf.pending_waits == 1
        tg.cancel_scope.cancel()
    assert buf.pending_waits == 0 and not buf._index


async def test_many_cancelled_pending_waits_leave_no_waiter() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    async with anyio.create_task_group() as tg:
        for i in range(2_000):
            tg.start_soon(buf.wait_for_transform, "map", f"f{i % 7}", Time(0), 100.0)
        await settle()
        assert buf.pending_waits == 2_000
        tg.cancel_scope.cancel()
    assert buf.pending_waits == 0 and not buf._index


async def test_wait_for_time_out_of_cache_window_fails_at_once() -> None:
    buf = Buffer(cache_time=10.0, clock=ManualClock(T0))
    buf.set_transform(tf("a", "b", Time(1000)))
    buf.set_transform(tf("a", "b", Time(1020)))
    with pytest.raises(ExtrapolationException, match="Lookup would require extrapolation"):
        await buf.wait_for_transform("a", "b", Time(1005))


async def test_invalid_ids_raise_at_once() -> None:
    buf = Buffer(clock=ManualClock(T0))
    with pytest.raises(InvalidArgumentException):
        await buf.wait_for_transform("/a", "b", Time(0))
    with pytest.raises(InvalidArgumentException):
        await buf.wait_for_transform("a", "", Time(0))


async def test_can_transform_async_is_a_bool() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    out: list[bool] = []

    async def ask() -> None:
        out.append(await buf.can_transform_async("a", "b", Time(0), timeout=1.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(ask)
        await clock.advance(1.0)
    assert out == [False]
    buf.set_transform(tf("a", "b", T0))
    assert await buf.can_transform_async("a", "b", Time(0), timeout=1.0)


async def test_transform_point_vector_and_the_tutorial_numbers() -> None:
    buf = Buffer(clock=ManualClock(T0))
    laser = TransformStamped(
        Header(T0, "base_link"), "base_laser", Transform(Vector3(0.1, 0.0, 0.2), Quaternion())
    )
    buf.set_transform(laser)
    p = PointStamped(Header(Time(0), "base_laser"), Point(1.0, 0.2, 0.0))
    out = await buf.transform(p, "base_link")
    assert out.header.frame_id == "base_link"
    assert out.header.stamp == T0
    assert tuple(out.point) == pytest.approx((1.1, 0.2, 0.2))
    v = await buf.transform(
        Vector3Stamped(Header(Time(0), "base_laser"), Vector3(1, 0, 0)), "base_link"
    )
    assert tuple(v.vector) == pytest.approx((1.0, 0.0, 0.0))  # rotation only
    with pytest.raises(TypeError):
        await buf.transform("not a message", "base_link")  # type: ignore[call-overload]


async def test_backward_clock_jump_clears_and_reevaluates_waits() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    buf.set_transform(tf("a", "b", Time(999)))
    buf.set_transform(tf("a", "b", Time(1000)))
    assert buf.can_transform("a", "b", Time(999, 500_000_000))
    results: list[TransformStamped] = []

    async def waiter() -> None:
        results.append(await buf.lookup_transform_async("a", "c", Time(0)))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        await clock.set(Time(500))  # jump back
        assert not buf.can_transform("a", "b", Time(999, 500_000_000))
        assert buf.pending_waits == 1  # still waiting, re-evaluated
        buf.set_transform(tf("a", "b", Time(500)))
        buf.set_transform(tf("b", "c", Time(500), x=1.0))
    assert results[0].header.stamp == Time(500)


async def test_full_lookup_waits_for_both_legs() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    got: list[TransformStamped] = []

    async def waiter() -> None:
        got.append(
            await buf.lookup_transform_full_async("b", Time(1005), "b", Time(1000), "a", 10.0)
        )

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        buf.set_transform(tf("a", "b", Time(1000), x=1.0))
        await settle()
        assert not got
        buf.set_transform(tf("a", "b", Time(1005), x=3.0))
    # b moved from x=1 to x=3 in the fixed frame a: a point fixed in a seen from b moved by -2
    assert got[0].transform.translation.x == pytest.approx(-2.0)


async def test_timeout_with_the_system_clock_uses_real_time() -> None:
    # A tiny real-time timeout (no sleep in the test: the wait itself times out).
    buf = Buffer()
    with pytest.raises(TimeoutException, match=r"Timed out after 0\.001 s waiting for"):
        await buf.lookup_transform_async("a", "b", Time(0), timeout=0.001)
    assert buf.pending_waits == 0


async def test_wait_across_a_loop_raises_lookup_exception_at_once() -> None:
    """wait_for_transform across a loop (a -> b -> a) raises
    LookupException at once, as its docstring says, instead of waiting."""
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("a", "b", T0))
    buf.set_transform(tf("b", "a", T0))
    buf.set_transform(tf("b", "d", T0))
    buf.set_transform(tf("x", "e", T0))
    outcomes: list[BaseException] = []

    async def waiter(time: Time) -> None:
        try:
            await buf.wait_for_transform("e", "d", time)
        except LookupException as exc:
            outcomes.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter, Time(0))
        tg.start_soon(waiter, T0)
        await settle()
        tg.cancel_scope.cancel()  # a wait still pending here is the bug
    assert len(outcomes) == 2
    assert all("contains a loop" in str(exc) for exc in outcomes)
    assert buf.pending_waits == 0


async def test_a_wait_loop_appearing_later_fails_the_wait() -> None:
    """A loop that forms while waiting fails the wait."""
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("a", "b", T0))
    outcomes: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.wait_for_transform("c", "b", Time(0))
        except LookupException as exc:
            outcomes.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert buf.pending_waits == 1
        buf.set_transform(tf("b", "a", T0))  # a <-> b: a loop above b
        buf.set_transform(tf("z", "c", T0))
        await settle()
        tg.cancel_scope.cancel()
    assert len(outcomes) == 1 and "loop" in str(outcomes[0])


async def test_waits_below_a_deep_chain_are_rechecked_without_rewalking_it() -> None:
    """With waits below a 10 000-deep chain, an insert that does not
    change the tree's shape rechecks each wait it touches with one query and does not
    recompute the frames they depend on (O(waiters touched), not O(depth x waiters));
    the frames a wait is indexed under are bounded by tf2's MAX_GRAPH_DEPTH."""
    buf = Buffer(clock=ManualClock(T0))
    depth = 10_000
    buf.set_transforms(tf(f"f{k}", f"f{k + 1}", T0) for k in range(depth))
    recomputed: list[str] = []
    chain_frames = buf.chain_frames

    def counting(target: str, source: str, time: Time = T0) -> list[str]:
        recomputed.append(source)
        frames = chain_frames(target, source, time)
        assert len(frames) <= MAX_GRAPH_DEPTH + 3
        return frames

    buf.chain_frames = counting  # type: ignore[method-assign]

    async with anyio.create_task_group() as tg:
        for i in range(20):
            tg.start_soon(buf.wait_for_transform, f"f{depth}", f"missing{i}", Time(0))
        await settle()
        assert buf.pending_waits == 20 and len(recomputed) == 20
        for k in range(1, 50):  # new samples on the leaf link every wait depends on
            buf.set_transform(tf(f"f{depth - 1}", f"f{depth}", Time(1000 + k)))
        assert len(recomputed) == 20  # rechecked, not re-indexed
        buf.set_transform(tf(f"f{depth}", "missing3", Time(1049)))  # a new link: re-index
        await settle()
        assert buf.pending_waits == 19
        tg.cancel_scope.cancel()


class _CountingClock(SystemClock):
    """A SystemClock that counts its ``call_later`` deadlines and their cancellations."""

    def __init__(self) -> None:
        super().__init__()
        self.scheduled = 0
        self.cancelled = 0

    def call_later(
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        cancel = super().call_later(seconds, callback)
        assert cancel is not None
        self.scheduled += 1

        def counted() -> None:
            self.cancelled += 1
            cancel()

        return counted


async def test_a_timed_wait_is_woken_by_a_clock_callback_and_cancels_it() -> None:
    """A ``timeout=`` is the clock's ``call_later`` deadline (no cancel scope
    per wait); a wait answered by the data cancels it, whatever ended the wait."""
    clock = _CountingClock()
    buf = Buffer(clock=clock)
    got: list[TransformStamped] = []
    async with anyio.create_task_group() as tg:

        async def waiter() -> None:
            got.append(await buf.lookup_transform_async("a", "b", Time(0), timeout=10.0))

        tg.start_soon(waiter)
        await anyio.wait_all_tasks_blocked()
        assert (clock.scheduled, clock.cancelled, buf.pending_waits) == (1, 0, 1)
        buf.set_transform(tf("a", "b", T0, x=1.0))
    assert got[0].transform.translation.x == 1.0
    assert (clock.scheduled, clock.cancelled, buf.pending_waits) == (1, 1, 0)
    with pytest.raises(TimeoutException):  # the deadline itself, in real time
        await buf.lookup_transform_async("a", "c", Time(0), timeout=0.001)
    with anyio.CancelScope() as scope:  # and a cancelled wait cancels it too
        scope.cancel()
        await buf.lookup_transform_async("a", "c", Time(0), timeout=10.0)
    assert (clock.scheduled, clock.cancelled, buf.pending_waits) == (3, 3, 0)


async def test_timed_waits_on_a_manual_clock_leave_no_deadline_behind() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    async with anyio.create_task_group() as tg:
        for _ in range(100):
            tg.start_soon(buf.lookup_transform_async, "a", "b", Time(0), 5.0)
        await clock.advance(0)
        assert clock.pending == 100 and buf.pending_waits == 100
        buf.set_transform(tf("a", "b", T0, x=1.0))
    assert clock.pending == 0 and buf.pending_waits == 0 and not buf._index


class _NoCallbackClock(ManualClock):
    """A clock that cannot schedule callbacks (``call_later`` gives None), as a
    third-party Clock may: Buffer then times out through its ``move_on_after``."""

    def call_later(  # type: ignore[override]
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        return None


async def test_a_clock_without_callbacks_times_out_through_its_cancel_scope() -> None:
    clock = _NoCallbackClock(T0)
    buf = Buffer(clock=clock)
    outcome: list[object] = []

    async def waiter(child: str) -> None:
        try:
            outcome.append(await buf.lookup_transform_async("a", child, Time(0), timeout=2.0))
        except TimeoutException as exc:
            outcome.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter, "b")
        tg.start_soon(waiter, "c")
        await clock.advance(1.0)
        buf.set_transform(tf("a", "b", T0, x=1.0))
        await clock.advance(1.0)
    assert isinstance(outcome[0], TransformStamped)
    assert isinstance(outcome[1], TimeoutException)
    assert clock.pending == 0 and buf.pending_waits == 0


@pytest.mark.parametrize("clock", [ManualClock(T0), SystemClock()], ids=["manual", "system"])
async def test_a_zero_timeout_wait_is_still_a_checkpoint(clock: ManualClock | SystemClock) -> None:
    """``timeout=0`` expires at once (the deadline callback runs before the wait), but
    the wait still yields: a cancelled scope cancels it, and a ``timeout=0`` polling loop
    lets other tasks run."""
    buf = Buffer(clock=clock)
    with anyio.CancelScope() as scope:
        scope.cancel()
        await buf.lookup_transform_async("a", "b", Time(0), timeout=0)
    assert scope.cancelled_caught
    ran = 0

    async def other() -> None:
        nonlocal ran
        ran += 1

    async with anyio.create_task_group() as tg:
        tg.start_soon(other)
        for _ in range(3):
            assert not await buf.can_transform_async("a", "b", Time(0), timeout=0.0)
        assert ran == 1
    assert buf.pending_waits == 0


@pytest.mark.parametrize("insert", ["set_transform", "set_transform_static", "set_transforms"])
async def test_an_insert_settles_a_wait_with_no_python_frame_of_the_buffer(insert: str) -> None:
    """The core's own set_transform(_static) and set_transforms settle the wait they
    answer (result, index, wake-up) before they return, a batch once per batch: Buffer
    and BufferCore add no Python frame of their own (they added ``Buffer.set_transform``,
    ``Buffer.set_transforms`` and ``BufferCore.set_transforms`` before the core settled
    waits itself). Not counted: frames of the pure-Python core (its own module and the
    TouchedFrames it builds) and trio's wake-up itself (``Wakeup.wake``, which reschedules
    the parked task; asyncio's is a future's ``set_result``)."""

    tfbus_dir = str(Path(tfbus.__file__).parent)
    twin = (str(Path(tfbus_dir, "core", "_py")), str(Path(tfbus_dir, "core", "results.py")))
    wakeup = str(Path(tfbus.__file__).parent / "_aio.py")
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("map", "odom", T0, x=1.0))
    result: list[TransformStamped] = []

    async def waiter() -> None:
        result.append(await buf.lookup_transform_async("map", "base", T0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await settle()
        assert buf.pending_waits == 1
        entered: list[str] = []

        def profile(frame: Any, event: str, arg: Any) -> None:
            name = frame.f_code.co_filename
            if (
                event == "call"
                and name.startswith(tfbus_dir)
                and (tfbus.core.COMPILED or not name.startswith(twin))
                and name != wakeup
            ):
                entered.append(frame.f_code.co_qualname)

        batch = [tf("odom", "base", T0, x=2.0), tf("base", "laser", T0, x=0.5)]
        sys.setprofile(profile)
        try:
            if insert == "set_transforms":
                answer: Any = buf.set_transforms(batch)
            else:
                answer = getattr(buf, insert)(batch[0])
        finally:
            sys.setprofile(None)
        assert entered == []
        if insert == "set_transforms":
            assert (answer.stored, set(answer.touched)) == (2, {"odom", "base", "laser"})
        else:
            assert answer
        assert buf.pending_waits == 0  # settled inside the insert, before any task ran
        assert not result
    assert result == [buf.lookup_transform("map", "base", T0)]
    assert result[0].transform.translation.x == pytest.approx(3.0)


async def test_a_wait_without_deadline_resumes_in_lookup_transform_async_alone() -> None:
    """An awaited exact lookup that has to wait, with no deadline: the Python frames of
    ``tfbus/buffer.py`` entered while it sets up its wait and while it resumes. The wait
    is set up with no callables built for it and resumes through
    ``lookup_transform_async`` alone (no ``Buffer._wait`` coroutine between it and the
    future the insert completes; a generator's resumption is a "call" to the profiler),
    returning the transform the insert's recheck found."""
    buffer_py = tfbus.buffer.__file__
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("map", "odom", T0, x=1.0))
    result: list[TransformStamped] = []
    entered: list[str] = []

    def profile(frame: Any, event: str, arg: Any) -> None:
        if event == "call" and frame.f_code.co_filename == buffer_py:
            code = frame.f_code  # co_qualname from Python 3.11; on 3.10, self's class
            qualname = getattr(code, "co_qualname", None)
            if qualname is None:
                qualname = f"{type(frame.f_locals['self']).__name__}.{code.co_name}"
            entered.append(qualname)

    async def waiter() -> None:
        result.append(await buf.lookup_transform_async("map", "base", T0))

    async with anyio.create_task_group() as tg:
        sys.setprofile(profile)
        try:
            tg.start_soon(waiter)
            await settle()
        finally:
            sys.setprofile(None)
        assert buf.pending_waits == 1
        assert entered == [
            "Buffer.lookup_transform_async",
            "_Waiter.__init__",
            "Buffer._frames_of",
            "Buffer._reindex",
            "Buffer._unindex",
        ]
        entered.clear()
        buf.set_transform(tf("odom", "base", T0, x=2.0))
        sys.setprofile(profile)
        try:
            await settle()
        finally:
            sys.setprofile(None)
        assert entered == ["Buffer.lookup_transform_async"]
    assert result == [buf.lookup_transform("map", "base", T0)]
    assert result[0].transform.translation.x == pytest.approx(3.0)


async def test_an_insert_leaves_the_index_edits_of_the_wait_it_settles_to_the_next_wait() -> None:
    """The insert that answers a wait wakes it without editing the buffer's index (off
    the path between the insert and the task's resume); the next wait set up, or
    ``pending_waits``, removes it. Memory stays bounded: 1 000 waits in a row leave at
    most one settled wait listed and nothing else indexed."""
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("map", "odom", T0, x=1.0))
    stamps = [Time.from_ns(T0.ns + k * 1000) for k in range(1, 1001)]
    results: list[TransformStamped] = []

    async def waiter() -> None:
        for stamp in stamps:
            results.append(await buf.lookup_transform_async("map", "odom", stamp))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        for k, stamp in enumerate(stamps, 1):
            await settle()
            assert buf.pending_waits == 1
            buf.set_transform(tf("map", "odom", stamp, x=float(k)))
            # Woken and settled, still indexed until the next wait or pending_waits.
            assert len(buf._settled) == 1
            assert set(buf._index) == {"map", "odom"}
            assert len(results) == k - 1
    assert [r.transform.translation.x for r in results] == [float(k) for k in range(1, 1001)]
    assert buf.pending_waits == 0
    assert not buf._index and not buf._settled
