"""The lookup server's queries reach the event loop through one bounded queue and a
ThreadWakeup, and the client's pending lookups hold no thread (Zenoh router on
127.0.0.1, asyncio and trio).

* A flood of queries while the event loop is busy: at most ``max_pending`` wait in the
  queue, the rest are refused at once in Zenoh's thread with the protocol's error reply
  ("buffer server busy: ... (max_queued)") and counted; another querier is answered.
* 50 lookups pending on a server add no OS thread to the client's process (a Zenoh get
  answered through a socket wake-up, not a worker thread per lookup); closing the server
  ends all 50 at once, unanswered.
"""

from __future__ import annotations

import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")

from test_remote import client_bus, free_port, ts, wait_until  # noqa: E402
from test_remote_bounds import raw_config  # noqa: E402

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.clock import ManualClock  # noqa: E402
from tfbus.codecs.native import WireCodec  # noqa: E402
from tfbus.errors import TimeoutException, TransformException  # noqa: E402
from tfbus.remote import BufferClient, BufferServer  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio


@dataclass
class Net:
    endpoint: str
    buffer: Buffer
    server_bus: Bus
    client: BufferClient


@asynccontextmanager
async def network() -> AsyncIterator[Net]:
    """A router, a server's bus and a thin client's bus (the server is the test's)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    buffer = Buffer(cache_time=10.0, clock=ManualClock(Time(100)))
    buffer.set_transform_static(ts("world", "base", 0, 1.0), "test")
    async with (
        ZenohRouter(listen=endpoint),
        client_bus(endpoint, name="server") as sbus,
        client_bus(endpoint, name="thin", topics=()) as cbus,
    ):
        yield Net(endpoint, buffer, sbus, BufferClient(cbus, timeout_padding=5.0))


async def reachable(client: BufferClient) -> None:
    """Wait until the server's queryable reaches the client through the router."""
    with anyio.fail_after(10):
        while not await client.can_transform("world", "base", Time(0), 0.0):
            await anyio.sleep(0.05)


async def test_a_flood_beyond_the_queue_is_refused_in_zenohs_thread_and_counted() -> None:
    """max_pending=8 (so 8 queued queries at most) and max_per_peer=4: a raw
    querier sends 40 lookups that would wait while the event loop is held; 32 are
    refused at once in Zenoh's thread (busy, "max_queued"), the 8 queued are taken once
    the loop runs (4 wait, 4 refused by max_per_peer), and another querier is answered.
    Before: Zenoh's thread handed each admitted query to the loop through a
    BlockingPortal and waited there for the busy loop, so no query was answered nor
    refused until the loop ran."""
    async with network() as net, BufferServer(net.buffer, net.server_bus,
                                              max_pending=8, max_per_peer=4) as server:
        await reachable(net.client)
        raw = zenoh.open(raw_config(net.endpoint))
        replies: list[bytes] = []
        lock = threading.Lock()
        refused_32 = threading.Event()

        def on_reply(reply: Any) -> None:  # the raw session's thread
            if reply.ok is not None:
                with lock:
                    replies.append(reply.ok.payload.to_bytes())
                    if len(replies) == 32:
                        refused_32.set()

        try:
            codec = WireCodec()
            request = {"op": "lookup", "target": "world", "source": "ghost", "time": 0,
                       "timeout": 30.0, "query_timeout": 10.0}
            payload = codec.encode(request, sender=1, seq=1)
            requests_before = server.statistics().requests
            # the event loop is held here (no await) until Zenoh's threads refused 32
            for _ in range(40):
                raw.get(server.where, zenoh.handlers.Callback(on_reply, lambda: None),
                        payload=payload, timeout=30.0)
            assert refused_32.wait(30.0), f"{len(replies)} replies"
            with lock:
                messages = [codec.decode(r).message for r in replies]
            assert messages == [{"error": "TransformException",
                                 "message": "buffer server busy: 8 queries queued "
                                            "(max_queued)"}] * 32
            await wait_until(lambda: net.buffer.pending_waits == 4, timeout=20)
            with anyio.fail_after(20):
                t = await net.client.lookup_transform("world", "base", Time(0), timeout=0.0)
            assert t.transform.translation.x == 1.0
            await wait_until(lambda: len(replies) == 36, timeout=20)
            with lock:
                tail = [codec.decode(r).message for r in replies[32:]]
            assert tail == [{"error": "TransformException",
                             "message": "buffer server busy: 4 lookups of this querier "
                                        "waiting (max_per_peer)"}] * 4
            stats = server.statistics()
            assert stats.requests - requests_before == 41
            assert (stats.busy, stats.pending) == (36, 4)
        finally:
            raw.close()  # type: ignore[no-untyped-call]
        await wait_until(lambda: server.statistics().pending == 0, timeout=40)


async def test_pending_lookups_hold_no_thread_and_end_when_the_server_closes() -> None:
    """50 lookups wait on the server (timeout 30 s): the client's process has no more
    OS threads than before they were asked (before: one worker thread each, at most 40,
    so the other 10 never reached the server). Closing the server ends all 50 at once,
    unanswered: each raises TimeoutException "no answer", far before its 35 s bound."""
    async with network() as net:
        outcomes: list[BaseException] = []

        async def ask() -> None:
            try:
                await net.client.lookup_transform("world", "ghost", Time(0), timeout=30.0)
            except TransformException as exc:
                outcomes.append(exc)

        async with anyio.create_task_group() as tg:
            async with BufferServer(net.buffer, net.server_bus, max_pending=100,
                                    max_per_peer=60) as server:
                await reachable(net.client)
                threads = threading.active_count()
                for _ in range(50):
                    tg.start_soon(ask)
                await wait_until(lambda: net.buffer.pending_waits == 50, timeout=30)
                names = [t.name for t in threading.enumerate()]
                assert threading.active_count() <= threads + 2, names
                assert server.statistics().pending == 50
            with anyio.fail_after(20):
                await wait_until(lambda: len(outcomes) == 50, timeout=20)
        assert {type(e) for e in outcomes} == {TimeoutException}
        assert all(str(e).startswith("no answer from buffer server") for e in outcomes)
        assert server.statistics().pending == 0
        assert net.buffer.pending_waits == 0
