"""Closing ends pending waits at once: ``Buffer.close()``/``aclose()``, leaving the last
TransformListener that feeds a buffer, and leaving the Bus under a listener each fail every
wait pending on the buffer with ``BufferClosedException`` (a ``TransformException``), so a
server shutting down does not wait for each wait's own timeout. ``TimeoutException`` is also
a built-in ``TimeoutError``. On asyncio and trio; time is a ManualClock that never moves, so
only the closing can end these waits."""

from __future__ import annotations

from typing import Any

import anyio
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import (
    Buffer,
    BufferClosedException,
    Bus,
    Header,
    TimeoutException,
    Transform,
    TransformException,
    TransformListener,
    TransformStamped,
    Vector3,
)
from tfbus.clock import ManualClock
from tfbus.time import Time

pytestmark = pytest.mark.anyio


def make_buffer() -> Buffer:
    return Buffer(clock=ManualClock(Time(100)))


async def start_waits(tg: Any, buffer: Buffer, n: int, outcomes: list[BaseException]) -> None:
    """``n`` tasks awaiting a transform that never arrives (no timeout); each appends what
    ended its wait."""

    async def wait(i: int) -> None:
        try:
            await buffer.lookup_transform_async("map", f"robot{i}", Time(0))
        except TransformException as exc:
            outcomes.append(exc)

    for i in range(n):
        tg.start_soon(wait, i)
    await anyio.wait_all_tasks_blocked()
    assert buffer.pending_waits == n


async def test_close_fails_every_pending_wait_at_once() -> None:
    buffer = make_buffer()
    outcomes: list[BaseException] = []
    with anyio.fail_after(10):  # a bound, never reached: the close ends the waits
        async with anyio.create_task_group() as tg:
            await start_waits(tg, buffer, 3, outcomes)
            buffer.close()
    assert [type(e) for e in outcomes] == [BufferClosedException] * 3
    assert len({id(e) for e in outcomes}) == 3  # one exception per task
    assert all("the buffer was closed" in str(e) for e in outcomes)
    assert buffer.pending_waits == 0
    assert buffer.closed


async def test_after_close_a_wait_fails_at_once_and_stored_data_still_answers() -> None:
    buffer = make_buffer()
    buffer.set_transform(
        TransformStamped(Header(Time(5), "map"), "odom", Transform(Vector3(1.0, 2.0, 3.0)))
    )
    await buffer.aclose()
    got = await buffer.lookup_transform_async("map", "odom", Time(0), timeout=1.0)
    assert tuple(got.transform.translation) == (1.0, 2.0, 3.0)
    with pytest.raises(BufferClosedException, match="not waiting for transform from"):
        await buffer.lookup_transform_async("map", "base_link", Time(0), timeout=1.0)
    assert buffer.lookup_transform("map", "odom", Time(5)).header.stamp == Time(5)


async def test_aclose_fails_the_waits_before_returning() -> None:
    buffer = make_buffer()
    outcomes: list[BaseException] = []
    async with anyio.create_task_group() as tg:
        await start_waits(tg, buffer, 2, outcomes)
        await buffer.aclose()
        await anyio.wait_all_tasks_blocked()
        assert [type(e) for e in outcomes] == [BufferClosedException] * 2


@pytest.mark.parametrize("inline", [True, False])
async def test_leaving_the_last_listener_fails_the_pending_waits(inline: bool) -> None:
    buffer = make_buffer()
    outcomes: list[BaseException] = []
    async with Bus() as bus, anyio.create_task_group() as tg:
        async with TransformListener(buffer, bus, inline=inline):
            async with TransformListener(buffer, bus, inline=inline):
                await start_waits(tg, buffer, 2, outcomes)
            await anyio.wait_all_tasks_blocked()
            assert outcomes == []  # another listener still feeds the buffer
            assert buffer.pending_waits == 2
        await anyio.wait_all_tasks_blocked()
        assert [type(e) for e in outcomes] == [BufferClosedException] * 2
        assert "the last TransformListener feeding the buffer was left" in str(outcomes[0])
    assert not buffer.closed  # the buffer stays usable: a new listener can feed it


async def test_leaving_the_bus_fails_the_waits_of_a_listener_still_on_it() -> None:
    buffer = make_buffer()
    outcomes: list[BaseException] = []
    async with anyio.create_task_group() as tg:
        async with Bus() as bus:
            listener = TransformListener(buffer, bus)
            await listener.__aenter__()  # entered by someone else, not left before the bus
            await start_waits(tg, buffer, 2, outcomes)
        await anyio.wait_all_tasks_blocked()
        assert [type(e) for e in outcomes] == [BufferClosedException] * 2
        await listener.__aexit__(None, None, None)  # leaving it later fails nothing more
    assert len(outcomes) == 2


async def test_an_application_shutdown_ends_its_requests_promptly() -> None:
    """A server's lifespan (bus + listener) ends while a request awaits a future stamp
    with a long timeout: the request fails with BufferClosedException now."""
    buffer = make_buffer()
    outcomes: list[BaseException] = []

    async def request() -> None:
        try:
            await buffer.lookup_transform_async("map", "base_link", Time(200), timeout=3600.0)
        except TransformException as exc:
            outcomes.append(exc)

    async with anyio.create_task_group() as tg:
        async with Bus() as bus, TransformListener(buffer, bus):
            tg.start_soon(request)
            await anyio.wait_all_tasks_blocked()
        await anyio.wait_all_tasks_blocked()
        assert [type(e) for e in outcomes] == [BufferClosedException]


async def test_timeout_exception_is_a_timeout_error_and_a_transform_exception() -> None:
    buffer = make_buffer()
    caught: list[TimeoutError] = []
    try:
        await buffer.lookup_transform_async("map", "base_link", Time(0), timeout=0)
    except TimeoutError as exc:  # one clause for tfbus's timeout= and the loop's deadlines
        caught.append(exc)
    assert len(caught) == 1
    assert isinstance(caught[0], TimeoutException)
    assert isinstance(caught[0], TransformException)
    assert str(caught[0]).startswith("Timed out after 0 s waiting for transform from")
    assert issubclass(TimeoutException, TimeoutError)


async def test_lookup_transform_with_a_tf2_ros_timeout_points_to_the_async_lookup() -> None:
    buffer = make_buffer()
    buffer.set_transform(
        TransformStamped(Header(Time(5), "map"), "odom", Transform(Vector3(1.0, 2.0, 3.0)))
    )
    with pytest.raises(TypeError, match=r"await buffer\.lookup_transform_async\('map', 'odom'"):
        buffer.lookup_transform("map", "odom", Time(0), timeout=1.0)
    # tf2_ros's default (no wait) is accepted and is the plain lookup
    got = buffer.lookup_transform("map", "odom", Time(0), timeout=0.0)
    assert tuple(got.transform.translation) == (1.0, 2.0, 3.0)
    assert buffer.lookup_transform("map", "odom", Time(5)).header.stamp == Time(5)
