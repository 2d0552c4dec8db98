"""The publish path of ``TransformBroadcaster.send_transform``: what it costs in
Python-level calls up to the listener's store, and the cancellation it checks first
(anyio's ``checkpoint_if_cancelled`` semantics: any cancelled scope around the sender
with no shielded scope in between, a deadline already past included)."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from types import FrameType
from typing import Any

import anyio
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

import tfbus.bus
import tfbus.core
import tfbus.listener
from tfbus.broadcaster import TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.core import BatchResult, BufferCore
from tfbus.listener import TransformListener
from tfbus.messages import (
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time

pytestmark = pytest.mark.anyio

# Python functions entered from ``await send_transform(ts)`` until the listener's store
# (the core's set_transform: C code in the compiled core): send_transform, the
# cancellation test (one function, on asyncio and on trio), the bus's delivery, the
# listener's _handle (not with the compiled message handler, tfbus._clistener, which is
# C) and its clock read: 5; with the compiled core, the handler, the delivery and
# asyncio's cancellation test are C (tfbus._clistener, tfbus._cbus), leaving 2 on asyncio
# and 3 on trio (the core's own frames, which the pure-Python core adds, are not
# counted: its test of the transform and the message it makes). The path before entered
# 6 on trio (trio's checkpoint_if_cancelled and current_task for the test), 7 on asyncio
# and 8 on trio before that (the broadcaster's _check, Bus.publish_nowait,
# Buffer.set_transform), and 15 and 13 before that (anyio's checkpoint coroutine and its
# task-state look-ups, Bus.publish, _as_message, TFMessage's __new__, the callback
# subscription's _call).
HANDLED_IN_C = tfbus.listener._HANDLER is not None
DELIVERED_IN_C = tfbus.bus._COMPILED is not None
CALLS_BEFORE_STORE = {
    "asyncio": 5 - HANDLED_IN_C - 2 * DELIVERED_IN_C,
    "trio": 5 - HANDLED_IN_C - DELIVERED_IN_C,
}
# The last two: the delivery (unless compiled) or what came before it, then the clock read
# (a ManualClock's: Python code; a SystemClock's is read in C by the compiled handler).
DELIVERY = [] if DELIVERED_IN_C else ["_deliver_each"] if HANDLED_IN_C else ["_handle"]
CORE_DIR = str(Path(tfbus.core.__file__).parent)


def _ts(stamp_s: float) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_sec(stamp_s), "world"),
        "probe",
        Transform(Vector3(1.0, 2.0, 3.0), Quaternion(0.0, 0.0, 0.0, 1.0)),
    )


async def test_send_transform_reaches_the_store_in_few_python_calls(
    anyio_backend_name: str,
) -> None:
    clock = ManualClock(Time.from_sec(100.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    async with Bus() as bus, TransformListener(buffer, bus, clock=clock):
        broadcaster = TransformBroadcaster(bus)
        await broadcaster.send_transform(_ts(100.0))  # warm: every look-up made once
        entered: list[str] = []
        stamp = Time.from_sec(100.5)

        def profile(frame: FrameType, event: str, arg: Any) -> None:
            # Frames entered while the buffer does not hold the transform yet (the store
            # itself may be C code, which calls no Python frame of its own).
            if (
                event == "call"
                and not frame.f_code.co_filename.startswith(CORE_DIR)
                and not buffer.can_transform("world", "probe", stamp)
            ):
                entered.append(frame.f_code.co_name)

        message = _ts(100.5)
        sys.setprofile(profile)
        try:
            await broadcaster.send_transform(message)
        finally:
            sys.setprofile(None)
        assert entered[0] == "send_transform"
        assert "_check" not in entered and "publish_nowait" not in entered
        assert "checkpoint_if_cancelled" not in entered, entered  # the test answered False
        assert entered[-1] == "now_ns", entered
        if DELIVERY:
            assert entered[-2:-1] == DELIVERY, entered
        else:
            assert "_deliver_each" not in entered and "_handle" not in entered, entered
        assert len(entered) == CALLS_BEFORE_STORE[anyio_backend_name], entered
        assert buffer.lookup_transform("world", "probe", Time.from_sec(100.5)).transform == (
            _ts(100.5).transform
        )


async def test_send_transform_in_a_cancelled_outer_scope_raises_and_sends_nothing() -> None:
    async with Bus() as bus:
        got: list[object] = []
        with bus.subscribe_callback("/tf", got.append):
            broadcaster = TransformBroadcaster(bus)
            with anyio.CancelScope() as outer:
                with anyio.CancelScope():  # not shielded: the outer cancellation reaches in
                    outer.cancel()
                    await broadcaster.send_transform(_ts(1.0))
            assert outer.cancelled_caught
            assert got == [] and broadcaster.sent == 0


async def test_send_transform_past_its_deadline_raises_and_sends_nothing() -> None:
    async with Bus() as bus:
        got: list[object] = []
        with bus.subscribe_callback("/tf", got.append):
            broadcaster = TransformBroadcaster(bus)
            with anyio.CancelScope(deadline=-math.inf) as scope:
                await broadcaster.send_transform(_ts(1.0))
            assert scope.cancelled_caught
            assert got == [] and broadcaster.sent == 0


async def test_send_transform_in_a_shielded_scope_inside_a_cancelled_one_is_sent() -> None:
    async with Bus() as bus:
        got: list[object] = []
        with bus.subscribe_callback("/tf", got.append):
            broadcaster = TransformBroadcaster(bus)
            with anyio.CancelScope() as outer:
                outer.cancel()
                with anyio.CancelScope(shield=True):
                    await broadcaster.send_transform(_ts(1.0))
                    await bus.publish("/tf", got[0])
            assert len(got) == 2 and broadcaster.sent == 1
            first = got[0]
            assert isinstance(first, TFMessage)
            assert first.transforms[0].transform.translation == Vector3(1.0, 2.0, 3.0)


async def test_listener_counts_one_transform_messages_as_one_item_batches() -> None:
    """A message of one transform is stored with the buffer's set_transform(_static); its
    counts are those of the same transform in a one-item list (the batch store)."""
    clock = ManualClock(Time.from_sec(100.0))

    def tf(child: str, stamp_s: float, x: float = 1.0) -> TransformStamped:
        return TransformStamped(
            Header(Time.from_sec(stamp_s), "world"),
            child,
            Transform(Vector3(x, 2.0, 3.0), Quaternion(0.0, 0.0, 0.0, 1.0)),
        )

    counts = []
    wraps: tuple[Callable[[tuple[Any, ...]], Any], ...] = (tuple, list)
    for wrap in wraps:
        buffer = Buffer(cache_time=10.0, clock=clock)
        async with Bus() as bus, TransformListener(buffer, bus, clock=clock) as listener:
            for item in (
                tf("a", 100.0),
                tf("a", 100.0, x=9.0),  # repeated stamp: TF_REPEATED_DATA, refused
                tf("a", 120.0),
                tf("a", 100.5),  # older than cache_time before the newest: refused
                tf("b", 100.0, x=math.nan),  # invalid
                "junk",  # malformed
            ):
                bus.deliver_nowait("/tf", TFMessage(wrap((item,))))
            bus.deliver_nowait("/tf_static", TFMessage(wrap((tf("s", 0.0, x=4.0),))))
            stats = listener.statistics()
            counts.append((stats.stored, stats.refused, stats.invalid, stats.malformed))
            assert buffer.lookup_transform("world", "a", Time.from_sec(120.0)).transform == (
                tf("a", 120.0).transform
            )
            assert buffer.lookup_transform("world", "s", Time.from_sec(500.0)).transform == (
                tf("s", 0.0, x=4.0).transform
            )
    assert counts == [(3, 2, 1, 1), (3, 2, 1, 1)]


async def test_a_raising_callback_is_counted_and_the_others_still_get_the_message() -> None:
    async with Bus() as bus:
        got: list[object] = []

        def broken(message: object) -> None:
            raise ValueError(f"cannot take {message!r}")

        with bus.subscribe_callback("/x", broken) as bad, bus.subscribe_callback(
            "/x", got.append
        ) as good:
            await bus.publish("/x", 1)
            bus.publish_nowait("/x", 2)
            assert got == [1, 2]
            assert (bad.statistics().delivered, bad.statistics().errors) == (2, 2)
            assert (good.statistics().delivered, good.statistics().errors) == (2, 0)
            assert bus.statistics()["/x"].delivered == 4


async def test_a_buffer_that_overrides_set_transforms_gets_every_message_through_it() -> None:
    """The one-transform store is taken only where it does what the batch store does:
    a subclass's own ``set_transforms`` is still called for a message of one transform."""
    batches: list[int] = []

    class Counting(BufferCore):
        def set_transforms(
            self,
            transforms: Iterable[TransformStamped],
            authority: str = "default",
            is_static: bool = False,
        ) -> BatchResult:
            items = list(transforms)
            batches.append(len(items))
            return super().set_transforms(items, authority, is_static)

    core = Counting(cache_time=10.0)
    clock = ManualClock(Time.from_sec(100.0))
    async with Bus() as bus, TransformListener(core, bus, clock=clock) as listener:
        await TransformBroadcaster(bus).send_transform(_ts(100.0))
        assert batches == [1]
        assert listener.statistics().stored == 1
        assert core.lookup_transform("world", "probe", Time.from_sec(100.0)).transform == (
            _ts(100.0).transform
        )


