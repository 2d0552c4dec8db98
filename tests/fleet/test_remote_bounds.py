"""BufferServer holds against any querier: every wait bounded, slots freed when the querier
goes, a per-querier share, frame ids bounded (Zenoh router on 127.0.0.1).

The server's buffer runs on a ManualClock: a server-clock timeout happens when the test
advances it. The queriers are real Zenoh sessions (clients of the router): tfbus's
BufferClient, a raw ``session.get`` as any Zenoh program sends it, and a BufferClient in a
child process that is SIGKILLed. Every wait is bounded (anyio.fail_after / Proc.expect).
"""

from __future__ import annotations

import sys
import textwrap
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")

from fleet_procs import Proc  # noqa: E402
from test_remote import client_bus, free_port, ts, wait_until  # noqa: E402

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.clock import ManualClock  # noqa: E402
from tfbus.codecs.native import WireCodec  # noqa: E402
from tfbus.errors import (  # noqa: E402
    InvalidArgumentException,
    LookupException,
    TransformException,
)
from tfbus.remote import MAX_FRAME_ID_BYTES, BufferClient, BufferServer  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio


@dataclass
class Setup:
    endpoint: str
    buffer: Buffer
    clock: ManualClock
    server: BufferServer
    client: BufferClient
    client_bus: Bus


@asynccontextmanager
async def served(**server_options: Any) -> AsyncIterator[Setup]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    clock = ManualClock(Time(100))
    buffer = Buffer(cache_time=10.0, clock=clock)
    buffer.set_transform_static(ts("world", "base", 0, 1.0), "test")
    async with (
        ZenohRouter(listen=endpoint),
        client_bus(endpoint, name="server") as sbus,
        client_bus(endpoint, name="thin", topics=()) as cbus,
        BufferServer(buffer, sbus, **server_options) as server,
    ):
        client = BufferClient(cbus, timeout_padding=5.0)
        with anyio.fail_after(10):
            while not await client.can_transform("world", "base", Time(0), 0.0):
                await anyio.sleep(0.05)
        yield Setup(endpoint, buffer, clock, server, client, cbus)


