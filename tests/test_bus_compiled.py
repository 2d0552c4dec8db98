"""The bus's compiled pieces (``tfbus._cbus``, with the compiled core) do what their pure
twins do: the delivery (``Bus._deliver_each``: the latch, the counters, each queued
subscription and each callback, in order, a callback's exception counted), the test of
cancellation a publish makes on asyncio (the ``_asyncio_cancel_called`` closure's walk of
anyio's cancel scopes) and the yield after a publish (``tfbus._aio.ShieldedYield``). The
delivery's outcome is also compared with the pure-Python core's, run in a process of its
own."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import anyio
import anyio.lowlevel
import pytest

import tfbus.bus
from tfbus._aio import ShieldedYield
from tfbus.bus import TF_STATIC_TOPIC, TF_TOPIC, Bus
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time

COMPILED = tfbus.bus._COMPILED
TOPIC = "/chatter"
needs_compiled = pytest.mark.skipif(
    COMPILED is None,
    reason="the compiled bus is not in use (TFBUS_PURE_PYTHON, or no extensions)")


def _ts(child: str, x: float = 0.1) -> TransformStamped:
    return TransformStamped(Header(Time(10), "base_link"), child,
                            Transform(Vector3(x, 0.0, 0.2), Quaternion()))


async def _deliveries(pure: bool) -> str:
    """One bus through every case of a delivery; everything it and its subscribers saw,
    as exact text. ``pure``: the bus delivers with ``_deliver_each``."""
    out: list[object] = []
    async with Bus(queue_size=2) as bus:
        if pure:
            bus._deliver = bus._deliver_each
        got: list[object] = []
        late: list[object] = []
        raised: list[object] = []

        def raises_on_odd(message: object) -> None:
            raised.append(message)
            if isinstance(message, int) and message % 2:
                raise ValueError(f"odd {message}")

        def subscribes_another(message: object) -> None:
            # Copy-on-write: the callback added now gets the next message, not this one.
            if message == 3:
                bus.subscribe_callback(TOPIC, late.append)

        queued = bus.subscribe(TOPIC)  # 2 slots: the oldest dropped
        bus.subscribe_callback(TOPIC, got.append)
        failing = bus.subscribe_callback(TOPIC, raises_on_odd)
        bus.subscribe_callback(TOPIC, subscribes_another)
        closing = bus.subscribe_callback(TOPIC, lambda m: closing.close() if m == 2 else None)
        for i in range(1, 6):
            await bus.publish(TOPIC, i)
        bus.deliver_nowait(TOPIC, 6)  # a remote message
        bus.deliver_many_nowait(TOPIC, [7, 8])
        tf = bus.subscribe(TF_TOPIC)
        await bus.publish(TF_TOPIC, TFMessage((_ts("base_laser"),)))
        await bus.publish("/nobody", "x")  # a topic's counters, with no subscriber
        bus.deliver_nowait("/remote_only", "y")
        await bus.publish(TF_STATIC_TOPIC, TFMessage((_ts("laser"), _ts("cam"))))
        await bus.publish(TF_STATIC_TOPIC, TFMessage((_ts("laser", 0.3),)))
        statics: list[object] = []
        bus.subscribe_callback(TF_STATIC_TOPIC, statics.append)  # the latch's snapshot
        late_queue = bus.subscribe(TF_STATIC_TOPIC)
        await bus.publish(TF_STATIC_TOPIC, TFMessage((_ts("imu"),)))
        out += [got, late, raised, statics, failing.statistics(), closing.statistics()]
        out += [queued.statistics(), [queued.receive_nowait() for _ in range(2)]]
        out += [late_queue.statistics(), late_queue.receive_nowait(), late_queue.receive_nowait()]
        out += [tf.receive_nowait()]
        out += [sorted(bus.statistics().items()), bus.latched_statics()]
    out.append(sorted(bus.statistics().items()))
    return repr(out)


def outcome() -> str:
    """:func:`_deliveries` with the bus's own delivery (compiled or not), on asyncio."""
    return anyio.run(_deliveries, False, backend="asyncio")


@needs_compiled
@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_compiled_delivery_does_what_the_bus_does(backend: str) -> None:
    compiled = anyio.run(_deliveries, False, backend=backend)
    pure = anyio.run(_deliveries, True, backend=backend)
    assert compiled == pure
    # The walk itself, by hand: message 2 reached the callback that closed itself, 3 made
    # the late callback, which saw 4 to 8; 1, 3, 5, 7 raised (4 errors counted).
    assert "CallbackStatistics(topic='/chatter', delivered=8, errors=4)" in compiled
    assert "CallbackStatistics(topic='/chatter', delivered=2, errors=0)" in compiled
    assert compiled.startswith("[[1, 2, 3, 4, 5, 6, 7, 8], [4, 5, 6, 7, 8], [1, 2, 3,")