def test_the_trio_cancellation_test_answers_as_trios_own_checkpoint() -> None:
    """The bus's test before a publish on trio answers as trio's
    ``checkpoint_if_cancelled`` decides (True: it would checkpoint and raise; the bus then
    awaits it), case by case, and counts the task's cancel point as that function does
    when it answers False."""
    trio = pytest.importorskip("trio")

    async def main() -> None:
        called = tfbus.bus._trio_cancel_called(trio.lowlevel)
        assert called is not None, "this trio keeps no cancellation state tfbus can read"

        async def trio_says() -> tuple[bool, int]:
            task = trio.lowlevel.current_task()
            before = task._cancel_points
            try:
                await trio.lowlevel.checkpoint_if_cancelled()
            except trio.Cancelled:
                return True, task._cancel_points - before
            return False, task._cancel_points - before

        async def both() -> tuple[bool, int]:
            task = trio.lowlevel.current_task()
            before = task._cancel_points
            ours = called()
            counted = task._cancel_points - before
            theirs, their_count = await trio_says()
            assert ours == theirs
            if not ours:  # (answering True, trio's own checkpoint, awaited next, counts)
                assert counted == their_count
            return ours, counted

        assert await both() == (False, 1)  # no scope cancelled
        with trio.CancelScope() as scope:
            scope.cancel()
            assert await both() == (True, 0)
            with trio.CancelScope(shield=True):
                assert await both() == (False, 1)  # shielded from it
                with trio.CancelScope() as inner:
                    inner.cancel()
                    assert await both() == (True, 0)  # cancelled inside the shield
        with trio.CancelScope(deadline=-math.inf):
            assert await both() == (True, 0)  # a deadline already past
        answers: list[tuple[bool, int]] = []

        async def child() -> None:
            answers.append(await both())
            nursery.cancel_scope.cancel()
            answers.append(await both())  # its nursery's scope, cancelled by the child

        async with trio.open_nursery() as nursery:
            nursery.start_soon(child)
        assert answers == [(False, 1), (True, 0)]
        # A KeyboardInterrupt pending: True for the run's main task (this one) only; not
        # asked of trio, which would raise it (the flag is set and cleared with no
        # checkpoint in between, where trio would deliver it).
        runner = trio.lowlevel.current_task()._runner
        assert runner.main_task is trio.lowlevel.current_task()
        pending: list[bool] = []

        def with_ki_pending() -> None:
            runner.ki_pending = True
            try:
                pending.append(called())
            finally:
                runner.ki_pending = False

        async def other() -> None:
            with_ki_pending()

        with_ki_pending()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(other)
        assert pending == [True, False] and called() is False

    trio.run(main)