def raw_config(endpoint: str) -> Any:
    """A plain Zenoh client session's config: the router only, no scouting."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    return config


async def _answered(client: BufferClient) -> None:
    t = await client.lookup_transform("world", "base", Time(0), timeout=0.0)
    assert t.transform.translation.x == 1.0


async def test_a_lookup_without_timeout_waits_max_wait_of_the_server_clock() -> None:
    """timeout None (wait forever, before: the slot was held for good) waits max_wait
    seconds of the buffer's clock, then is answered with the lookup's own error."""
    async with served(max_wait=5.0) as s:
        outcome: list[BaseException] = []

        async def ask() -> None:
            try:
                await s.client.lookup_transform("world", "ghost", Time(0), timeout=None)
            except TransformException as exc:
                outcome.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(ask)
            await wait_until(lambda: s.buffer.pending_waits == 1)
            await s.clock.advance(4.9)
            await anyio.sleep(0.05)
            assert not outcome and s.server.statistics().pending == 1
            await s.clock.advance(0.2)
        assert type(outcome[0]) is LookupException
        assert "ghost" in str(outcome[0])
        assert s.server.statistics().pending == 0


async def test_a_querier_whose_query_expires_frees_its_slot() -> None:
    """A raw Zenoh querier asks a lookup that never comes (timeout None) and gives up
    after 0.5 s; the server's only slot (max_pending=1) is free again once the querier's
    query_timeout has passed; a querier that sends no query_timeout is bounded by
    max_wait wall seconds (here 2 s, the server's clock standing still). Before: the
    slot stayed taken and every later lookup was refused as busy."""
    async with served(max_pending=1, max_per_peer=1, max_wait=2.0) as s:
        raw = zenoh.open(raw_config(s.endpoint))
        try:
            codec = WireCodec()
            for extra in ({"query_timeout": 0.5}, {}):
                request = {"op": "lookup", "target": "world", "source": "ghost", "time": 0,
                           "timeout": None, **extra}
                payload = codec.encode(request, sender=1, seq=1)
                await anyio.to_thread.run_sync(
                    lambda p=payload: list(raw.get(s.server.where, payload=p, timeout=0.5)))
                await wait_until(lambda: s.server.statistics().pending == 0, timeout=20)
                await _answered(s.client)
            assert s.server.statistics().busy == 0
        finally:
            raw.close()


async def test_a_cancelled_client_lookup_frees_its_server_slot() -> None:
    """5 lookup_transform(..., timeout=None) cancelled by move_on_after: the server's 5
    waits end at once (before: they held 5 slots for good)."""
    async with served() as s:
        with anyio.move_on_after(30) as scope:
            async with anyio.create_task_group() as tg:
                for _ in range(5):
                    tg.start_soon(s.client.lookup_transform, "world", "ghost", Time(0), None)
                await wait_until(lambda: s.buffer.pending_waits == 5, timeout=20)
                scope.cancel()
        await wait_until(lambda: s.buffer.pending_waits == 0, timeout=20)
        stats = s.server.statistics()
        assert (stats.pending, stats.cancelled) == (0, 5)
        await _answered(s.client)


CHILD = """
import sys, anyio
from tfbus import Bus, Time
from tfbus.remote import BufferClient
from tfbus.transports.zenoh import ZenohTransport

async def main():
    transport = ZenohTransport(connect=sys.argv[1], config={"mode": "client"}, topics=())
    async with Bus(transport=transport) as bus:
        client = BufferClient(bus)
        async with anyio.create_task_group() as tg:
            for _ in range(3):
                tg.start_soon(client.lookup_transform, "world", "ghost", Time(0), None)
            print("asked", flush=True)

anyio.run(main)
"""


async def test_a_querier_whose_process_dies_frees_its_slots() -> None:
    """A BufferClient in another process asks 3 lookups that never come and is
    SIGKILLed: Zenoh deletes its session's liveliness tokens, and the server ends the 3
    waits (before: they held their slots for good)."""
    async with served() as s:
        child = Proc(argv=[sys.executable, "-c", textwrap.dedent(CHILD), s.endpoint])
        try:
            await anyio.to_thread.run_sync(lambda: child.expect(lambda line: line == "asked"))
            await wait_until(lambda: s.buffer.pending_waits == 3, timeout=30)
            child.kill()
            await wait_until(lambda: s.buffer.pending_waits == 0, timeout=20)
        finally:
            child.kill()
        stats = s.server.statistics()
        assert (stats.pending, stats.cancelled) == (0, 3)
        await _answered(s.client)


async def test_one_querier_cannot_take_every_slot() -> None:
    """max_pending=8, so 2 per querier: one querier's 8 waiting lookups get 2 slots, 6
    are refused at once (busy, counted); another querier is still answered. Before: the
    first took all 8 and the other was refused."""
    async with served(max_pending=8) as s, \
            client_bus(s.endpoint, name="greedy", topics=()) as gbus:
        greedy = BufferClient(gbus, timeout_padding=5.0)
        refused: list[str] = []

        async def ask() -> None:
            try:
                await greedy.lookup_transform("world", "ghost", Time(0), timeout=None)
            except TransformException as exc:
                refused.append(str(exc))

        async with anyio.create_task_group() as tg:
            for _ in range(8):
                tg.start_soon(ask)
            await wait_until(lambda: len(refused) == 6 and s.buffer.pending_waits == 2,
                             timeout=20)
            assert refused == [
                "buffer server busy: 2 lookups of this querier waiting (max_per_peer)"
            ] * 6
            await _answered(s.client)  # another querier
            tg.cancel_scope.cancel()
        await wait_until(lambda: s.server.statistics().pending == 0, timeout=20)
        assert s.server.statistics().busy == 6


async def test_frame_ids_longer_than_the_bound_are_refused() -> None:
    """A 5 kB frame id is answered at once with an InvalidArgumentException naming the
    field (before: it waited, holding its frame id), a 100 kB one with the request's
    size; one of MAX_FRAME_ID_BYTES is looked up as usual."""
    async with served() as s:
        with pytest.raises(InvalidArgumentException) as err:
            await s.client.lookup_transform("world", "g" * 5000, Time(0), timeout=None)
        assert str(err.value) == (
            f"request field 'source' is a frame id of 5000 bytes, longer than "
            f"{MAX_FRAME_ID_BYTES}")
        with pytest.raises(InvalidArgumentException, match="'fixed' is a frame id of 1025"):
            await s.client.lookup_transform_full("world", Time(0), "base", Time(0),
                                                 "é" * 512 + "f", timeout=None)
        with pytest.raises(InvalidArgumentException,
                           match=r"^request of 100\d\d\d bytes, longer than 16384$"):
            await s.client.lookup_transform("world", "g" * 100_000, Time(0), timeout=None)
        with pytest.raises(LookupException):
            await s.client.lookup_transform("world", "g" * MAX_FRAME_ID_BYTES, Time(0), 0.0)
        assert s.server.statistics().pending == 0


async def test_serve_buffer_bounds_every_wait() -> None:
    """``tfbus serve-buffer --max-wait 2`` (a child process, Zenoh client of the router):
    a lookup of a frame that never comes with timeout None is answered with the lookup's
    error after 2 s of the server's clock (before: the option did not exist, and the
    lookup waited for ever); the summary counts the busy and cancelled lookups."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with ZenohRouter(listen=endpoint), \
            client_bus(endpoint, name="thin", topics=()) as cbus:
        server = Proc("serve-buffer", "--bus", f"zenoh:mode=client&connect={endpoint}",
                      "--max-wait", "2", "--max-pending", "4")
        try:
            await anyio.to_thread.run_sync(lambda: server.expect(
                lambda line: "buffer server on" in line))
            client = BufferClient(cbus, timeout_padding=5.0)
            with anyio.fail_after(60):
                while True:  # the queryable reaches this client through the router
                    try:
                        await client.lookup_transform("world", "ghost", Time(0), timeout=None)
                    except LookupException as exc:
                        assert str(exc) == ('"world" passed to lookupTransform argument '
                                            'target_frame does not exist. ')
                        break
                    except TransformException as exc:
                        assert str(exc).startswith("no answer from buffer server")
                        await anyio.sleep(0.1)
            assert server.stop() == 0
            lines = await anyio.to_thread.run_sync(server.rest)
            assert any(line.startswith("[ INFO] summary: ") and
                       line.endswith(" 0 malformed, 0 busy, 0 cancelled") for line in lines)
        finally:
            server.kill()
