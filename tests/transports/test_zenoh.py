"""Tests of the Zenoh transport (tfbus.transports.zenoh) -- real processes on 127.0.0.1; its wire
format is tested in tests/codecs/test_codec_native.py.

Every Zenoh session here uses explicit 127.0.0.1 endpoints with multicast scouting off
(the transport's defaults); every wait is bounded; child processes are killed in
``finally``.
"""

from __future__ import annotations

import dataclasses
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
msgspec = pytest.importorskip("msgspec")

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.codecs import native as wire  # noqa: E402
from tfbus.errors import TransportError  # noqa: E402
from tfbus.listener import TransformListener  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time  # noqa: E402
from tfbus.transports.spec import open_bus  # noqa: E402
from tfbus.transports.spec import parse_bus_spec as parse_any_spec  # noqa: E402
from tfbus.transports.zenoh import (  # noqa: E402
    PEERS_TOPIC,
    PeerEvent,
    ZenohOptions,
    ZenohTransport,
    zenoh_config,
)
from tfbus.transports.zenoh.keys import key_topic as _key_topic  # noqa: E402
from tfbus.transports.zenoh.keys import topic_key as _topic_key  # noqa: E402

HEAD = bytes([wire.MAGIC, wire.WIRE_VERSION])
BLOCK = zenoh.CongestionControl.BLOCK
ROOT = Path(__file__).resolve().parents[2]
PEERS_DIR = ROOT / "peers" / "zenoh"


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


def test_topic_keys_round_trip() -> None:
    for topic in ["/tf", "/tf_static", "/a/b", "/we ird/*/$x#?@%/", "/ünï", "//x"]:
        key = _topic_key(topic)
        zenoh.KeyExpr(f"tfbus/{key}")  # valid key expression
        assert _key_topic(key) == topic
    assert _topic_key("/tf") == "tf"


