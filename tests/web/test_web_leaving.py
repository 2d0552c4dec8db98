"""``tfbus web`` while clients leave in every way, on asyncio and trio: a close handshake
mid-stream (dozens at once), an aborted connection, a half-open one, one that never
reads, one closing while its ``call_service`` or action goal is answered. A client that
subscribed and is still here keeps getting ``/tf``; a message for a closing or closed
connection is dropped and counted (``TfWebServer.dropped_closed``); no connection ends
or stalls the server."""

from __future__ import annotations

import contextlib
import socket
import struct

import anyio
import pytest
from web_support import RawClient, Served, served, ts
from wsproto.events import CloseConnection

from tfbus.messages import TFMessage

pytestmark = pytest.mark.anyio


async def _subscribed(w: Served, client: RawClient, n: int) -> None:
    await client.send({"op": "subscribe", "topic": "/tf"})
    await w.until(lambda: sum("/tf" in c.session.subscriptions for c in w.server.clients) >= n)


async def _keeps_serving(w: Served, keeper: RawClient, x: float) -> None:
    """``keeper`` (subscribed to /tf) receives a transform published now."""
    w.move(x)
    m = await keeper.receive_until(
        lambda m: m.get("topic") == "/tf"
        and m["msg"]["transforms"][0]["transform"]["translation"]["x"] == x)
    assert m["op"] == "publish"


async def _stream_tf(w: Served, count: int) -> None:
    """Publish ``count`` transforms, one a loop pass (a checkpoint between them)."""
    for i in range(count):
        w.move(0.001 * i)
        await anyio.sleep(0)


async def _close_handshake(client: RawClient) -> None:
    """Send a Close frame and read until the server's Close answers it (RFC 6455 5.5.1)."""
    await client.stream.send(client.ws.send(CloseConnection(code=1000)))
    with anyio.fail_after(60):
        while not client.closed:
            try:
                await client.receive(60)
            except anyio.EndOfStream:
                break


async def test_dozens_of_close_handshakes_mid_stream_leave_the_server_serving() -> None:
    async with served() as w, RawClient.connect(w.server.port) as keeper:
        await _subscribed(w, keeper, 1)
        for rounds in range(3):
            async with contextlib.AsyncExitStack() as stack:
                leavers = [await stack.enter_async_context(RawClient.connect(w.server.port))
                           for _ in range(30)]
                for k, c in enumerate(leavers, start=2):
                    await _subscribed(w, c, k)
                async with anyio.create_task_group() as tg:
                    tg.start_soon(_stream_tf, w, 400)
                    for c in leavers:
                        tg.start_soon(_close_handshake, c)
            await w.until(lambda: len(w.server.clients) == 1)
            await _keeps_serving(w, keeper, 100.0 + rounds)
        assert w.server.errors == 0


async def test_abort_half_open_and_never_reading_harm_no_other() -> None:
    async with served(send_timeout=2.0, queue_size=16) as w, \
            RawClient.connect(w.server.port) as keeper:
        await _subscribed(w, keeper, 1)
        async with RawClient.connect(w.server.port) as aborted, \
                RawClient.connect(w.server.port) as half_open, \
                RawClient.connect(w.server.port) as never_reads:
            for k, c in enumerate((aborted, half_open, never_reads), start=2):
                await _subscribed(w, c, k)
            # An abort: RST (SO_LINGER 0) while transforms flow.
            sock = aborted.stream.extra(anyio.abc.SocketAttribute.raw_socket)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            async with anyio.create_task_group() as tg:
                tg.start_soon(_stream_tf, w, 200)
                await aborted.stream.aclose()
            # Half-open: the client shuts its sending side and keeps reading nothing.
            await half_open.stream.send_eof()
            await _stream_tf(w, 200)
            await _keeps_serving(w, keeper, 7.0)
            await w.until(lambda: len(w.server.clients) <= 3)
            # never_reads is still subscribed: big messages fill its socket, then its
            # queue (bounded: the oldest dropped, counted) while the keeper is served.
            names = [f"frame_{i:04d}_" + "x" * 200 for i in range(300)]
            for i in range(1, 200):
                w.stamp += 1_000_000
                w.bus.publish_nowait("/tf", TFMessage(
                    [ts(float(i), w.stamp, child=n) for n in names]))
                await _keeps_serving(w, keeper, 1000.0 + i)
                if any(c.dropped for c in w.server.clients):
                    break
            (full,) = [c for c in w.server.clients if c.dropped]
            assert len(full.outbox) == 16
            # It now sends a Close without reading: what it had queued is never sent.
            await never_reads.stream.send(never_reads.ws.send(CloseConnection(code=1000)))
            await w.until(lambda: full not in w.server.clients)
            await w.until(lambda: w.server.dropped_closed >= 15)
        await w.until(lambda: len(w.server.clients) == 1)
        await _keeps_serving(w, keeper, 9.0)
        assert w.server.errors <= 2  # the abort and the half-open (or a timeout)


async def test_close_while_a_service_call_or_goal_is_answered() -> None:
    async with served() as w, RawClient.connect(w.server.port) as keeper:
        await _subscribed(w, keeper, 1)
        w.move(1.0)
        for op in (
            {"op": "call_service", "service": "/republish_tfs", "id": "s1",
             "args": {"source_frames": ["base_link"], "target_frame": "world",
                      "angular_thres": 0.0, "trans_thres": 0.0, "rate": 50.0,
                      "timeout": {"secs": 10, "nsecs": 0}}},
            {"op": "send_action_goal", "action": "/tf2_web_republisher",
             "action_type": "tf2_web_republisher_msgs/action/TFSubscription", "id": "g1",
             "args": {"source_frames": ["base_link"], "target_frame": "world",
                      "angular_thres": 0.0, "trans_thres": 0.0, "rate": 50.0}},
        ):
            async with RawClient.connect(w.server.port) as c:
                await c.send(op)
                await _close_handshake(c)
            await _stream_tf(w, 100)
            await w.until(lambda: len(w.server.clients) == 1)
            await _keeps_serving(w, keeper, 2.0)
        assert w.server.errors == 0
