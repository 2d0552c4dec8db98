"""tfbus.remote: BufferServer / BufferClient through a Zenoh router on 127.0.0.1.

The router is Zenoh's own (a session in router mode, tfbus.transports.zenoh.router); the
server and the client are Zenoh clients of it. Timeouts are on the server's clock: the
server's buffer runs on a ManualClock, so a timeout happens when the test advances it.
Every wait is bounded (anyio.fail_after).
"""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.clock import ManualClock  # noqa: E402
from tfbus.codecs.native import WireCodec  # noqa: E402
from tfbus.core.policy import (  # noqa: E402
    Clamp,
    ExpireAfter,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
    expire_after,
)
from tfbus.errors import (  # noqa: E402
    BackwardExtrapolationException,
    ConnectivityException,
    ForwardExtrapolationException,
    InvalidArgumentException,
    LookupException,
    NoDataForExtrapolationException,
    TimeoutException,
    TransformException,
)
from tfbus.messages import (  # noqa: E402
    Header,
    Point,
    PointStamped,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.remote import BufferClient, BufferServer  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.ros1.action import LookupActionClient  # noqa: E402
from tfbus.transports.zenoh import ZenohTransport  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio

NS = 1_000_000_000


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ts(parent: str, child: str, sec: float, x: float) -> TransformStamped:
    return TransformStamped(
        Header(Time(sec), parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


def client_bus(endpoint: str, **kw: object) -> Bus:
    return Bus(transport=ZenohTransport(connect=endpoint, config={"mode": "client"}, **kw))


async def wait_until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.01)


@dataclass
class Setup:
    buffer: Buffer
    clock: ManualClock
    server: BufferServer
    client: BufferClient
    client_bus: Bus


@asynccontextmanager
async def served(cache_policy: ExpireAfter | None = None) -> AsyncIterator[Setup]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    clock = ManualClock(Time(100))
    buffer = Buffer(cache_time=10.0, clock=clock, cache_policy=cache_policy)
    buffer.set_transform(ts("world", "base", 10, 1.0), "test")
    buffer.set_transform(ts("world", "base", 12, 3.0), "test")
    buffer.set_transform_static(ts("base", "laser", 0, 0.5), "test")
    async with (
        ZenohRouter(listen=endpoint),
        client_bus(endpoint, name="server") as sbus,
        client_bus(endpoint, name="thin", topics=()) as cbus,
        BufferServer(buffer, sbus) as server,
    ):
        client = BufferClient(cbus, timeout_padding=5.0)
        # the queryable reaches the client through the router: wait for one answer
        with anyio.fail_after(10):
            while not await client.can_transform("world", "base", Time(0), 0.0):
                await anyio.sleep(0.05)
        yield Setup(buffer, clock, server, client, cbus)


async def test_lookups_answer_as_the_server_buffer() -> None:
    async with served() as s:
        t = await s.client.lookup_transform("world", "laser", Time(11), timeout=1.0)
        assert t.header.frame_id == "world" and t.child_frame_id == "laser"
        assert t.header.stamp == Time(11)
        assert t.transform.translation.x == pytest.approx(2.5)  # 2.0 interpolated + 0.5
        local = s.buffer.lookup_transform("world", "laser", Time(11))
        assert t == local
        full = await s.client.lookup_transform_full(
            "laser", Time(12), "laser", Time(10), "world", timeout=0.0
        )
        assert full.transform.translation.x == pytest.approx(-2.0)  # base moved +2 m
        assert await s.client.can_transform("world", "laser", Time(0), 0.0) is True
        assert await s.client.can_transform("world", "nowhere", Time(0), 0.0) is False
        p = await s.client.transform(
            PointStamped(Header(Time(12), "laser"), Point(1.0, 2.0, 3.0)), "world", 0.0
        )
        assert p.header.frame_id == "world" and p.point == Point(4.5, 2.0, 3.0)
        assert s.server.statistics().answered >= 5


async def test_a_lookup_without_await_names_the_missing_await() -> None:
    """tf2_ros's ``BufferClient.lookup_transform`` blocks; here the call without ``await``
    says so at the result's first use, and awaiting the same call answers."""
    async with served() as s:
        pending = s.client.lookup_transform("world", "laser", Time(11), timeout=1.0)
        with pytest.raises(
            AttributeError,
            match=r"BufferClient\.lookup_transform\(\.\.\.\) is a coroutine: write "
            r"`await buffer_client\.lookup_transform\(\.\.\.\)`.*'transform'",
        ):
            pending.transform  # noqa: B018
        asked = s.client.can_transform("world", "laser", Time(0), 0.0)
        with pytest.raises(TypeError, match=r"BufferClient\.can_transform\(\.\.\.\) is a coro"):
            bool(asked)
        asked.close()  # dropped on purpose: no warning
        assert (await pending).transform.translation.x == pytest.approx(2.5)


async def test_errors_come_back_as_the_same_tf2_classes_and_messages() -> None:
    async with served() as s:
        s.buffer.set_transform_static(ts("island", "palm", 0, 1.0), "test")
        cases = [
            (("world", "ghost", Time(0)), LookupException),
            (("world", "palm", Time(0)), ConnectivityException),
            (("world", "base", Time(50)), ForwardExtrapolationException),
            (("", "base", Time(0)), InvalidArgumentException),
        ]
        for args, cls in cases:
            with pytest.raises(cls) as local:
                s.buffer.lookup_transform(*args)
            with pytest.raises(cls) as remote:
                await s.client.lookup_transform(*args, timeout=0.0)
            assert type(remote.value) is cls
            assert str(remote.value) == str(local.value)


async def test_a_frame_the_servers_buffer_expired_is_unknown_to_remote_lookups() -> None:
    """The server's buffer forgets 'cup' (expire_after 5 s: its newest, 12 s, is older
    than 20 - 5); the client gets tf2's LookupException, as the server's own lookup."""
    async with served(cache_policy=expire_after(5.0)) as s:
        s.buffer.set_transform(ts("world", "cup", 12, 4.0), "test")
        t = await s.client.lookup_transform("world", "cup", Time(12), timeout=0.0)
        assert t.transform.translation.x == 4.0
        s.buffer.set_transform(ts("world", "base", 20, 5.0), "test")
        assert s.buffer.statistics().frames_expired == 1
        with pytest.raises(LookupException) as local:
            s.buffer.lookup_transform("world", "cup", Time(12))
        with pytest.raises(LookupException) as remote:
            await s.client.lookup_transform("world", "cup", Time(12), timeout=0.0)
        assert type(remote.value) is LookupException
        assert str(remote.value) == str(local.value)
        assert "cup" in str(remote.value)
        assert await s.client.can_transform("world", "cup", Time(0), 0.0) is False
        got = await s.client.lookup_transform("world", "laser", Time(20), timeout=0.0)
        assert got.transform.translation.x == 5.5  # base's link is kept


async def test_timeouts_run_on_the_servers_clock() -> None:
    async with served() as s:
        outcome: list[BaseException] = []

        async def ask() -> None:
            try:
                await s.client.lookup_transform("world", "ghost", Time(0), timeout=3.0)
            except LookupException as exc:
                outcome.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await wait_until(lambda: s.buffer.pending_waits == 1)
            await s.clock.advance(2.9)
            await anyio.sleep(0.05)
            assert not outcome and s.buffer.pending_waits == 1
            await s.clock.advance(0.2)
        # tf2_ros buffer_server: the expired goal is answered with lookupTransform's error
        assert len(outcome) == 1 and type(outcome[0]) is LookupException
        assert str(outcome[0]) == (
            '"ghost" passed to lookupTransform argument source_frame does not exist. '
        )


async def test_a_waiting_lookup_resumes_when_the_data_arrives() -> None:
    async with served() as s:
        result: list[TransformStamped] = []

        async def ask() -> None:
            result.append(await s.client.lookup_transform("world", "arm", Time(0), timeout=60))

        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await wait_until(lambda: s.buffer.pending_waits == 1)
            s.buffer.set_transform(ts("base", "arm", 12, 0.25), "test")
        assert result[0].transform.translation.x == pytest.approx(3.25)


async def test_bad_requests_are_counted_and_named() -> None:
    async with served() as s:
        session = s.client_bus.transport.session  # type: ignore[union-attr]
        key = s.server.where
        # not a tfbus payload: counted, left unanswered
        replies = await anyio.to_thread.run_sync(
            lambda: list(session.get(key, payload=b"\x00garbage", timeout=3.0))
        )
        assert [r for r in replies if r.ok is not None] == []
        await wait_until(lambda: s.server.statistics().malformed == 1)
        # a tfbus map with a bad field: an InvalidArgumentException naming it
        codec = WireCodec()
        bad = codec.encode({"op": "lookup", "target": "world", "source": 7, "time": 0,
                            "timeout": 0.0}, sender=1, seq=1)
        replies = await anyio.to_thread.run_sync(
            lambda: list(session.get(key, payload=bad, timeout=3.0))
        )
        answer = codec.decode(replies[0].ok.payload.to_bytes()).message
        assert answer == {"error": "InvalidArgumentException",
                          "message": "request field 'source' has an invalid value 7"}
        # the server goes on answering
        t = await s.client.lookup_transform("world", "base", Time(0), timeout=0.0)
        assert t.transform.translation.x == pytest.approx(3.0)


async def test_client_needs_a_transport_with_lookups_and_a_server() -> None:
    with pytest.raises(TypeError, match="this bus has no transport"):
        BufferClient(Bus())
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with ZenohRouter(listen=endpoint), client_bus(endpoint, topics=()) as bus:
        client = BufferClient(bus, timeout_padding=0.2)
        with pytest.raises(TimeoutException, match="no answer from buffer server"):
            await client.lookup_transform("world", "base", Time(0), timeout=0.0)


async def test_requests_over_max_pending_are_refused_and_counted() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    clock = ManualClock(Time(100))
    buffer = Buffer(clock=clock)
    buffer.set_transform_static(ts("world", "base", 0, 1.0), "test")
    async with (
        ZenohRouter(listen=endpoint),
        client_bus(endpoint, name="server") as sbus,
        client_bus(endpoint, name="thin", topics=()) as cbus,
        BufferServer(buffer, sbus, max_pending=1) as server,
    ):
        client = BufferClient(cbus, timeout_padding=5.0)
        with anyio.fail_after(10):
            while not await client.can_transform("world", "base", Time(0), 0.0):
                await anyio.sleep(0.05)
        outcome: list[BaseException] = []

        async def ask() -> None:
            try:
                await client.lookup_transform("world", "ghost", Time(0), timeout=5.0)
            except TransformException as exc:
                outcome.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await wait_until(lambda: buffer.pending_waits == 1)
            with pytest.raises(TransformException,
                               match=r"^buffer server busy: 1 lookups waiting \(max_pending\)$"):
                await client.lookup_transform("world", "base", Time(0), timeout=0.0)
            assert server.statistics().busy == 1
            await clock.advance(5.0)
        assert type(outcome[0]) is LookupException
        # the slot is free again
        t = await client.lookup_transform("world", "base", Time(0), timeout=0.0)
        assert t.transform.translation.x == 1.0


# ---------------------------------------------------------------------- fail_fast
# The request carries "fail_fast": true; the server answers with the exception its
# Buffer raises (same class and message). ROS 1's tf2_msgs/LookupTransform goal has no
# such field: its client refuses fail_fast=True.


async def test_fail_fast_travels_to_the_server_and_its_error_comes_back() -> None:
    async with served() as s:
        # world -> base: 10, 12 s, then 23 s (cache 10 s: only 23 s is kept, nothing
        # before 13 s is accepted any more); base -> arm: 12 s. At 11 s the path's latest
        # common time (12 s) keeps a plain wait waiting, but base's link never answers.
        s.buffer.set_transform(ts("base", "arm", 12, 0.5), "test")
        s.buffer.set_transform(ts("world", "base", 23, 5.0), "test")
        s.buffer.set_transform_static(ts("island", "palm", 0, 1.0), "test")
        with pytest.raises(BackwardExtrapolationException) as local:
            await s.buffer.lookup_transform_async("world", "arm", Time(11), 30.0,
                                                  fail_fast=True)
        with pytest.raises(BackwardExtrapolationException) as remote:
            await s.client.lookup_transform("world", "arm", Time(11), timeout=30.0,
                                            fail_fast=True)
        assert str(remote.value) == str(local.value) == (
            "Lookup would require extrapolation at time 11.000000000, but only time "
            "23.000000000 is in the buffer, when looking up transform from frame [arm] to "
            "frame [world]"
        )
        with pytest.raises(ConnectivityException):
            await s.client.lookup_transform_full("world", Time(11), "palm", Time(11),
                                                 "world", timeout=30.0, fail_fast=True)
        assert await s.client.can_transform("world", "palm", Time(11), 30.0,
                                            fail_fast=True) is False
        with pytest.raises(BackwardExtrapolationException):
            await s.client.transform(PointStamped(Header(Time(11), "arm"), Point()), "world",
                                     30.0, fail_fast=True)
        assert s.clock.now() == Time(100) and s.buffer.pending_waits == 0
        # Without fail_fast the server waits on its clock, then answers with the
        # lookup's own error (tf2_ros buffer_server).
        outcome: list[BaseException] = []

        async def ask() -> None:
            try:
                await s.client.lookup_transform("world", "arm", Time(11), timeout=30.0)
            except TransformException as exc:
                outcome.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await wait_until(lambda: s.buffer.pending_waits == 1)
            await anyio.sleep(0.05)
            assert not outcome
            await s.clock.advance(30.0)
        assert type(outcome[0]) is NoDataForExtrapolationException


async def test_a_fail_fast_field_that_is_not_a_bool_is_named() -> None:
    async with served() as s:
        session = s.client_bus.transport.session  # type: ignore[union-attr]
        codec = WireCodec()
        bad = codec.encode({"op": "lookup", "target": "world", "source": "base", "time": 0,
                            "timeout": 0.0, "fail_fast": "yes"}, sender=1, seq=1)
        replies = await anyio.to_thread.run_sync(
            lambda: list(session.get(s.server.where, payload=bad, timeout=3.0))
        )
        answer = codec.decode(replies[0].ok.payload.to_bytes()).message
        assert answer == {"error": "InvalidArgumentException",
                          "message": "request field 'fail_fast' has an invalid value 'yes'"}


async def test_the_ros1_action_client_refuses_fail_fast() -> None:
    client = LookupActionClient.__new__(LookupActionClient)  # no ROS 1 node: refused first
    with pytest.raises(ValueError, match="tf2_msgs/LookupTransform action's goal has no"):
        await client.lookup_transform("world", "base", Time(13), 1.0, fail_fast=True)


async def test_a_lookup_policy_crosses_the_wire() -> None:
    """Clamp, Previous and Nearest asked remotely: the server's PolicyResult (transform
    and report), equal to its local answer; a failure is the same tf2 class and message."""
    async with served() as s:
        cases = [
            (Time(13), Clamp(2.0), 3.5, (13 * NS, 12 * NS)),  # base's 12 s sample held
            (Time(11), Previous(), 1.5, (11 * NS, 10 * NS)),  # base's 10 s sample
            (Time(11.2), Nearest(0.5), 2.7, (11_200_000_000, 11_200_000_000)),  # tf2's
        ]
        for at, policy, x, stamps in cases:
            remote = await s.client.lookup_transform("world", "laser", at, 1.0, policy=policy)
            local = s.buffer.lookup_transform("world", "laser", at, policy=policy)
            assert type(remote) is PolicyResult and type(remote.report) is PolicyReport
            assert remote == local
            assert remote.transform.transform.translation.x == pytest.approx(x)
            assert remote.report.frames == ("laser", "base")
            assert remote.report.stamps_ns == stamps
        with pytest.raises(ForwardExtrapolationException) as local_error:
            s.buffer.lookup_transform("world", "laser", Time(50), policy=Nearest(0.5))
        with pytest.raises(ForwardExtrapolationException) as remote_error:
            await s.client.lookup_transform("world", "laser", Time(50), 0.0, policy=Nearest(0.5))
        assert str(remote_error.value) == str(local_error.value)


async def test_a_remote_window_waits_on_the_servers_clock() -> None:
    """Window(0.5, 2.0) at 13 s (1 s after base's newest sample): the server waits for
    data at 13 s; a sample at 14 s (x 5) answers it, interpolated (x 4 + 0.5)."""
    async with served() as s:
        got: list[PolicyResult] = []

        async def ask() -> None:
            got.append(
                await s.client.lookup_transform(
                    "world", "laser", Time(13), 5.0, policy=Window(0.5, 2.0)
                )
            )

        with anyio.fail_after(10):
            async with anyio.create_task_group() as tg:
                tg.start_soon(ask)
                await wait_until(lambda: s.buffer.pending_waits == 1)
                s.buffer.set_transform(ts("world", "base", 14, 5.0), "test")
        assert got[0].transform.transform.translation.x == pytest.approx(4.5)
        assert got[0].report.exact


async def test_a_bad_policy_field_is_named() -> None:
    async with served() as s:
        session = s.client_bus.transport.session  # type: ignore[union-attr]
        codec = WireCodec()
        for policy in (["sideways", 0, 0], ["nearest", -1, 0], ["clamp", 1], "nearest"):
            bad = codec.encode({"op": "lookup", "target": "world", "source": "base",
                                "time": 0, "timeout": 0.0, "policy": policy},
                               sender=1, seq=1)
            replies = await anyio.to_thread.run_sync(
                lambda bad=bad: list(session.get(s.server.where, payload=bad, timeout=3.0))
            )
            answer = codec.decode(replies[0].ok.payload.to_bytes()).message
            assert answer == {"error": "InvalidArgumentException",
                              "message": f"request field 'policy' has an invalid value {policy!r}"}
        t = await s.client.lookup_transform("world", "base", Time(0), timeout=0.0)
        assert t.transform.translation.x == pytest.approx(3.0)


async def test_can_full_and_transform_carry_the_policy() -> None:
    """can_transform, lookup_transform_full and transform with a policy answer as the
    server's buffer does under it (base: x 1 at 10 s, x 3 at 12 s; laser static x 0.5)."""
    async with served() as s:
        assert await s.client.can_transform("world", "laser", Time(13), 0.0) is False
        assert await s.client.can_transform(
            "world", "laser", Time(13), 0.0, policy=Clamp(1.5)) is True
        assert await s.client.can_transform(
            "world", "laser", Time(13), 0.0, policy=Nearest(0.5)) is False
        found = await s.client.lookup_transform_full(
            "laser", Time(13), "laser", Time(10), "world", 0.0, policy=Previous())
        local = s.buffer.lookup_transform_full(
            "laser", Time(13), "laser", Time(10), "world", policy=Previous())
        assert isinstance(found, PolicyResult) and found == local
        assert found.transform.transform.translation.x == pytest.approx(-2.0)
        assert found.report.max_abs_delta_ns == NS
        p = PointStamped(Header(Time(13), "laser"), Point(1.0, 0.0, 0.0))
        moved, report = await s.client.transform(p, "world", 0.0, policy=Clamp(1.5))
        assert moved.point == Point(4.5, 0.0, 0.0) and moved.header.stamp == Time(13)
        assert report == s.buffer.lookup_transform(
            "world", "laser", Time(13), policy=Clamp(1.5)).report
        with pytest.raises(ForwardExtrapolationException) as remote:
            await s.client.lookup_transform_full(
                "laser", Time(20), "laser", Time(10), "world", 0.0, policy=Nearest(0.5))
        assert "into the future" in str(remote.value)
