"""Every tfbus context manager lets what its ``async with`` body raised leave as itself
(``tfbus._aio.exit_task_group``), never inside an ``ExceptionGroup``, on asyncio and trio:
``except MyError`` around the block catches it. A cancellation still reaches the cancel
scope that caused it; a background task's failure with no body exception propagates as
the task group's ``BaseExceptionGroup``.

The transports over a network use 127.0.0.1 only: Zenoh with an explicit tcp/127.0.0.1
endpoint (multicast scouting off, the transport's default), ROS 2 on a random domain with
the loopback Cyclone configuration, ROS 1 on the harness's own roscore.
"""

from __future__ import annotations

import socket
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, AsyncExitStack
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
import pytest
from dds_domains import new_domain
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    master_fixture,
    ros1_fixture,
)

from tfbus import Buffer, Bus, TimeoutException, TransformListener
from tfbus.clock import ManualClock
from tfbus.filters import MessageFilter
from tfbus.messages import Header, PointStamped, TFMessage
from tfbus.time import Time
from tfbus.transports.memory import MemoryTransport

if sys.version_info < (3, 11):
    from exceptiongroup import BaseExceptionGroup

pytestmark = pytest.mark.anyio


class MyError(Exception):
    """What the body raises."""


class MyBaseError(BaseException):
    """A BaseException that is not an Exception (as KeyboardInterrupt is)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _body_raises(cm: AbstractAsyncContextManager[Any], exc: BaseException) -> None:
    async with cm:
        await anyio.lowlevel.checkpoint()
        raise exc


async def _assert_leaves_as_itself(make: Callable[[], AbstractAsyncContextManager[Any]]) -> None:
    error = MyError("from the body")
    with pytest.raises(MyError) as info:
        await _body_raises(make(), error)
    assert info.value is error
    base = MyBaseError("a BaseException from the body")
    with pytest.raises(MyBaseError) as binfo:
        await _body_raises(make(), base)
    assert binfo.value is base


# -- the bus, on every transport -------------------------------------------------------------


async def test_bus_without_transport() -> None:
    await _assert_leaves_as_itself(Bus)


async def test_bus_over_memory_transport() -> None:
    await _assert_leaves_as_itself(lambda: Bus(transport=MemoryTransport()))


async def test_bus_over_zenoh() -> None:
    pytest.importorskip("zenoh")
    from tfbus.transports.zenoh import ZenohTransport

    await _assert_leaves_as_itself(
        lambda: Bus(transport=ZenohTransport(listen=f"tcp/127.0.0.1:{free_port()}"))
    )


async def test_bus_over_ros2() -> None:
    pytest.importorskip("cyclonedds", reason="needs the ros2 extra: pip install 'tfbus[ros2]'")
    from tfbus.transports.ros2 import Ros2Transport

    domain = new_domain()
    await _assert_leaves_as_itself(lambda: Bus(transport=Ros2Transport(domain_id=domain)))


async def test_bus_over_ros1(master: Master) -> None:
    from tfbus.transports.ros1 import Ros1Transport

    await _assert_leaves_as_itself(
        lambda: Bus(transport=Ros1Transport(master_uri=master.uri))
    )


# -- what runs on a bus ----------------------------------------------------------------------


class _OnBus:
    """``async with Bus() as bus, make(bus):`` as one context manager, the bus outermost:
    the body's exception passes through both."""

    def __init__(
        self,
        make: Callable[[Bus], AbstractAsyncContextManager[Any]],
        bus: Callable[[], Bus] = Bus,
    ) -> None:
        self._make = make
        self._bus = bus
        self._stack = AsyncExitStack()

    async def __aenter__(self) -> Any:
        bus = await self._stack.enter_async_context(self._bus())
        return await self._stack.enter_async_context(self._make(bus))

    async def __aexit__(self, *exc: Any) -> bool:
        return await self._stack.__aexit__(*exc)


@pytest.mark.parametrize("inline", [True, False])
async def test_transform_listener(inline: bool) -> None:
    await _assert_leaves_as_itself(
        lambda: _OnBus(lambda bus: TransformListener(Buffer(), bus, inline=inline))
    )


async def test_subscription() -> None:
    await _assert_leaves_as_itself(lambda: _OnBus(lambda bus: bus.subscribe("/chat")))


async def test_message_filter() -> None:
    async def never() -> AsyncIterator[PointStamped]:
        await anyio.sleep_forever()
        yield PointStamped(Header(Time(1), "a"))  # pragma: no cover

    await _assert_leaves_as_itself(lambda: MessageFilter(Buffer(), "map", never()))


