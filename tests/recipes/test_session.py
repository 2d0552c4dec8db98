"""open_session: a bus, buffer, listener and broadcasters held by a background task, closed
from any task of the same loop (asyncio and trio)."""

from __future__ import annotations

from typing import Any

import anyio
import anyio.abc
import pytest

from tfbus import (
    Header,
    ManualClock,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformStamped,
    Vector3,
    open_session,
)
from tfbus.bus import Bus
from tfbus.session import TransformSession

LATEST = Time(0)


def _tf(x: float, stamp: Time = LATEST) -> TransformStamped:
    return TransformStamped(
        Header(stamp, "map"), "base_link", Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


async def _open_in_child_task(**kwargs: Any) -> TransformSession:
    """Open in a task that then ends, as a notebook cell's task does."""
    opened: list[TransformSession] = []

    async def cell() -> None:
        opened.append(await open_session(**kwargs))

    async with anyio.create_task_group() as tg:
        tg.start_soon(cell)
    return opened[0]


@pytest.mark.anyio
async def test_opened_in_one_task_used_and_closed_in_others(anyio_backend: str) -> None:
    with anyio.fail_after(30):
        session = await _open_in_child_task()
        assert not session.closed
        await session.broadcaster.send_transform(_tf(1.5))
        found = session.buffer.lookup_transform("map", "base_link", Time(0))
        assert found.transform.translation.x == 1.5
        async with anyio.create_task_group() as tg:  # closed from yet another task
            tg.start_soon(session.aclose)
        assert session.closed
        await session.aclose()  # idempotent
        with pytest.raises(anyio.ClosedResourceError):
            session.broadcaster.send_transform_nowait(_tf(2.0))


@pytest.mark.anyio
async def test_a_name_opened_again_closes_the_previous_session(anyio_backend: str) -> None:
    with anyio.fail_after(30):
        first = await _open_in_child_task(name="robot")
        other = await open_session(name="arm")
        second = await _open_in_child_task(name="robot")
        assert first.closed and not second.closed and not other.closed
        await second.aclose()
        await other.aclose()
        third = await open_session(name="robot")  # the name is free again after aclose
        assert not third.closed
        await third.aclose()


@pytest.mark.anyio
async def test_a_cancelled_wait_leaves_the_session_usable(anyio_backend: str) -> None:
    clock = ManualClock(Time(100))
    session = await open_session(clock=clock)
    try:
        with anyio.fail_after(30):
            with anyio.move_on_after(0.05):  # the caller gives up (a notebook interrupt)
                await session.buffer.lookup_transform_async("map", "base_link", Time(0))
            assert session.buffer.pending_waits == 0
            failures: list[TimeoutException] = []

            async def wait() -> None:
                try:
                    await session.buffer.lookup_transform_async(
                        "map", "base_link", Time(0), timeout=1.0
                    )
                except TimeoutException as exc:
                    failures.append(exc)

            async with anyio.create_task_group() as tg:
                tg.start_soon(wait)
                await anyio.wait_all_tasks_blocked()
                await clock.advance(2.0)  # the buffer's clock: 1 s timeout expires
            assert len(failures) == 1
            await session.broadcaster.send_transform(_tf(3.0, Time(101)))
            found = await session.buffer.lookup_transform_async(
                "map", "base_link", Time(101), timeout=1.0
            )
            assert found.transform.translation.x == 3.0
    finally:
        await session.aclose()


class _FailingTransport:
    async def run(
        self, bus: Bus, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        raise OSError("no route to 127.0.0.1:1")

    def send_nowait(self, topic: str, message: object) -> None:
        raise AssertionError("never opened")


@pytest.mark.anyio
async def test_a_transport_failing_to_start_raises_from_open(anyio_backend: str) -> None:
    with anyio.fail_after(30):
        with pytest.raises(OSError, match=r"no route to 127\.0\.0\.1:1"):
            await open_session(_FailingTransport())
        async with anyio.create_task_group() as tg:
            with pytest.raises(OSError, match="no route"):
                await open_session(_FailingTransport(), task_group=tg)


@pytest.mark.anyio
async def test_in_a_task_group_the_group_waits_for_aclose(anyio_backend: str) -> None:
    with anyio.fail_after(30):
        async with anyio.create_task_group() as tg:
            session = await open_session(task_group=tg)
            await session.broadcaster.send_transform(_tf(4.0))
            assert session.buffer.lookup_transform("map", "base_link", Time(0)) is not None
            async with session:  # the context manager's exit is aclose()
                pass
        assert session.closed