def parse_bus_spec(text: str) -> ZenohOptions:
    """A ``zenoh`` spec's options: the one parser (spec.parse_bus_spec), then ZenohOptions."""
    return ZenohOptions.from_spec(parse_any_spec(text))


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
    bus = open_bus("zenoh?namespace=r2&name=x")
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
        # No echo: Zenoh matches no subscriber to our publisher, our own included (it
        # only takes remote samples), so nothing can come back.
        assert transport.matching("/tf") is False
        assert sub.statistics().queued == 0
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
        # Subscribed before B exists: B's arrival is an event A must deliver. (B's own
        # view of A, known from Zenoh's liveliness history as B's session opens, may be
        # delivered before B's test code can subscribe: it is checked as state below.)
        peers = a.subscribe(PEERS_TOPIC)
        async with Bus(transport=tb) as b:
            statics = b.subscribe("/tf_static")
            sub = b.subscribe("/tf", queue_size=5000)
            await wait_until(lambda: len(b.latched_statics().transforms) == 2)
            latched = {t.child_frame_id: t for t in b.latched_statics().transforms}
            assert latched["s1"].transform.translation.x == 9.0
            with anyio.fail_after(5):
                ev = await peers.receive()
            assert isinstance(ev, PeerEvent) and ev.alive and ev.name == "B"
            await wait_until(lambda: any(p.name == "A" for p in tb.alive().values()))
            assert [p.name for p in tb.broadcasters().values()] == ["A"]
            done = b.subscribe("/done")
            with anyio.fail_after(5):
                await ta.wait_matching("/tf")  # B's subscriber is known to A's publisher

            async def sync(mark: int) -> None:
                """Wait until B got marker ``mark``: everything A sent before it has been
                received or lost (one session, one link: FIFO). The marker may be dropped
                too (CongestionControl.DROP), so it is repeated."""
                with anyio.fail_after(10):
                    while True:
                        a.publish_nowait("/done", mark)
                        with anyio.move_on_after(0.2):
                            while (await done.receive()) != mark:
                                pass
                            return

            for chunk in range(20):
                for i in range(chunk * 100 + 1, chunk * 100 + 101):
                    a.publish_nowait("/tf", TFMessage((ts("m", i),)))
                await sync(chunk)  # paced by the receiver, not by a sleep
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
async def test_malformed_payloads_are_dropped_and_counted_and_a_delete_ignored() -> None:
    port = free_port()
    transport = ZenohTransport(
        listen=f"tcp/127.0.0.1:{port}", name="victim", limits=wire.WireLimits(max_transforms=10)
    )
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    async with Bus(transport=transport) as bus:
        sub = bus.subscribe("/tf")
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher("tfbus/tf", congestion_control=BLOCK)
            await wait_until(lambda: raw.matching_status.matching)  # the victim subscribes
            codec = wire.WireCodec()
            good = codec.encode(TFMessage((ts("ok", 1),)), sender=5, seq=1)
            bad_version = bytes([wire.MAGIC, wire.WIRE_VERSION + 1]) + good[2:]
            too_many = codec.encode(TFMessage((ts("x", 1),) * 11), sender=6, seq=1)
            last = codec.encode(TFMessage((ts("ok", 2),)), sender=5, seq=2)
            for payload in [good, b"\x00garbage", good[:-3], bad_version, too_many, b""]:
                raw.put(payload)
            # a DELETE on the key carries no message: ignored, unlike the empty PUT above
            raw.delete()
            raw.put(last)
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
async def test_received_topics_keys_are_declared_once_up_to_the_bound(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each data key a transport receives a valid message on is declared to its session
    as a key expression once (Zenoh then keeps the route of its samples), at most
    MAX_ROUTE_KEYS of them; a key beyond the bound, or whose only payload does not
    decode, is received as before and not declared; closing the bus forgets them."""
    from tfbus.transports.zenoh import transport as zenoh_transport

    monkeypatch.setattr(zenoh_transport, "MAX_ROUTE_KEYS", 3)
    port = free_port()
    transport = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="receiver")
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    topics = [f"/t{i}" for i in range(5)]
    codec = wire.WireCodec()
    async with Bus(transport=transport) as bus:
        subs = {topic: bus.subscribe(topic) for topic in [*topics, "/bad"]}
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raws = {t: session.declare_publisher(f"tfbus{t}", congestion_control=BLOCK)
                    for t in [*topics, "/bad"]}
            await wait_until(lambda: all(r.matching_status.matching for r in raws.values()))
            raws["/bad"].put(b"\x00garbage")
            for seq in (1, 2):  # every topic twice: declared at its first message only
                for i, topic in enumerate(topics):
                    raws[topic].put(codec.encode(TFMessage((ts(f"c{i}", seq),)), sender=7,
                                                 seq=seq))
            with anyio.fail_after(5):
                for topic in topics:
                    for seq in (1, 2):
                        got = await subs[topic].receive()
                        assert got.transforms[0].header.stamp.ns == seq
            declared = transport._route_keys
            assert len(declared) == 3
            assert set(declared) <= {f"tfbus{t}" for t in topics}
            for key, expr in declared.items():
                assert isinstance(expr, zenoh.KeyExpr) and str(expr) == key
            assert transport.statistics().malformed == 1
            assert subs["/bad"].statistics().queued == 0
        finally:
            await anyio.to_thread.run_sync(session.close)
    assert transport._route_keys == {}


def laser_scan(sec: float, n: int = 720) -> Any:
    import numpy as np

    from tfbus.sensor_msgs import LaserScan

    ranges = np.linspace(0.2, 12.0, n, dtype=np.float32)
    ranges[::7] = np.nan
    ranges[3] = np.inf
    return LaserScan(header=Header(Time.from_sec(sec), "base_laser"), angle_min=-3.14159,
                     angle_max=3.14159, angle_increment=6.28318 / n, time_increment=1e-4,
                     scan_time=0.1, range_min=0.1, range_max=30.0, ranges=ranges,
                     intensities=np.arange(n, dtype=np.float32))


@pytest.mark.anyio
async def test_laser_scans_cross_bit_for_bit_and_bad_ones_are_dropped() -> None:
    """A sensor_msgs/LaserScan published on one Zenoh bus arrives equal, bit for bit, on
    another; a damaged or oversized scan is counted and dropped, the next kept."""
    from tfbus.sensor_msgs import LaserScan

    port = free_port()
    ta = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="laser")
    tb = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="viewer",
                        limits=wire.WireLimits(max_scan_beams=1000))
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    async with Bus(transport=ta) as a, Bus(transport=tb) as b:
        sub = b.subscribe("/scan", queue_size=10)
        with anyio.fail_after(5):
            await ta.wait_matching("/scan")
        sent = laser_scan(12.5)
        a.publish_nowait("/scan", sent)
        with anyio.fail_after(5):
            got = await sub.receive()
        assert type(got) is LaserScan and got is not sent
        assert got.header == sent.header
        for name in ("angle_min", "angle_max", "angle_increment", "time_increment",
                     "scan_time", "range_min", "range_max"):
            assert getattr(got, name) == getattr(sent, name), name
        assert got.ranges.tobytes() == sent.ranges.tobytes()
        assert got.intensities.tobytes() == sent.intensities.tobytes()
        assert len(got.ranges) == 720

        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher("tfbus/scan", congestion_control=BLOCK)
            await wait_until(lambda: raw.matching_status.matching)
            # "matching" may be the laser's session only: probe (another sender) until the
            # viewer's own route to this session is up (Zenoh's gossip, slower at load)
            probe, seq = wire.WireCodec(), 0
            with anyio.fail_after(20):
                while True:
                    seq += 1
                    raw.put(probe.encode(laser_scan(12.9, 10), sender=78, seq=seq))
                    with anyio.move_on_after(0.2):
                        heard = await sub.receive()
                        assert heard.header.stamp == Time.from_sec(12.9)
                        break
            codec = wire.WireCodec()
            good = codec.encode(laser_scan(13.0, 10), sender=77, seq=1)
            at = good.index(b"\xc4\x28")  # ranges: bin 8 of 40 bytes
            damaged = good[:at] + b"\xc4\x27" + good[at + 2 : at + 41] + good[at + 42 :]
            too_long = codec.encode(laser_scan(13.0, 1001), sender=77, seq=2)
            last = codec.encode(laser_scan(14.0, 10), sender=77, seq=3)
            before = tb.statistics()
            for payload in (damaged, too_long, good[:-5], last):
                raw.put(payload)
            with anyio.fail_after(5):
                kept = await sub.receive()
                while kept.header.stamp == Time.from_sec(12.9):  # a probe still on its way
                    kept = await sub.receive()
            assert kept.header.stamp == Time.from_sec(14.0)
            assert kept.ranges.tobytes() == laser_scan(14.0, 10).ranges.tobytes()
            stats = tb.statistics()
            assert stats.malformed - before.malformed == 2
            assert stats.over_limit - before.over_limit == 1
            assert sub.statistics().queued == 0
        finally:
            await anyio.to_thread.run_sync(session.close)


@pytest.mark.anyio
async def test_default_rendezvous_port_and_namespaces() -> None:
    port = free_port()  # stands in for DEFAULT_PORT: defaults, on a port of our own
    t1 = ZenohTransport(port=port, name="first")
    t2 = ZenohTransport(port=port, name="second")  # port taken: falls back to ephemeral
    t3 = ZenohTransport(port=port, name="other-robot", namespace="robot2")
    async with Bus(transport=t1) as b1, Bus(transport=t3) as b3:
        s3 = b3.subscribe("/tf")
        async with Bus(transport=t2) as b2:
            s2 = b2.subscribe("/tf")
            await wait_until(lambda: any(p.name == "second" for p in t1.alive().values()))
            with anyio.fail_after(5):
                await t1.wait_matching("/tf")
            b1.publish_nowait("/tf", TFMessage((ts("m", 1),)))
            with anyio.fail_after(5):
                assert (await s2.receive()).transforms[0].child_frame_id == "m"
            assert [p.name for p in t1.alive().values()] == ["second"]
        # With "second" gone, nobody matches first's /tf publisher: the bus in namespace
        # robot2 does not subscribe to it (an event, not a wait for nothing to happen).
        with anyio.fail_after(5):
            await t1.wait_matching("/tf", matching=False)
        assert s3.statistics().delivered == 0


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


# Bound of a wait that includes a child process's start (interpreter, imports, its Zenoh
# session): seconds at load 8 on 2 cores. The waits are on output lines, so a generous
# bound costs nothing when the line comes.
STARTUP = 60.0


def test_processes_exchange_late_joiner_gets_statics_kill_and_restart() -> None:
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with peers() as ps:
        b1 = Peer("broadcaster.py", "--listen", ep, "--name", "b1", "--rate", "100")
        ps.append(b1)
        # READY comes after the static publish: the listener started next is a true
        # late joiner (it must get the static from the latch query, not the stream).
        b1.expect(lambda line: line.startswith("READY"), timeout=STARTUP)
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
        # late joiner gets statics
        lis.expect(lambda line: line == "STATIC b1_static", timeout=STARTUP)
        lis.expect(lambda line: line.startswith("PEER 1 b1"))
        first = lis.expect(lambda line: _tf_stamp(line, "b1_moving") is not None)
        s0 = _tf_stamp(first, "b1_moving")
        assert s0 is not None
        later = lis.expect(lambda line: (_tf_stamp(line, "b1_moving") or 0) >= s0 + 20)
        assert later
        lis.expect(lambda line: line.startswith("LOOKUP b1_moving"))  # awaited lookup woke
        # SIGKILL: the listener reports the broadcaster gone
        b1.kill()
        lis.expect(lambda line: line == "PEER 0 b1 -", timeout=30.0)
        # restart on the same endpoint: the listener reconnects and the stream resumes
        b2 = Peer("broadcaster.py", "--listen", ep, "--name", "b2", "--rate", "100")
        ps.append(b2)
        lis.expect(lambda line: line == "STATIC b2_static", timeout=STARTUP)
        lis.expect(lambda line: (_tf_stamp(line, "b2_moving") or 0) >= 10)
        assert any(line.startswith("PEER 1 b2") for line in lis.seen)


def _envelope(tag: bytes, body: bytes, sender: bytes = b"\x05", seq: bytes = b"\x01") -> bytes:
    return HEAD + b"\x94" + sender + seq + tag + body


# -- hostile payloads through a real Bus ---------------------------------------------------


@pytest.mark.anyio
async def test_bus_survives_hostile_payloads() -> None:
    """Hostile payloads through a real Bus with ZenohTransport (loopback, explicit
    endpoints): a 1 000-deep payload (RecursionError ended the Bus), stamps >= 2**63 ns
    (crashed --bus commands later) and forged/negative sequence numbers (`lost` went to
    9e18) are counted and dropped or reported; valid messages beside them arrive, and the
    bus keeps running."""
    port = free_port()
    transport = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="victim")
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    codec = wire.WireCodec()

    def tf(stamp: int, seq: int, sender: int = 5) -> bytes:
        return codec.encode(TFMessage((ts("ok", stamp),)), sender=sender, seq=seq)

    huge_stamp = tf(7, 2).replace(b"\x07\xa5world", b"\xcf" + b"\xff" * 8 + b"\xa5world", 1)
    hostile = [
        _envelope(b"\xa2tf", b"\x91" * 1000 + b"\xc0"),  # deep nesting, TFMessage tag
        _envelope(b"\xa0", b"\x91" * 1000 + b"\xc0"),  # deep nesting, plain value
        _envelope(b"\xa7Vector3", b"\x81\x00" * 1000 + b"\xc0"),  # deep nesting, maps
        huge_stamp,  # stamp >= 2**63 ns
        _envelope(b"\xa2tf", tf(1, 1)[8:], seq=b"\xff"),  # negative seq
    ]
    async with Bus(transport=transport) as bus:
        sub = bus.subscribe("/tf")
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher("tfbus/tf", congestion_control=BLOCK)
            await wait_until(lambda: raw.matching_status.matching)
            raw.put(tf(1, 1))
            for payload in hostile:
                raw.put(payload)
            raw.put(tf(2, 2**63 - 1))  # forged: a reset, not 9e18 lost
            raw.put(tf(3, 3))  # the real stream again: a reset
            raw.put(tf(4, 4))
            with anyio.fail_after(5):
                got = [(await sub.receive()).transforms[0].header.stamp.ns for _ in range(4)]
            assert got == [1, 2, 3, 4]
            stats = transport.statistics()
            assert (stats.malformed, stats.over_limit) == (3, 2)  # nesting: over the bound
            assert stats.dropped == len(hostile)
            assert (stats.lost, stats.resets, stats.delivered) == (0, 2, 4)
            # the bus and the transport are alive: a local round trip still works
            bus.publish_nowait("/tf", TFMessage((ts("local", 9),)))
            assert sub.receive_nowait().transforms[0].child_frame_id == "local"
            assert transport.running
        finally:
            await anyio.to_thread.run_sync(session.close)


@pytest.mark.anyio
async def test_late_joiner_gets_the_valid_static_after_a_nan_resend() -> None:
    """The latched static across processes' worth of transports: a NaN static re-sent by the
    publisher no longer replaces the valid latched one that late joiners are served."""
    port = free_port()
    ta = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="A")
    good = ts("laser", 1, 1.5)
    nan = TransformStamped(
        good.header, "/laser", Transform(Vector3(float("nan"), 0.0, 0.0), Quaternion())
    )
    async with Bus(transport=ta) as a:
        a.publish_nowait("/tf_static", TFMessage((good,)))
        a.publish_nowait("/tf_static", TFMessage((nan,)))
        # A's send thread has put both (the NaN one merged into the latched snapshot when
        # it found the first still queued): B, started next, is a true late joiner. (B
        # started before that put gets the static live, and the replies are duplicates.)
        await wait_until(lambda: ta.statistics().sent + ta.statistics().send_merged == 2,
                         timeout=15.0)
        assert ta.statistics().send_queued == 0
        tb = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="B")
        async with Bus(transport=tb) as b:
            # a late joiner's session start and its query to A take seconds at load 8
            await wait_until(lambda: tb.statistics().latched_replies >= 1, timeout=15.0)
            assert b.latched_statics() == TFMessage((good,))


def test_a_late_joiner_is_served_what_was_handed_to_zenoh_numbered_as_it() -> None:
    """The latch a late joiner is served holds what the latched topic's payloads 1..n
    held, numbered n, from the moment payload n is handed to Zenoh's worker: a query
    while a static still waits in the send queue is served the previous snapshot
    (nothing before the first), so the reply and the live payload with one number
    always hold the same transforms -- also when a second static is merged into the
    waiting one -- and a receiver keeps one of them without losing the other's."""
    from tfbus.transports.zenoh import transport as zt

    tr = ZenohTransport(name="latch")
    outlet = tr._outlet("/tf_static")
    put: list[bytes] = []

    class Publisher:  # Zenoh's publisher, as the worker thread uses it
        def put(self, payload: bytes) -> None:
            put.append(payload)

    outlet.publisher, outlet.queued = Publisher(), True  # type: ignore[assignment]
    laser, camera = ts("laser", 1, 1.5), ts("camera", 1, 0.5)

    def served() -> tuple[int, TFMessage] | None:
        if outlet.latched_payload is None:
            return None
        d = tr._codec.decode(outlet.latched_payload)
        assert isinstance(d.message, TFMessage)
        return d.seq, d.message

    tr.send_nowait("/tf_static", TFMessage((laser,)))
    assert served() is None  # payload 1 still waits: nothing handed over yet
    tr.send_nowait("/tf_static", TFMessage((camera,)))  # merged into the waiting one
    assert served() is None and tr.statistics().send_merged == 1
    assert zt._put_all(tr._take_sends()) == (1, [])
    live = tr._codec.decode(put[-1])
    assert served() == (1, live.message) and live.seq == 1
    assert outlet.latched_payload == put[-1]  # the merged snapshot is what was put
    assert {t.child_frame_id for t in live.message.transforms} == {"laser", "camera"}
    tr.send_nowait("/tf_static", TFMessage((ts("wheel", 1, 0.1),)))
    assert served() == (1, live.message)  # 2 waits: 1's snapshot is still served
    zt._put_all(tr._take_sends())
    now = served()
    assert now is not None and now[0] == 2 and len(now[1].transforms) == 3
    assert tr._codec.decode(put[-1]).message == TFMessage((ts("wheel", 1, 0.1),))
    # a receiver served the reply numbered 2 before the live payloads: it held them both
    rx = ZenohTransport(name="rx")
    assert rx._receive(zt._REPLY, "/tf_static", outlet.latched_payload or b"") is not None
    assert rx._receive(zt._SAMPLE, "/tf_static", put[0]) is None
    assert rx._receive(zt._SAMPLE, "/tf_static", put[1]) is None
    assert rx.statistics().duplicates == 2


def test_a_latched_message_is_delivered_once_when_the_reply_races_the_live_one() -> None:
    """A node that starts publishing ``/tf_static`` is queried by its peers (its new
    topic token) while its first message is on the way: the live payload and the reply
    (the latched payload, numbered as the last one sent) both arrive, in either order.
    Each message reaches the bus once; the other is counted in ``duplicates``. A reply
    to a receiver that joined late still delivers what it missed."""
    from tfbus.transports.zenoh import transport as zt

    tr = ZenohTransport(name="dedupe")
    one = TFMessage((ts("laser", 1, 1.5),))
    two = TFMessage((ts("laser", 1, 1.5), ts("camera", 1, 0.5)))

    def payload(message: TFMessage, sender: int, seq: int) -> bytes:
        return tr._codec.encode(message, sender=sender, seq=seq)

    topic = "/tf_static"
    # live first, then the reply to the query its token caused
    assert tr._receive(zt._SAMPLE, topic, payload(one, 11, 1)) == one
    assert tr._receive(zt._REPLY, topic, payload(one, 11, 1)) is None
    # reply first (the sender's second message), then that message live
    assert tr._receive(zt._REPLY, topic, payload(two, 11, 2)) == two
    assert tr._receive(zt._SAMPLE, topic, payload(two, 11, 2)) is None
    stats = tr.statistics()
    assert (stats.received, stats.duplicates, stats.latched_replies) == (4, 2, 1)
    # joined late: seen live from message 3 on, so a reply numbered 3 holds what 1-2 sent
    three = TFMessage((ts("wheel", 1, 0.1),))
    assert tr._receive(zt._SAMPLE, topic, payload(three, 12, 3)) == three
    assert tr._receive(zt._REPLY, topic, payload(two, 12, 3)) == two
    assert tr.statistics().duplicates == 2


@pytest.mark.anyio
async def test_a_latched_message_that_reached_no_one_is_delivered_by_the_reply() -> None:
    """A fleet follows a robot's topics once its liveliness says it is there. A robot's
    first ``/robot2/tf_static`` can arrive live before that token: it reaches no one, so
    the reply to the query the token causes is news, not a duplicate, and the fleet gets
    the static. A clean-clone run lost robot2's static this way (its lookup timed out).
    A token and a live payload drained together are delivered in order: the fleet
    follows first, and the reply after that is the duplicate."""
    from tfbus.fleet import FleetBuffer
    from tfbus.transports.zenoh import transport as zt

    tr = ZenohTransport(namespace="*", name="viewer")
    static = TFMessage((ts("laser", 1, 0.5, parent="base"),))

    def payload(sender: int) -> bytes:
        return tr._codec.encode(static, sender=sender, seq=1)

    def drain(*items: tuple[int, str, bytes]) -> None:
        tr._inbox.extend(items)
        assert not tr._drain(bus)

    async with Bus() as bus, FleetBuffer(bus) as fleet:
        drain((zt._SAMPLE, "tfbus/robot2/tf_static", payload(21)))  # nobody follows robot2
        assert "robot2" not in fleet.robots()
        drain((zt._ALIVE_PUT, "tfbus/robot2/@alive/a1/static", b""),
              (zt._REPLY, "tfbus/robot2/@latch/a1/tf_static", payload(21)))
        got = fleet["robot2"].lookup_transform("base", "laser", Time(0))
        assert got.transform.translation.x == 0.5
        assert tr.statistics().duplicates == 0

        drain((zt._ALIVE_PUT, "tfbus/robot3/@alive/b2/static", b""),
              (zt._SAMPLE, "tfbus/robot3/tf_static", payload(22)))
        drain((zt._REPLY, "tfbus/robot3/@latch/b2/tf_static", payload(22)))
        assert fleet["robot3"].can_transform("base", "laser", Time(0))
        assert tr.statistics().duplicates == 1
        assert fleet.statistics().messages == 2


@pytest.mark.anyio
async def test_drained_samples_in_order_are_taken_inline_and_counted_as_each_one_alone() -> None:
    """The receive loop takes a sample of a data key it has had a valid sample on, whose
    payload is a TFMessage the compiled decoder reads, numbered next in its stream with
    no reply of it delivered at or after that number, without the per-payload path
    (``_receive``, ``SequenceTracker.observe``). What it delivers and counts is what the
    per-payload path delivers and counts for the same entries, taken alone (a transport
    with no compiled decoder), entry by entry: in order, a repeat, a gap, a reply ahead
    of the live stream and the live payloads it already held, a second sender, a
    malformed payload, a refused key, a clock, a topic nobody follows (its stream then
    not remembered as delivered) and the same stream once somebody does."""
    from tfbus.messages import Clock
    from tfbus.subscription import CallbackSubscription
    from tfbus.transports.zenoh import transport as zt

    encoder = ZenohTransport(name="encoder")

    def pay(message: object, sender: int, seq: int) -> bytes:
        return encoder._codec.encode(message, sender=sender, seq=seq)

    keys = encoder._keys
    tf_key, other_key, clock_key = keys.data("/tf"), keys.data("/other"), keys.data("/clock")
    latch_key = keys.latch("n1", "/tf")

    def tf(n: int) -> TFMessage:
        return TFMessage((ts("laser", n, 0.1 * n),))

    entries: list[tuple[int, str, bytes]] = [
        (zt._SAMPLE, tf_key, pay(tf(1), 5, 1)),  # the key's first: per payload
        (zt._SAMPLE, tf_key, pay(tf(2), 5, 2)),
        (zt._SAMPLE, tf_key, pay(tf(3), 5, 3)),
        (zt._SAMPLE, tf_key, pay(tf(3), 5, 3)),  # the same number again: a reset
        (zt._SAMPLE, tf_key, pay(tf(6), 5, 6)),  # two lost
        (zt._REPLY, latch_key, pay(tf(8), 5, 8)),  # a reply ahead of the live stream
        (zt._SAMPLE, tf_key, pay(tf(7), 5, 7)),  # held by the reply: duplicates
        (zt._SAMPLE, tf_key, pay(tf(8), 5, 8)),
        (zt._SAMPLE, tf_key, pay(tf(9), 5, 9)),
        (zt._SAMPLE, tf_key, pay(tf(1), 6, 1)),  # another sender's stream
        (zt._SAMPLE, tf_key, pay(tf(2), 6, 2)),
        (zt._SAMPLE, tf_key, HEAD + b"\x93junk"),  # malformed
        (zt._SAMPLE, "elsewhere/tf", pay(tf(3), 6, 3)),  # not this bus's key
        (zt._SAMPLE, tf_key, pay(tf(3), 6, 3)),
        (zt._SAMPLE, clock_key, pay(Clock(Time(4)), 5, 1)),
        (zt._SAMPLE, clock_key, pay(Clock(Time(5)), 5, 2)),
        (zt._SAMPLE, other_key, pay(tf(1), 7, 1)),  # nobody follows /other yet
        (zt._SAMPLE, other_key, pay(tf(2), 7, 2)),
    ]
    followed = (zt._SAMPLE, other_key, pay(tf(1), 8, 1))  # a whole stream from 1
    unfollowed = (zt._SAMPLE, other_key, pay(tf(2), 8, 2))  # taken inline, reaching no one
    later = [(zt._REPLY, keys.latch("n2", "/other"), pay(tf(2), 7, 2)),  # news: unseen
             (zt._SAMPLE, other_key, pay(tf(3), 7, 3)),
             (zt._REPLY, keys.latch("n3", "/other"), pay(tf(2), 8, 2)),  # news: unseen
             (zt._SAMPLE, other_key, pay(tf(3), 8, 3)),
             (zt._SAMPLE, tf_key, pay(tf(10), 5, 10))]  # fmt: skip

    async def run(compiled: bool) -> tuple[list[tuple[str, object]], dict[str, int], int]:
        tr = ZenohTransport(name="rx")
        if not compiled:
            tr._tf_decoder = None
        per_payload = 0
        receive = tr._receive

        def counted(*args: Any) -> object | None:
            nonlocal per_payload
            per_payload += 1
            return receive(*args)

        tr._receive = counted  # type: ignore[method-assign]
        got: list[tuple[str, object]] = []
        async with Bus() as bus:
            for topic in ("/tf", "/clock"):
                bus.subscribe_callback(topic, lambda m, t=topic: got.append((t, m)))
            def other() -> CallbackSubscription:
                return bus.subscribe_callback("/other", lambda m: got.append(("/other", m)))

            for entry in [*entries, followed, unfollowed]:  # one entry a batch
                following = other() if entry is followed else None
                tr._inbox.append(entry)
                assert not tr._drain(bus, True)
                if following is not None:
                    following.close()
            other()
            tr._inbox.extend(later)  # one batch
            assert not tr._drain(bus, True)
        stats = dataclasses.asdict(tr.statistics())
        return got, stats, per_payload

    inline, inline_stats, inline_calls = await run(compiled=True)
    alone, alone_stats, alone_calls = await run(compiled=False)
    if wire._compiled_tf is None:
        pytest.skip("no compiled core: every payload takes the per-payload path")
    assert inline == alone and inline_stats == alone_stats
    assert [m for t, m in inline if t == "/tf"] == [
        tf(1), tf(2), tf(3), tf(3), tf(6), tf(8), tf(9), tf(1), tf(2), tf(3), tf(10)]
    assert [t for t, _ in inline].count("/clock") == 2
    assert [m for t, m in inline if t == "/other"] == [tf(1), tf(2), tf(3), tf(2), tf(3)]
    assert (inline_stats["received"], inline_stats["delivered"]) == (25, 21)
    assert (inline_stats["lost"], inline_stats["resets"], inline_stats["duplicates"]) == (2, 1, 2)
    assert (inline_stats["malformed"], inline_stats["refused_keys"]) == (1, 1)
    assert inline_stats["batches"] == len(entries) + 3
    # taken inline: /tf 2, 3, 9, 10 of sender 5 and 2, 3 of sender 6; /other 2 and 3 of
    # senders 7 and 8 (each 2 reaching no one, each 3 after the reply of 2 delivered)
    assert alone_calls == len(entries) + 2 + len(later)
    assert inline_calls == alone_calls - 10


def test_a_sample_over_the_inbox_bound_drops_the_oldest_and_is_counted() -> None:
    """Zenoh's thread queues each sample for the event loop in a bounded inbox: past
    ``max_pending`` entries the oldest is dropped and counted in ``overflow``, and the
    loop's wake-up is asked for once until it is served."""
    from types import SimpleNamespace

    from tfbus.transports._base import ThreadWakeup

    tr = ZenohTransport(name="rx", max_pending=3)
    key = tr._keys.data("/tf")

    def sample(n: int) -> Any:
        payload = SimpleNamespace(to_bytes=lambda: bytes([n]))
        return SimpleNamespace(payload=payload, kind=zenoh.SampleKind.PUT, key_expr=key)

    wakeup = tr._wakeup = ThreadWakeup()
    try:
        for n in range(1, 6):
            tr._on_sample(sample(n))
        assert [p for _, _, p in tr._inbox] == [b"\x03", b"\x04", b"\x05"]
        assert tr.statistics().overflow == 2
        assert wakeup._r.recv(16) == b"\0"  # one wake-up for the burst
    finally:
        wakeup.close()


# -- bus specs and errors ----------------------------------------------------------------


def test_bus_spec_grammar_and_scheme_table() -> None:
    """One grammar for every transport (tfbus/transports/spec.py)."""
    from tfbus.transports import spec

    parsed = spec.parse_bus_spec("zenoh:connect=tcp/127.0.0.1:7447&name=p?listen=tcp/a:1,tcp/b:2")
    assert parsed.scheme == "zenoh"
    assert parsed.values("connect") == ("tcp/127.0.0.1:7447",)
    assert parsed.values("listen") == ("tcp/a:1", "tcp/b:2")
    assert parsed.value("name") == "p"
    assert spec.parse_bus_spec("zenoh:tcp/10.0.0.2:7448").values("connect") == (
        "tcp/10.0.0.2:7448",
    )
    assert spec.parse_bus_spec("memory").options == {}
    assert parse_bus_spec("zenoh:connect=tcp/127.0.0.1:7447").connect == ("tcp/127.0.0.1:7447",)
    for bad in ["nope", "memory:x", "memory?x=1", "zenoh:bogus=1", "", "zenoh?express=maybe"]:
        with pytest.raises(ValueError):
            spec.open_transport(bad)
    assert set(spec.schemes()) >= {"memory", "zenoh"}
    with pytest.raises(ValueError):
        spec.register_scheme(spec.TransportScheme("zenoh", "x"))
    # a scheme whose extra is missing: one clear error naming the extra
    spec.register_scheme(
        spec.TransportScheme("absent", "tfbus.nothing", extra="absent", requires=("no_such_mod",))
    )
    try:
        with pytest.raises(TransportError, match=r"pip install 'tfbus\[absent\]'"):
            spec.open_transport("absent")
    finally:
        spec._SCHEMES.pop("absent")
    from tfbus.transports.memory import MemoryTransport

    assert isinstance(spec.open_transport("memory"), MemoryTransport)
    bus = spec.open_bus("zenoh?namespace=r3", name="x")
    assert isinstance(bus.transport, ZenohTransport) and bus.transport.name == "x"


@pytest.mark.anyio
async def test_zenoh_errors_are_transport_errors(tmp_path: Path) -> None:
    """Zenoh's own errors reach callers as tfbus.errors.TransportError (one
    error type for every transport), with the ZError as the cause."""
    bad = tmp_path / "bad.json5"
    bad.write_text("{ this is not json5")
    with pytest.raises(TransportError) as info:
        ZenohTransport(config=str(bad))
    assert isinstance(info.value.__cause__, zenoh.ZError)
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    async with Bus(transport=ZenohTransport(listen=ep, name="holder")):
        with pytest.raises(TransportError) as info:
            async with Bus(transport=ZenohTransport(listen=ep, name="second")):
                pass
    assert isinstance(info.value.__cause__, zenoh.ZError)


# -- congestion: /tf_static is never dropped; congestion_control="block" counts its drops --


def big(child: str, ns: int, n: int = 40) -> TFMessage:
    """A /tf message of ``n`` transforms (about 4 kB): a few thousand fill Zenoh's queue."""
    return TFMessage(tuple(ts(f"{child}_{k}", ns, float(k)) for k in range(n)))


@pytest.mark.anyio
async def test_tf_static_is_not_dropped_while_tf_floods_the_link() -> None:
    port = free_port()
    ta = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="A")
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    gate = threading.Event()  # a subscriber that stalls: Zenoh's queue to it fills up
    got: list[tuple[str, bytes]] = []

    def slow(sample: Any) -> None:
        gate.wait(10)
        got.append((str(sample.key_expr), sample.payload.to_bytes()))

    async with Bus(transport=ta) as a:
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            session.declare_subscriber("tfbus/**", slow)
            with anyio.fail_after(10):
                await ta.wait_matching("/tf")
            a.publish_nowait("/tf_static", TFMessage((ts("s0", 1),)))
            for i in range(1, 3001):  # no await: faster than the stalled link drains
                a.publish_nowait("/tf", big("m", i))
                if i % 300 == 0:
                    a.publish_nowait("/tf_static", TFMessage((ts(f"s{i // 300}", 1),)))
            gate.set()
            codec = wire.WireCodec()

            def statics() -> set[str]:
                return {t.child_frame_id for key, payload in list(got)
                        if key == "tfbus/tf_static"
                        for t in codec.decode(payload).message.transforms}

            # every static arrives (BLOCK; the ones published while one waited are
            # merged into it); /tf loses what Zenoh dropped (DROP)
            await wait_until(lambda: len(statics()) == 11, timeout=30)
            assert statics() == {f"s{k}" for k in range(11)}
            # the send thread's puts are counted once it hands back to the event loop,
            # which may be after the subscriber has them
            await wait_until(lambda: ta.statistics().send_queued == 0
                             and ta.statistics().sent + ta.statistics().send_merged == 3011,
                             timeout=10)
            sa = ta.statistics()
            assert sa.send_dropped == 0
            assert ta.congestion_control == "drop"
            # what Zenoh was told (its drops cannot be seen from Python): /tf_static
            # blocks and is reliable, /tf drops
            outlets = ta._outlets
            static_pub, tf_pub = outlets["/tf_static"].publisher, outlets["/tf"].publisher
            assert static_pub is not None and tf_pub is not None
            assert static_pub.congestion_control == BLOCK
            assert static_pub.reliability == zenoh.Reliability.RELIABLE
            assert tf_pub.congestion_control == zenoh.CongestionControl.DROP
        finally:
            gate.set()
            await anyio.to_thread.run_sync(session.close)


