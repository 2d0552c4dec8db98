"""ROS 2 geometry2's ``tf2_ros_py/test/test_buffer.py``, case for case, written again
against ``tfbus.compat.tf2_ros`` (our code: the same cases and assertions; rclpy's
clock, ``Time``, ``Duration`` and messages stood in for by objects with their fields).

Adapted, and why:

* the "immediately available" cases drive the coroutine by hand (``coro.send(None)``
  raises StopIteration) exactly as upstream;
* the "delayed" cases cannot: a pending tfbus wait needs an event loop (anyio) where
  rclpy's future needs none, so they run under ``anyio`` (asyncio and trio) with the
  same order of events — start the wait, then set the transform, then get it;
* results are tfbus types, so ``transform == result`` compares the result with the
  tfbus TransformStamped of the same fields.

``test_listener_and_broadcaster.py`` (rclpy nodes) is covered by
``tests/compat/test_compat_rclpy.py`` with the real rclpy, not case for case.
"""

from __future__ import annotations

import time

import anyio
import pytest
from test_upstream_tf2_py import Hd, RclTime, TfMsg

from tfbus.compat._args import to_transform_stamped
from tfbus.compat.tf2_ros import Buffer


def now() -> RclTime:
    """rclpy.clock.Clock().now(): the system time."""
    return RclTime(nanoseconds_extra=time.time_ns())


def build_transform(target: str, source: str, stamp: RclTime) -> TfMsg:
    t = TfMsg(Hd(stamp.to_msg(), target), source)
    t.transform.translation.x = 42.0
    t.transform.translation.y = -3.14
    t.transform.rotation.w = 1.0
    return t


def _same(transform: TfMsg, output: object) -> None:
    assert transform.child_frame_id == output.child_frame_id  # type: ignore[attr-defined]
    ours = output.transform.translation  # type: ignore[attr-defined]
    assert (transform.transform.translation.x, transform.transform.translation.y,
            transform.transform.translation.z) == (ours.x, ours.y, ours.z)


def test_can_transform_valid_transform() -> None:
    buffer = Buffer()
    stamp = now()
    transform = build_transform("foo", "bar", stamp)
    assert buffer.set_transform(transform, "unittest") is None  # type: ignore[func-returns-value]
    assert buffer.can_transform("foo", "bar", stamp)
    _same(transform, buffer.lookup_transform("foo", "bar", stamp))


def test_await_transform_immediately_available() -> None:
    buffer = Buffer()
    stamp = now()
    transform = build_transform("foo", "bar", stamp)
    buffer.set_transform(transform, "unittest")
    coro = buffer.lookup_transform_async("foo", "bar", stamp)
    with pytest.raises(StopIteration) as excinfo:
        coro.send(None)
    assert to_transform_stamped(transform) == excinfo.value.value
    coro.close()


def test_await_transform_full_immediately_available() -> None:
    buffer = Buffer()
    stamp = now()
    transform = build_transform("foo", "bar", stamp)
    buffer.set_transform(transform, "unittest")
    coro = buffer.lookup_transform_full_async("foo", stamp, "bar", stamp, "foo")
    with pytest.raises(StopIteration) as excinfo:
        coro.send(None)
    assert to_transform_stamped(transform) == excinfo.value.value
    coro.close()


async def _delayed(full: bool) -> None:
    buffer = Buffer()
    stamp = now()
    transform = build_transform("foo", "bar", stamp)
    got: list[object] = []

    async def wait() -> None:
        if full:
            got.append(await buffer.lookup_transform_full_async("foo", stamp, "bar", stamp, "foo"))
        else:
            got.append(await buffer.lookup_transform_async("foo", "bar", stamp))

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait)
        await anyio.wait_all_tasks_blocked()
        assert not got  # pending, as upstream's first coro.send(None)
        buffer.set_transform(transform, "unittest")
    assert got == [to_transform_stamped(transform)]


@pytest.mark.anyio
async def test_await_transform_delayed() -> None:
    await _delayed(full=False)


@pytest.mark.anyio
async def test_await_transform_full_delayed() -> None:
    await _delayed(full=True)


def test_buffer_non_default_cache() -> None:
    buffer = Buffer(cache_time=RclTime(seconds=10.0))
    stamp = now()
    transform = build_transform("foo", "bar", stamp)
    assert buffer.set_transform(transform, "unittest") is None  # type: ignore[func-returns-value]
    assert buffer.can_transform("foo", "bar", stamp)
    _same(transform, buffer.lookup_transform("foo", "bar", stamp))

