"""A tf2_ros habit on the native async API: calling a waiting method of ``Buffer`` without
``await`` (tf2_ros's ``buffer.transform(p, "map")`` blocks and returns the point).

The call returns an awaitable (:class:`tfbus._aio.Awaiting`) that behaves as the coroutine
when awaited, run as a task or started in a task group, and names the mistake when used as
the result: ``p2.point`` is an AttributeError, ``if buffer.can_transform_async(...)`` a
TypeError, each saying ``Buffer.transform(...) is a coroutine: write `await
buffer.transform(...)```; dropped without ever being awaited it warns with that text (not
Python's bare "coroutine ... was never awaited") and leaves no wait registered. On asyncio
and trio; the data is in the buffer, so no wait depends on time.
"""

from __future__ import annotations

import gc
import math
import warnings
from collections.abc import Callable, Coroutine
from typing import Any

import anyio
import numpy as np
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import Buffer, Header, Point, PointStamped, Time, Transform, TransformStamped, Vector3
from tfbus.clock import ManualClock

pytestmark = pytest.mark.anyio

ODOM_IN_MAP = (1.0, 2.0, 3.0)  # map -> odom at 5 s; at 4 s it was (0, 2, 3): 1 m/s along x
P_ODOM = PointStamped(Header(Time(0), "odom"), Point(1.0, 0.0, 0.0))
P_MAP = (2.0, 2.0, 3.0)


def make_buffer() -> Buffer:
    buffer = Buffer(clock=ManualClock(Time(5)))
    for sec, x in ((4, 0.0), (5, 1.0)):
        buffer.set_transform(
            TransformStamped(Header(Time(sec), "map"), "odom", Transform(Vector3(x, 2.0, 3.0)))
        )
    return buffer


def translation(ts: TransformStamped) -> tuple[float, float, float]:
    v = ts.transform.translation
    return (v.x, v.y, v.z)


# Each waiting method of Buffer: the call, and a check of its awaited answer (known numbers).
CALLS: dict[str, tuple[Callable[[Buffer], Any], Callable[[Any], bool]]] = {
    "wait_for_transform": (
        lambda b: b.wait_for_transform("map", "odom", Time(0)),
        lambda r: translation(r) == ODOM_IN_MAP,
    ),
    "lookup_transform_async": (
        lambda b: b.lookup_transform_async("map", "odom", Time(0), timeout=1.0),
        lambda r: translation(r) == ODOM_IN_MAP and r.header.stamp == Time(5),
    ),
    "lookup_transform_full_async": (
        lambda b: b.lookup_transform_full_async("map", Time(5), "odom", Time(5), "map"),
        lambda r: translation(r) == ODOM_IN_MAP,
    ),
    "can_transform_async": (
        lambda b: b.can_transform_async("map", "odom", Time(0)),
        lambda r: r is True,
    ),
    "transform": (
        lambda b: b.transform(P_ODOM, "map"),
        lambda r: tuple(r.point) == P_MAP and r.header.frame_id == "map",
    ),
    "transform_full": (
        lambda b: b.transform_full(P_ODOM, "map", Time(5), "map"),
        lambda r: tuple(r.point) == P_MAP and r.header.stamp == Time(5),
    ),
    "lookup_transforms_async": (
        lambda b: b.lookup_transforms_async("map", "odom", [Time(5)]),
        lambda r: tuple(r.translations[0]) == ODOM_IN_MAP,
    ),
    "transform_points_async": (
        lambda b: b.transform_points_async([[1.0, 0.0, 0.0]], "map", "odom", [Time(5)]),
        lambda r: np.array_equal(r, [P_MAP]),
    ),
    "lookup_velocity_async": (
        lambda b: b.lookup_velocity_async("odom", "map", Time(5), 1.0),
        lambda r: math.isclose(r.velocity.linear.x, 1.0) and r.velocity.linear.y == 0.0,
    ),
    "lookup_velocity_full_async": (
        lambda b: b.lookup_velocity_full_async(
            "odom", "map", "map", (0.0, 0.0, 0.0), "odom", Time(5), 1.0
        ),
        lambda r: math.isclose(r.velocity.linear.x, 1.0) and r.velocity.linear.y == 0.0,
    ),
}


def mistake(method: str) -> str:
    return rf"Buffer\.{method}\(\.\.\.\) is a coroutine: write `await buffer\.{method}\(\.\.\.\)`"


@pytest.mark.parametrize("method", list(CALLS))
async def test_the_result_of_a_call_without_await_names_the_missing_await(method: str) -> None:
    buffer = make_buffer()
    call, answer_is_right = CALLS[method]
    pending = call(buffer)
    with pytest.raises(AttributeError, match=mistake(method) + r".*no attribute 'point'") as e:
        pending.point  # noqa: B018  (what a tf2_ros user writes next)
    assert e.value.name == "point"
    assert not hasattr(pending, "header")
    with pytest.raises(TypeError, match=mistake(method) + r".*no truth value"):
        bool(pending)
    with pytest.raises(TypeError, match=mistake(method) + r".*cannot be indexed"):
        pending[0]
    # The same object, awaited, is the answer.
    assert answer_is_right(await pending)


@pytest.mark.parametrize("method", list(CALLS))
async def test_a_call_never_awaited_warns_naming_the_missing_await(method: str) -> None:
    buffer = make_buffer()
    gc.collect()  # what earlier tests left to the collector warns out here, not below
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        CALLS[method][0](buffer)  # dropped at once
        gc.collect()
    assert [w.category for w in caught] == [RuntimeWarning]  # not Python's second one too
    assert len(caught) == 1
    text = str(caught[0].message)
    assert text.startswith(f"Buffer.{method}(...) is a coroutine: write `await buffer.{method}")
    assert "never awaited" in text
    assert buffer.pending_waits == 0


async def test_a_wait_without_await_is_a_coroutine_for_task_groups_and_tasks(
    anyio_backend_name: str,
) -> None:
    """What tasks need from a coroutine: started by a task group (trio checks for a
    :class:`collections.abc.Coroutine`), run as an asyncio task, and a wait for data that
    arrives later ends with it."""
    buffer = Buffer(clock=ManualClock(Time(5)))
    pending = buffer.lookup_transform_async("map", "odom", Time(5), timeout=10.0)
    with pytest.raises(AttributeError, match=mistake("lookup_transform_async")):
        pending.transform  # noqa: B018
    assert isinstance(pending, Coroutine)
    got: list[TransformStamped] = []

    async def keep(awaitable: Any) -> None:
        got.append(await awaitable)

    async with anyio.create_task_group() as tg:
        tg.start_soon(keep, pending)
        tg.start_soon(buffer.wait_for_transform, "map", "odom", Time(5))  # a task's coroutine
        await anyio.wait_all_tasks_blocked()
        assert buffer.pending_waits == 2
        buffer.set_transform(
            TransformStamped(Header(Time(5), "map"), "odom", Transform(Vector3(*ODOM_IN_MAP)))
        )
    assert [translation(ts) for ts in got] == [ODOM_IN_MAP]
    assert buffer.pending_waits == 0
    if anyio_backend_name == "asyncio":
        import asyncio

        task = asyncio.create_task(buffer.transform(P_ODOM, "map"))
        assert tuple((await task).point) == P_MAP