@pytest.mark.anyio
async def test_congestion_control_block_counts_its_drops_at_the_sender() -> None:
    port = free_port()
    ta = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="A",
                        congestion_control="block", max_send_pending=50)
    tb = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="B")
    async with Bus(transport=ta) as a, Bus(transport=tb) as b:
        sub = b.subscribe("/tf", queue_size=5000)
        with anyio.fail_after(10):
            await ta.wait_matching("/tf")
        a.publish_nowait("/tf", big("m", 1))
        with anyio.fail_after(10):
            await sub.receive()
        # 500 at once: the send queue holds the newest 50, the 450 before are dropped
        for i in range(2, 502):
            a.publish_nowait("/tf", big("m", i))
        assert ta.statistics().send_dropped == 450
        await wait_until(lambda: ta.statistics().sent == 51, timeout=20)
        await wait_until(lambda: sub.statistics().queued == 50, timeout=20)
        got = [sub.receive_nowait().transforms[0].header.stamp.ns for _ in range(50)]
        assert got == list(range(452, 502))
        assert tb.statistics().lost == 450  # the receiver sees the same gap
        # paced by what was handed to Zenoh: BLOCK never drops, nothing is lost
        for chunk in range(40):  # 50 at a time: the send queue never overflows
            for i in range(50):
                a.publish_nowait("/tf", big("m", 1000 + chunk * 50 + i, n=10))
            await wait_until(lambda c=chunk: ta.statistics().sent == 101 + c * 50, 20)
        await wait_until(lambda: tb.statistics().received >= 2051, timeout=20)
        sa, sb = ta.statistics(), tb.statistics()
        assert (sa.sent, sa.send_dropped, sa.send_queued) == (2051, 450, 0)
        assert sb.lost == 450 and sub.statistics().queued == 2000
        tf_pub = ta._outlets["/tf"].publisher
        assert tf_pub is not None and tf_pub.congestion_control == BLOCK


def test_congestion_control_option() -> None:
    assert parse_bus_spec("zenoh?congestion_control=block").congestion_control == "block"
    assert parse_bus_spec("zenoh").transport().congestion_control == "drop"
    with pytest.raises(ValueError, match="congestion_control must be drop or block, got 'x'"):
        parse_bus_spec("zenoh?congestion_control=x")
    with pytest.raises(ValueError, match="congestion_control must be 'drop' or 'block'"):
        ZenohTransport(congestion_control="fast")
    with pytest.raises(ValueError, match="max_send_pending must be at least 1, got 0"):
        ZenohTransport(max_send_pending=0)
