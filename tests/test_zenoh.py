"""Tests of tfbus.transports (wire format, Zenoh transport) -- real processes on 127.0.0.1.

Every Zenoh session here uses explicit 127.0.0.1 endpoints with multicast scouting off
(the transport's defaults); every wait is bounded; child processes are killed in
``finally``.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("msgspec")

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.listener import TransformListener  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Point,
    PointStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time  # noqa: E402
from tfbus.transports import wire  # noqa: E402
from tfbus.transports.zenoh import (  # noqa: E402
    PEERS_TOPIC,
    PeerEvent,
    ZenohOptions,
    ZenohTransport,
    _key_topic,
    _topic_key,
    parse_bus_spec,
    zenoh_bus_from_options,
    zenoh_config,
)

HEAD = bytes([wire.MAGIC, wire.WIRE_VERSION])
PEERS_DIR = Path(__file__).parent / "zenoh_peers"
ROOT = Path(__file__).parent.parent


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ts(child: str, ns: int, x: float = 0.0, parent: str = "world") -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


async def wait_until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.01)


# -- wire format ------------------------------------------------------------------------


def test_wire_round_trip_tf_typed_and_raw() -> None:
    codec = wire.WireCodec()
    msg = TFMessage((ts("a", 1_700_000_000_123_456_789, 1.5), ts("b", 7)))
    out = codec.decode(codec.encode(msg, sender=42, seq=3))
    assert out == wire.Decoded(42, 3, msg)
    assert type(out.message) is TFMessage
    assert type(out.message.transforms[0].header.stamp) is Time
    point = PointStamped(Header(Time(2), "map"), Point(1.0, 2.0, 3.0))
    assert codec.decode(codec.encode(point, sender=1, seq=1)).message == point
    assert codec.decode(codec.encode({"k": [1, "x"]}, sender=1, seq=1)).message == {"k": [1, "x"]}
    with pytest.raises(wire.WireEncodeError):
        codec.encode(object(), sender=1, seq=1)


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        (b"", wire.WireDecodeError),
        (b"garbage bytes", wire.WireDecodeError),
        (bytes([wire.MAGIC, wire.WIRE_VERSION + 1]) + b"\x90", wire.WireVersionError),
        (bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\xc1", wire.WireDecodeError),
        (
            bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\x94\x01\x01\xa2tf\x91\x01",
            wire.WireDecodeError,
        ),
        (bytes([wire.MAGIC, wire.WIRE_VERSION]) + b"\x94\x01\x01\xa3zzz\x90", wire.WireDecodeError),
    ],
)
def test_wire_rejects_malformed(payload: bytes, error: type[Exception]) -> None:
    with pytest.raises(error):
        wire.WireCodec().decode(payload)


def test_wire_limits_and_negative_stamp() -> None:
    codec = wire.WireCodec(wire.WireLimits(max_transforms=2, max_frame_id_length=8))
    ok = codec.encode(TFMessage((ts("a", 1), ts("b", 2))), sender=1, seq=1)
    assert len(codec.decode(ok).message.transforms) == 2  # type: ignore[attr-defined]
    with pytest.raises(wire.WireLimitError):
        codec.decode(codec.encode(TFMessage((ts("a", 1),) * 3), sender=1, seq=1))
    with pytest.raises(wire.WireLimitError):
        codec.decode(codec.encode(TFMessage((ts("x" * 9, 1),)), sender=1, seq=1))
    small = wire.WireCodec(wire.WireLimits(max_payload_bytes=10))
    with pytest.raises(wire.WireLimitError):
        small.decode(ok)
    bad_stamp = ok.replace(b"\x01\xa5world", b"\xff\xa5world", 1)
    with pytest.raises(wire.WireDecodeError):
        codec.decode(bad_stamp)


def test_topic_keys_round_trip() -> None:
    for topic in ["/tf", "/tf_static", "/a/b", "/we ird/*/$x#?@%/", "/ünï", "//x"]:
        key = _topic_key(topic)
        zenoh.KeyExpr(f"tfbus/{key}")  # valid key expression
        assert _key_topic(key) == topic
    assert _topic_key("/tf") == "tf"


def test_parse_bus_spec() -> None:
    assert parse_bus_spec("zenoh") == ZenohOptions()
    opts = parse_bus_spec(
        "zenoh?connect=tcp/10.0.0.2:7448,tcp/10.0.0.3:7448&listen=tcp/0.0.0.0:7448"
        "&namespace=robot1&name=planner&port=9000&express=1"
    )
    assert opts.connect == ("tcp/10.0.0.2:7448", "tcp/10.0.0.3:7448")
    assert opts.listen == ("tcp/0.0.0.0:7448",)
    assert (opts.namespace, opts.name, opts.port, opts.express) == ("robot1", "planner", 9000, True)
    assert parse_bus_spec("zenoh:tcp/10.0.0.2:7448").connect == ("tcp/10.0.0.2:7448",)
    for bad in ["memory", "zenoh?bogus=1", "zenoh?port=x", "zenoh?name=a&name=b"]:
        with pytest.raises(ValueError):
            parse_bus_spec(bad)
    with pytest.raises(ValueError):
        ZenohTransport(prefix="tf*bus")
    bus = zenoh_bus_from_options("zenoh?namespace=r2&name=x")
    assert isinstance(bus.transport, ZenohTransport)
    assert bus.transport.key_prefix == "tfbus/r2"


def test_default_config_is_loopback_without_multicast() -> None:
    def get(cfg: Any, key: str) -> Any:
        return json.loads(cfg.get_json(key))

    cfg, fallback = zenoh_config(port=17000)
    assert get(cfg, "scouting/multicast/enabled") is False
    assert get(cfg, "mode") == "peer"
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:17000"]
    assert get(cfg, "connect/endpoints") == ["tcp/127.0.0.1:17000"]
    assert fallback is not None
    assert get(fallback, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert get(fallback, "scouting/multicast/enabled") is False
    cfg, fallback = zenoh_config(connect="tcp/127.0.0.1:1")
    assert fallback is None and get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    cfg, _ = zenoh_config(listen="tcp/127.0.0.1:2", config={"transport/link/tx/lease": 3000})
    assert get(cfg, "transport/link/tx/lease") == 3000


# -- in-process (two sessions, one process) ------------------------------------------------


@pytest.mark.anyio
async def test_in_process_api_unchanged_and_no_echo() -> None:
    port = free_port()
    transport = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="solo")
    buffer = Buffer()
    async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
        sub = bus.subscribe("/tf")
        bus.publish_nowait("/tf", TFMessage((ts("base", 5, 2.0),)))
        with anyio.fail_after(5):
            assert (await sub.receive()).transforms[0].child_frame_id == "base"
            got = await buffer.lookup_transform_async("world", "base", Time(0), timeout=5)
        assert got.transform.translation.x == 2.0
        await anyio.sleep(0.1)
        assert sub.statistics().queued == 0  # no echo of our own publish
        assert bus.statistics()["/tf"].remote == 0
        assert transport.statistics().sent == 1
    assert not transport.running


@pytest.mark.anyio
async def test_two_buses_exchange_in_order_and_statics_and_peers() -> None:
    port = free_port()
    ta = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="A")
    tb = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="B")
    async with Bus(transport=ta) as a:
        a.publish_nowait("/tf_static", TFMessage((ts("s1", 1), ts("s2", 1))))
        a.publish_nowait("/tf_static", TFMessage((ts("s1", 1, 9.0),)))  # replaces s1
        async with Bus(transport=tb) as b:
            peers = b.subscribe(PEERS_TOPIC)
            statics = b.subscribe("/tf_static")
            sub = b.subscribe("/tf", queue_size=5000)
            await wait_until(lambda: len(b.latched_statics().transforms) == 2)
            latched = {t.child_frame_id: t for t in b.latched_statics().transforms}
            assert latched["s1"].transform.translation.x == 9.0
            with anyio.fail_after(5):
                ev = await peers.receive()
            assert isinstance(ev, PeerEvent) and ev.alive and ev.name == "A"
            await wait_until(lambda: any(p.name == "B" for p in ta.alive().values()))
            assert [p.name for p in tb.broadcasters().values()] == ["A"]
            done = b.subscribe("/done")
            for chunk in range(20):
                for i in range(chunk * 100 + 1, chunk * 100 + 101):
                    a.publish_nowait("/tf", TFMessage((ts("m", i),)))
                await anyio.sleep(0.002)
            await anyio.sleep(0.1)
            with anyio.fail_after(10):  # the end marker may be dropped too: repeat it
                while done.statistics().delivered == 0:
                    a.publish_nowait("/done", True)
                    with anyio.move_on_after(0.2):
                        await done.receive()
            stamps = []
            while sub.statistics().queued:
                stamps.append(sub.receive_nowait().transforms[0].header.stamp.ns)
            stats = tb.statistics()
            # Zenoh may drop under CPU starvation (CongestionControl.DROP): counted as lost
            assert stamps == sorted(set(stamps))  # per-publisher order kept
            assert len(stamps) + stats.lost == 2000 and len(stamps) > 1000
            assert stats.dropped == 0
            assert stats.batches < len(stamps)  # batched wake-ups, not one per message
            assert statics.statistics().delivered >= 1
            # any msgpack value crosses on other topics
            other = b.subscribe("/chat")
            a.publish_nowait("/chat", {"hi": [1, 2]})
            with anyio.fail_after(5):
                assert await other.receive() == {"hi": [1, 2]}
        await wait_until(lambda: not ta.alive())


@pytest.mark.anyio
async def test_malformed_payloads_are_dropped_and_counted() -> None:
    port = free_port()
    transport = ZenohTransport(
        listen=f"tcp/127.0.0.1:{port}", name="victim", limits=wire.WireLimits(max_transforms=10)
    )
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    async with Bus(transport=transport) as bus:
        sub = bus.subscribe("/tf")
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            await wait_until(lambda: bool(transport.alive()) or bool(session.info.peers_zid()))
            await anyio.sleep(0.2)  # let the subscriber declaration reach the raw session
            codec = wire.WireCodec()
            good = codec.encode(TFMessage((ts("ok", 1),)), sender=5, seq=1)
            bad_version = bytes([wire.MAGIC, wire.WIRE_VERSION + 1]) + good[2:]
            too_many = codec.encode(TFMessage((ts("x", 1),) * 11), sender=6, seq=1)
            last = codec.encode(TFMessage((ts("ok", 2),)), sender=5, seq=2)
            block = zenoh.CongestionControl.BLOCK
            for payload in [good, b"\x00garbage", good[:-3], bad_version, too_many, b"", last]:
                session.put("tfbus/tf", payload, congestion_control=block)
            with anyio.fail_after(5):
                first = await sub.receive()
                second = await sub.receive()
            assert [m.transforms[0].header.stamp.ns for m in (first, second)] == [1, 2]
            stats = transport.statistics()
            assert (stats.malformed, stats.wrong_version, stats.over_limit) == (3, 1, 1)
            assert stats.dropped == 5 and stats.delivered == 2 and stats.lost == 0
        finally:
            await anyio.to_thread.run_sync(session.close)


@pytest.mark.anyio
async def test_default_rendezvous_port_and_namespaces() -> None:
    port = free_port()  # stands in for DEFAULT_PORT: defaults, on a port of our own
    t1 = ZenohTransport(port=port, name="first")
    t2 = ZenohTransport(port=port, name="second")  # port taken: falls back to ephemeral
    t3 = ZenohTransport(port=port, name="other-robot", namespace="robot2")
    async with Bus(transport=t1) as b1, Bus(transport=t2) as b2, Bus(transport=t3) as b3:
        s2 = b2.subscribe("/tf")
        s3 = b3.subscribe("/tf")
        await wait_until(lambda: any(p.name == "second" for p in t1.alive().values()))
        await anyio.sleep(0.1)
        b1.publish_nowait("/tf", TFMessage((ts("m", 1),)))
        with anyio.fail_after(5):
            assert (await s2.receive()).transforms[0].child_frame_id == "m"
        await anyio.sleep(0.2)
        assert s3.statistics().delivered == 0  # another namespace sees nothing
        assert [p.name for p in t1.alive().values()] == ["second"]


# -- real processes ----------------------------------------------------------------------


class Peer:
    """A child process whose stdout lines are collected by a reader thread."""

    def __init__(self, script: str, *args: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        env["PYTHONUNBUFFERED"] = "1"
        self.proc = subprocess.Popen(
            [sys.executable, str(PEERS_DIR / script), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def expect(self, predicate: Callable[[str], bool], timeout: float = 10.0) -> str:
        """The first line, already seen or still to come, that matches ``predicate``."""
        for line in self.seen:
            if predicate(line):
                return line
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"timed out; last lines: {self.seen[-10:]}; {self.stderr()}")
            try:
                line = self.lines.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    raise AssertionError(f"peer exited: {self.stderr()}") from None
                continue
            self.seen.append(line)
            if predicate(line):
                return line

    def stderr(self) -> str:
        if self.proc.poll() is None or self.proc.stderr is None:
            return ""
        return self.proc.stderr.read()[-2000:]

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)


@contextmanager
def peers() -> Iterator[list[Peer]]:
    started: list[Peer] = []
    try:
        yield started
    finally:
        for p in started:
            p.kill()


def _tf_stamp(line: str, child: str) -> int | None:
    parts = line.split()
    if len(parts) == 3 and parts[0] == "TF" and parts[1] == child:
        return int(parts[2])
    return None


def test_processes_exchange_late_joiner_gets_statics_kill_and_restart() -> None:
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with peers() as ps:
        b1 = Peer("broadcaster.py", "--listen", ep, "--name", "b1", "--rate", "100")
        ps.append(b1)
        b1.expect(lambda line: line.startswith("READY"))
        # Scenario set-up, not a wait for a result: let real time pass so that the static
        # is published well before the listener process exists (a true late joiner).
        time.sleep(0.3)
        lis = Peer(
            "listener.py",
            "--connect",
            ep,
            "--name",
            "lis",
            "--lookup",
            "b1_moving",
            "--backend",
            "trio",
        )
        ps.append(lis)
        lis.expect(lambda line: line == "STATIC b1_static")  # late joiner gets statics
        lis.expect(lambda line: line.startswith("PEER 1 b1"))
        first = lis.expect(lambda line: _tf_stamp(line, "b1_moving") is not None)
        s0 = _tf_stamp(first, "b1_moving")
        assert s0 is not None
        later = lis.expect(lambda line: (_tf_stamp(line, "b1_moving") or 0) >= s0 + 20)
        assert later
        lis.expect(lambda line: line.startswith("LOOKUP b1_moving"))  # awaited lookup woke
        # SIGKILL: the listener reports the broadcaster gone
        b1.kill()
        lis.expect(lambda line: line == "PEER 0 b1 -", timeout=8.0)
        # restart on the same endpoint: the listener reconnects and the stream resumes
        b2 = Peer("broadcaster.py", "--listen", ep, "--name", "b2", "--rate", "100")
        ps.append(b2)
        lis.expect(lambda line: line == "STATIC b2_static", timeout=10.0)
        lis.expect(lambda line: (_tf_stamp(line, "b2_moving") or 0) >= 10)
        assert any(line.startswith("PEER 1 b2") for line in lis.seen)
