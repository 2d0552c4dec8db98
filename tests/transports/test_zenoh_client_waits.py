"""A ``mode=client`` bus started before its router waits for it (as rmw_zenoh waits for
``rmw_zenohd``), says once every few seconds what it is trying, and is bounded by
``connect_timeout`` when one is given. Everything on 127.0.0.1; every wait bounded."""

from __future__ import annotations

import logging
import socket

import anyio
import pytest

pytest.importorskip("zenoh")

from tfbus.broadcaster import StaticTransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.errors import TransportError
from tfbus.listener import TransformListener
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.spec import open_transport, parse_bus_spec
from tfbus.transports.zenoh import ZenohTransport
from tfbus.transports.zenoh.router import ZenohRouter

pytestmark = pytest.mark.anyio


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class _Waiting(logging.Handler):
    """Records the transport's "waiting for a Zenoh router" lines."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@pytest.fixture(name="waiting")
def waiting_fixture() -> _Waiting:
    handler = _Waiting()
    logger = logging.getLogger("tfbus.transports.zenoh")
    logger.addHandler(handler)
    yield handler
    logger.removeHandler(handler)


def client(endpoint: str, **kwargs: object) -> ZenohTransport:
    return ZenohTransport(connect=endpoint, config={"mode": "client"}, **kwargs)  # type: ignore[arg-type]


async def test_a_client_started_before_its_router_waits_for_it(waiting: _Waiting) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    tf = TransformStamped(Header(Time(5), "map"), "robot",
                          Transform(Vector3(1.0, 2.0, 3.0), Quaternion()))
    opened = anyio.Event()
    found: list[float] = []

    async def listener_side() -> None:
        async with Bus(transport=client(endpoint, name="early")) as bus:
            buffer = Buffer()
            async with TransformListener(buffer, bus):
                opened.set()
                t = await buffer.lookup_transform_async("map", "robot", Time(5), timeout=20.0)
                found.append(t.transform.translation.z)

    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            tg.start_soon(listener_side)
            while not waiting.lines:  # it said what it waits for, and is still waiting
                await anyio.sleep(0.05)
            assert not opened.is_set()
            assert (f"waiting for a Zenoh router or peer at {endpoint} (is `tfbus router`"
                    " running?)") in waiting.lines[0]
            async with ZenohRouter(listen=endpoint):
                await opened.wait()
                async with Bus(transport=client(endpoint, name="late")) as bus:
                    # latched: reaches the early client whenever its subscription is up
                    await StaticTransformBroadcaster(bus).send_transform(tf)
                    while not found:
                        await anyio.sleep(0.05)
    assert found == [3.0]
    assert len(waiting.lines) <= 3  # once every few seconds, not once per retry


async def test_connect_timeout_bounds_the_wait() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with anyio.fail_after(30):
        with pytest.raises(TransportError) as info:
            async with Bus(transport=client(endpoint, connect_timeout=0.5)):
                pass  # pragma: no cover - never opens
    assert "no Zenoh router or peer answered within 0.5 s (connect_timeout)" in str(info.value)
    assert "Unable to connect to any of" in str(info.value)


async def test_a_waiting_client_is_cancelled_at_once() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with anyio.fail_after(30):
        with anyio.move_on_after(1.0) as scope:
            async with Bus(transport=client(endpoint)):
                pass  # pragma: no cover - never opens
    assert scope.cancelled_caught


async def test_a_peer_without_its_endpoint_still_opens_at_once(waiting: _Waiting) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with anyio.fail_after(30):
        async with Bus(transport=ZenohTransport(connect=endpoint, connect_timeout=0)):
            pass
    assert waiting.lines == []


def test_connect_timeout_in_a_bus_spec() -> None:
    port = free_port()
    transport = open_transport(parse_bus_spec(
        f"zenoh:mode=client&connect=tcp/127.0.0.1:{port}&connect_timeout=2.5"))
    assert isinstance(transport, ZenohTransport)
    assert transport._connect_timeout == 2.5
    for bad in ("nan", "inf", "-1", "soon"):
        with pytest.raises(ValueError, match=f"connect_timeout must be finite seconds >= 0, "
                                             f"got '{bad}'"):
            open_transport(parse_bus_spec(f"zenoh:connect_timeout={bad}"))
    with pytest.raises(ValueError, match="connect_timeout must be None or finite"):
        ZenohTransport(connect_timeout=-1.0)
