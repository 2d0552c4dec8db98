"""A buffer server and a Zenoh receiver under a burst of mutated input, live on 127.0.0.1.

The lookup server (``BufferServer`` on Zenoh) gets 150 requests built from valid ones:
every field replaced by a hostile value (huge, empty, control characters, wrong types,
negative, 2**63 and beyond, NaN, nested), ops swapped, fields dropped, and the encoded bytes
cut or bit-flipped. Each reply, if any, is a tfbus map (the transform, or an error naming
tf2's exception); undecodable requests are counted as malformed and left unanswered (one
longer than the server takes is answered so);
nothing waits beyond the request's own bound. Then a valid lookup is answered as before.

A Zenoh transport gets 150 mutated ``/tf`` payloads (the same mutations of a valid tfbus
wire message) from a raw zenoh-python publisher, then a valid one: the valid one arrives,
and every payload the codec refuses is counted (malformed, wrong version or over a limit).
The mutations are drawn from a fixed seed: the same burst on every run.
"""

from __future__ import annotations

import math
import random
from typing import Any

import anyio
import pytest

pytest.importorskip("zenoh")

import zenoh
from test_remote import free_port, served, ts

from tfbus.bus import Bus
from tfbus.codecs import native as wire
from tfbus.errors import WireError
from tfbus.messages import TFMessage
from tfbus.time import Time
from tfbus.transports.zenoh import ZenohTransport
from tfbus.transports.zenoh.config import zenoh_config

pytestmark = pytest.mark.anyio

HOSTILE: list[Any] = [
    "", "/", "x" * 100_000, "\x00", "\x1b[2J", "ü/ß", " world", -1, 0, 2**63 - 1, 2**63, 2**64,
    -(2**63), 1e308, -0.0, math.nan, math.inf, None, True, [], {}, [[["deep"]]], {"a": {"b": 1}},
    b"\xff\xfe",
]
VALID: list[dict[str, Any]] = [
    {"op": "lookup", "target": "world", "source": "laser", "time": 11 * 10**9, "timeout": 0.0},
    {"op": "full", "target": "laser", "target_time": 12 * 10**9, "source": "laser",
     "source_time": 10 * 10**9, "fixed": "world", "timeout": 0.0},
    {"op": "can", "target": "world", "source": "base", "time": 0, "timeout": 0.0},
    {"op": "lookup", "target": "world", "source": "base", "time": 0, "timeout": 0.5,
     "policy": [1, 10**9, 0]},
]


def _mutate(rng: random.Random, payload: bytes) -> bytes:
    data = bytearray(payload)
    for _ in range(rng.randint(1, 3)):
        op = rng.choice(["flip", "cut", "extend", "byte"])
        if op == "cut":
            del data[rng.randint(0, len(data)):]
        elif op == "extend":
            data += rng.randbytes(rng.randint(1, 32))
        elif data:
            at = rng.randrange(len(data))
            if op == "flip":
                data[at] ^= 1 << rng.randrange(8)
            else:
                data[at] = rng.choice([0x00, 0x7F, 0x80, 0xC1, 0xFF])
    return bytes(data)


def _requests(rng: random.Random, codec: wire.WireCodec, n: int) -> list[bytes]:
    out: list[bytes] = []
    for i in range(n):
        request = dict(rng.choice(VALID))
        for _ in range(rng.randint(1, 3)):
            what = rng.choice(["replace", "drop", "add", "op"])
            if what == "replace":
                request[rng.choice(sorted(request))] = rng.choice(HOSTILE)
            elif what == "drop" and len(request) > 1:
                del request[rng.choice(sorted(request))]
            elif what == "add":
                request[rng.choice(["fail_fast", "id", "query_timeout", "x"])] = rng.choice(HOSTILE)
            else:
                request["op"] = rng.choice(["lookup", "full", "can", "", "LOOKUP", 7, None])
        try:
            payload = codec.encode(request, sender=3, seq=i + 1)
        except (WireError, TypeError, ValueError, OverflowError):  # refused at the sender
            continue
        out.append(_mutate(rng, payload) if rng.random() < 0.4 else payload)
    return out


async def test_a_burst_of_mutated_requests_leaves_the_server_answering() -> None:
    rng = random.Random(20261125)
    codec = wire.WireCodec()
    async with served() as s:
        session = s.client_bus.transport.session  # type: ignore[union-attr]
        key = s.server.where
        requests = _requests(rng, codec, 150)
        assert len(requests) > 100
        undecodable = 0  # and left unanswered: a too-long request is answered by name
        for payload in requests:
            try:
                codec.decode(payload)
                bad = False
            except WireError:
                bad = True
            replies = await anyio.to_thread.run_sync(
                lambda p=payload: list(session.get(key, payload=p, timeout=5.0)))
            undecodable += bad and not replies
            for reply in replies:
                assert reply.ok is not None, "the server answered with a Zenoh error"
                answer = codec.decode(reply.ok.payload.to_bytes()).message
                assert isinstance(answer, (dict, bool)) or hasattr(answer, "transform"), answer
                if isinstance(answer, dict) and "error" in answer:
                    assert answer["error"].endswith("Exception"), answer
                    assert isinstance(answer["message"], str) and answer["message"]
        assert undecodable > 0
        stats = s.server.statistics()
        assert stats.malformed == undecodable
        t = await s.client.lookup_transform("world", "laser", Time(11), timeout=1.0)
        assert t.transform.translation.x == pytest.approx(2.5)


async def test_a_burst_of_mutated_tf_payloads_is_counted_and_the_valid_one_arrives() -> None:
    rng = random.Random(11)
    port = free_port()
    transport = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="victim",
                               limits=wire.WireLimits(max_transforms=10))
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    codec = wire.WireCodec()
    valid = codec.encode(TFMessage((ts("world", "base", 1, 1.0), ts("base", "laser", 1, 0.5))),
                         sender=8, seq=1)
    burst = [_mutate(rng, valid) for _ in range(150)]
    refused = 0
    for payload in burst:
        try:
            decoded = codec.decode(payload)
            if len(getattr(decoded.message, "transforms", ())) > 10:
                refused += 1
        except WireError:
            refused += 1
    assert refused > 50
    last = codec.encode(TFMessage((ts("world", "probe", 2, 7.0),)), sender=99, seq=1)
    async with Bus(transport=transport) as bus:
        sub = bus.subscribe("/tf", queue_size=1000)
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher("tfbus/tf",
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            with anyio.fail_after(20):
                while not raw.matching_status.matching:
                    await anyio.sleep(0.01)  # polls the victim's subscription, bounded
            for payload in [*burst, last]:
                raw.put(payload)
            with anyio.fail_after(20):
                while True:
                    message = await sub.receive()
                    if any(t.child_frame_id == "probe" for t in message.transforms):
                        break
            stats = transport.statistics()
            assert stats.malformed + stats.wrong_version + stats.over_limit == refused
        finally:
            await anyio.to_thread.run_sync(session.close)