@needs_compiled
def test_the_compiled_delivery_does_what_the_pure_core_does() -> None:
    """The pure-Python core (``TFBUS_PURE_PYTHON=1``: every pure twin, the counters'
    class included) in a process of its own gives the same outcome, bit for bit."""
    here = Path(__file__).parent
    env = {**os.environ, "TFBUS_PURE_PYTHON": "1"}
    code = (f"import sys; sys.path.insert(0, {str(here)!r}); import test_bus_compiled as t; "
            "import tfbus.bus; assert tfbus.bus._COMPILED is None; print(t.outcome())")
    pure = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120, check=True).stdout.strip()
    assert pure == outcome()


def _walks() -> tuple[Callable[[], bool], Callable[[], bool]]:
    """The compiled cancellation test and the Python walk, for the running loop."""
    loop = asyncio.get_running_loop()
    compiled = tfbus.bus._asyncio_cancel_called(loop)
    saved = tfbus.bus._COMPILED
    tfbus.bus._COMPILED = None
    try:
        walk = tfbus.bus._asyncio_cancel_called(loop)
    finally:
        tfbus.bus._COMPILED = saved
    assert compiled is not None and walk is not None
    assert type(compiled) is not type(walk)
    return compiled, walk


@needs_compiled
def test_the_compiled_cancellation_test_answers_as_the_walk() -> None:
    answers: list[tuple[str, bool, bool]] = []

    async def main() -> None:
        compiled, walk = _walks()

        def ask(case: str) -> None:
            answers.append((case, compiled(), walk()))

        ask("no scope cancelled")
        with anyio.CancelScope() as scope:
            scope.cancel()
            ask("own scope cancelled")
        with anyio.CancelScope() as outer:
            with anyio.CancelScope():
                with anyio.CancelScope():
                    outer.cancel()
                    ask("outermost cancelled, two open scopes inside")
        with anyio.CancelScope() as outer:
            with anyio.CancelScope(shield=True):
                outer.cancel()
                ask("outer cancelled, a shielded scope inside")
        with anyio.CancelScope(shield=True) as shielded:
            shielded.cancel()
            ask("a shielded scope cancelled itself")
        with anyio.CancelScope(deadline=-float("inf")):
            ask("a deadline already past")
        async with anyio.create_task_group() as tg:

            async def in_a_child() -> None:
                ask("a child task, nothing cancelled")
                tg.cancel_scope.cancel()
                ask("a child task, its group cancelled")

            tg.start_soon(in_a_child)
        loop = asyncio.get_running_loop()
        done = asyncio.Event()
        loop.call_soon(lambda: (ask("a loop callback: no task"), done.set()))
        await done.wait()

    anyio.run(main, backend="asyncio")
    expected = [False, True, True, False, True, True, False, True, False]
    assert [c for _, c, _ in answers] == expected, answers
    assert [w for _, _, w in answers] == expected, answers


async def _order(make_yield: Callable[[asyncio.AbstractEventLoop], Any]) -> list[str]:
    """What runs around one task's await of a shielded yield: every task already ready
    runs before it resumes; a cancel scope cancelled meanwhile does not interrupt it (its
    next checkpoint does); ``Task.cancel`` lands at it."""
    steps: list[str] = []
    shielded = make_yield(asyncio.get_running_loop())
    async with anyio.create_task_group() as tg:
        scope = anyio.CancelScope()

        async def other() -> None:
            steps.append("other ran")
            scope.cancel()

        async def yielder() -> None:
            with scope:
                tg.start_soon(other)
                await shielded
                steps.append("resumed")
                await anyio.lowlevel.checkpoint()
                steps.append("not reached")
            steps.append(f"cancelled_caught={scope.cancelled_caught}")

        tg.start_soon(yielder)
    started = asyncio.Event()

    async def native() -> None:
        started.set()
        await shielded
        steps.append("not reached after Task.cancel")

    task = asyncio.get_running_loop().create_task(native())
    await started.wait()
    task.cancel()
    try:
        await task
    except asyncio.CancelledError:
        steps.append("Task.cancel landed")
    return steps


@needs_compiled
def test_the_compiled_shielded_yield_yields_as_the_generator() -> None:
    assert COMPILED is not None

    def run(make: Callable[[asyncio.AbstractEventLoop], Any]) -> list[str]:
        def start() -> Awaitable[list[str]]:
            return _order(make)

        return anyio.run(start, backend="asyncio")

    compiled = run(COMPILED.ShieldedYield)
    assert compiled == run(ShieldedYield)
    assert compiled == ["other ran", "resumed", "cancelled_caught=True", "Task.cancel landed"]