async def test_fleet_buffer() -> None:
    from tfbus.fleet import FleetBuffer

    await _assert_leaves_as_itself(lambda: _OnBus(FleetBuffer))


async def test_bag_recorder(tmp_path: Path) -> None:
    from tfbus.bag.writer import BagRecorder

    paths = iter(tmp_path / f"r{i}.mcap" for i in range(2))
    await _assert_leaves_as_itself(lambda: _OnBus(lambda bus: BagRecorder(bus, next(paths))))


async def test_compat_tf2_ros_listener() -> None:
    from tfbus.compat.tf2_ros import Buffer as RosBuffer
    from tfbus.compat.tf2_ros import TransformListener as RosListener

    await _assert_leaves_as_itself(lambda: _OnBus(lambda bus: RosListener(RosBuffer(), bus=bus)))


async def test_zenoh_buffer_server_and_router() -> None:
    pytest.importorskip("zenoh")
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.lookups import BufferServer
    from tfbus.transports.zenoh.router import ZenohRouter

    def zenoh_bus() -> Bus:
        return Bus(transport=ZenohTransport(listen=f"tcp/127.0.0.1:{free_port()}"))

    await _assert_leaves_as_itself(
        lambda: _OnBus(lambda bus: BufferServer(Buffer(), bus), zenoh_bus)
    )
    await _assert_leaves_as_itself(
        lambda: ZenohRouter(listen=f"tcp/127.0.0.1:{free_port()}")
    )


async def test_ros1_buffer_server(master: Master) -> None:
    from tfbus.bus import Bus
    from tfbus.remote import BufferServer
    from tfbus.transports.ros1 import Ros1Transport

    async with Bus(transport=Ros1Transport(master.uri, None, "127.0.0.1")) as bus:
        await _assert_leaves_as_itself(lambda: BufferServer(Buffer(), bus))


# -- what the README's example does -------------------------------------------------------------


async def test_a_lookup_timeout_inside_bus_and_listener_is_caught_as_itself() -> None:
    buffer = Buffer(clock=ManualClock(Time(100)))
    caught: list[TimeoutException] = []
    try:
        async with Bus() as bus, TransformListener(buffer, bus, inline=False):
            await buffer.lookup_transform_async("map", "base_link", Time(0), timeout=0)
    except TimeoutException as exc:
        caught.append(exc)
    assert len(caught) == 1
    assert "map" in str(caught[0]) and "base_link" in str(caught[0])


# -- cancellation and background failures -----------------------------------------------------


async def test_a_cancellation_still_reaches_its_cancel_scope() -> None:
    with anyio.CancelScope() as scope:
        async with Bus() as bus, TransformListener(Buffer(), bus, inline=False):
            scope.cancel()
            await anyio.sleep_forever()
    assert scope.cancelled_caught


async def test_move_on_after_around_a_wait_inside_the_bus() -> None:
    buffer = Buffer()
    with anyio.move_on_after(0) as scope:
        async with Bus(transport=MemoryTransport()) as bus, TransformListener(
            buffer, bus, inline=False
        ):
            await buffer.wait_for_transform("map", "base_link", Time(0))
    assert scope.cancelled_caught
    assert buffer.pending_waits == 0


class _FailsAfterStart:
    """A transport whose task fails once the body has started (a background failure)."""

    def __init__(self) -> None:
        self.fail = anyio.Event()

    async def run(self, bus: Bus, *, task_status: anyio.abc.TaskStatus[None]) -> None:
        task_status.started()
        await self.fail.wait()
        raise OSError("the link went down")

    def send_nowait(self, topic: str, message: object) -> None:
        self.fail.set()


async def test_a_background_failure_is_grouped_when_the_body_ends_normally() -> None:
    transport = _FailsAfterStart()
    with pytest.raises(BaseExceptionGroup) as info:
        async with Bus(transport=transport) as bus:
            bus.publish_nowait("/tf", TFMessage(()))
            await transport.fail.wait()
            await anyio.sleep_forever()
    assert info.group_contains(OSError, match="the link went down")


async def test_the_body_error_wins_over_a_background_failure_and_keeps_it_as_context() -> None:
    transport = _FailsAfterStart()
    error = MyError("from the body")
    with pytest.raises(MyError) as info:
        async with Bus(transport=transport) as bus:
            bus.publish_nowait("/tf", TFMessage(()))
            try:
                await anyio.sleep_forever()  # until the failing transport cancels the body
            except anyio.get_cancelled_exc_class():
                raise error from None  # e.g. a clean-up that fails
    assert info.value is error
    context = info.value.__context__
    assert isinstance(context, BaseExceptionGroup)
    assert [str(e) for e in context.exceptions] == ["the link went down"]
