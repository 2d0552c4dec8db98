"""``tfbus view --foxglove``: a Foxglove WebSocket protocol client (subprotocol
``foxglove.sdk.v1``, the ``websockets`` package) subscribes to ``/tf`` and a scan topic,
decodes the protobuf messages it receives (wire format decoded here, field numbers from
the foxglove schemas) and compares every transform with ``Buffer.lookup_transform``;
bag time arrives as the server time, tf errors as status messages."""

from __future__ import annotations

import asyncio
import json
import struct
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest

pytest.importorskip("foxglove")
pytest.importorskip("viser")
websockets = pytest.importorskip("websockets")

from tfbus import Time  # noqa: E402
from tfbus.bag import load_buffer  # noqa: E402
from tfbus.view.foxglove_bridge import FoxgloveBridge  # noqa: E402
from tfbus.view.player import BagPlayer  # noqa: E402
from tfbus.view.scans import ScanTrack  # noqa: E402
from tfbus.view.server import TfPage  # noqa: E402
from tfbus.view.timeline import BagTimeline  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
LASER = DATA / "laser" / "drl_guardian_3.bag"


def fields(buf: bytes) -> dict[int, list[Any]]:
    """Protocol buffers wire format: field number -> values (varint: int, fixed64: float
    (the schemas' doubles), fixed32: float, length-delimited: bytes)."""
    out: dict[int, list[Any]] = {}
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        num, wire = key >> 3, key & 7
        if wire == 0:
            val, i = _varint(buf, i)
        elif wire == 1:
            val, i = struct.unpack_from("<d", buf, i)[0], i + 8
        elif wire == 5:
            val, i = struct.unpack_from("<f", buf, i)[0], i + 4
        elif wire == 2:
            n, i = _varint(buf, i)
            val, i = buf[i:i + n], i + n
        else:
            raise AssertionError(f"wire type {wire}")
        out.setdefault(num, []).append(val)
    return out


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def _one(f: dict[int, list[Any]], n: int, default: Any) -> Any:
    return f.get(n, [default])[0]


def frame_transform(buf: bytes) -> tuple[int, str, str, tuple[float, ...], tuple[float, ...]]:
    """foxglove.FrameTransform: timestamp=1 (sec=1, nsec=2), parent=2, child=3,
    translation=4 (x y z = 1 2 3), rotation=5 (x y z w = 1 2 3 4)."""
    f = fields(buf)
    ts = fields(_one(f, 1, b""))
    stamp = _one(ts, 1, 0) * 1_000_000_000 + _one(ts, 2, 0)
    tr = fields(_one(f, 4, b""))
    rot = fields(_one(f, 5, b""))
    return (stamp, _one(f, 2, b"").decode(), _one(f, 3, b"").decode(),
            tuple(_one(tr, k, 0.0) for k in (1, 2, 3)),
            tuple(_one(rot, k, 0.0) for k in (1, 2, 3, 4)))


def probe_channel(bridge: FoxgloveBridge) -> Any:
    """A ``/probe`` channel on the bridge's context: the client knows its subscription is
    active once a probe message reaches it (no sleep)."""
    from foxglove.channels import FrameTransformsChannel

    return FrameTransformsChannel("/probe", context=bridge.context)


async def collect(port: int, probe_ch: Any, topics: list[str], act: Any, want: int,
                  need_status: int = 0, want_scans: int = 0) -> dict[str, Any]:
    """Subscribe to ``topics``, call ``act()``, gather messages until ``want`` tf batches,
    a time and statuses arrived (bounded: 10 s)."""
    got: dict[str, Any] = {"tf": [], "scan": [], "time": [], "status": []}
    from foxglove.messages import FrameTransforms

    probe = "/probe"
    async with websockets.connect(f"ws://127.0.0.1:{port}",
                                  subprotocols=["foxglove.sdk.v1"], close_timeout=1) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        channels: dict[str, dict[str, Any]] = {}
        with anyio.fail_after(10):
            while not all(t in channels for t in [probe, *topics]):
                msg = await ws.recv()
                if isinstance(msg, str):
                    m = json.loads(msg)
                    if m["op"] == "serverInfo":
                        assert "time" in m["capabilities"]
                    if m["op"] == "advertise":
                        channels.update({c["topic"]: c for c in m["channels"]})
        subs = {k + 1: t for k, t in enumerate(topics)}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": k, "channelId": channels[t]["id"]} for k, t in subs.items()]
            + [{"id": 0, "channelId": channels[probe]["id"]}]}))
        # one subscribe op: once a probe arrives, every subscription above is active
        with anyio.fail_after(10):
            while True:
                probe_ch.log(FrameTransforms(transforms=[]))
                msg = None
                with anyio.move_on_after(0.05):
                    msg = await ws.recv()
                if msg is None:
                    continue
                if isinstance(msg, bytes) and msg[0] == 1 and \
                        struct.unpack_from("<I", msg, 1)[0] == 0:
                    break
        act()
        with anyio.fail_after(10):
            while len(got["tf"]) < want or not got["time"] or len(got["status"]) < need_status \
                    or len(got["scan"]) < want_scans:
                msg = await ws.recv()
                if isinstance(msg, str):
                    m = json.loads(msg)
                    if m["op"] == "status":
                        got["status"].append(m)
                    continue
                if msg[0] == 2:
                    got["time"].append(struct.unpack_from("<Q", msg, 1)[0])
                elif msg[0] == 1:
                    sub, log_time = struct.unpack_from("<IQ", msg, 1)
                    if sub == 0:
                        continue  # a probe still in flight
                    key = "tf" if subs[sub] in ("/tf", "/tf_static") else "scan"
                    got[key].append((log_time, msg[13:]))
                    got.setdefault(subs[sub], []).append((log_time, msg[13:]))
    got["channels"] = channels
    return got


def test_foxglove_client_receives_the_bags_transforms(page: TfPage) -> None:
    timeline = BagTimeline.read(TURTLE)
    full = load_buffer(TURTLE)
    bridge = FoxgloveBridge("127.0.0.1", 0)
    try:
        assert bridge.port != 0
        player = BagPlayer(page, timeline, paused=True, foxglove=bridge)
        player.seek(3.0)
        upto = sum(1 for t in timeline.times if t <= player.time().ns)
        got = asyncio.run(collect(bridge.port, probe_channel(bridge), ["/tf"], player.render, upto))
    finally:
        bridge.close()
    assert got["channels"]["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert got["time"][-1] == player.time().ns
    assert len(got["tf"]) == upto
    assert [lt for lt, _ in got["tf"]] == timeline.times[:upto]
    checked = 0
    for _, payload in got["tf"]:
        for item in fields(payload)[1]:
            stamp, parent, child, xyz, xyzw = frame_transform(item)
            at = Time(0) if stamp == 0 else Time.from_ns(stamp)
            ref = full.lookup_transform(parent, child, at)
            v, q = ref.transform.translation, ref.transform.rotation
            assert xyz == (v.x, v.y, v.z) and xyzw == (q.x, q.y, q.z, q.w)
            checked += 1
    assert checked >= upto
    assert got["status"] == []  # every frame placed in world: no error


def test_tf_errors_arrive_as_status(page: TfPage) -> None:
    timeline = BagTimeline.read(TURTLE)
    bridge = FoxgloveBridge("127.0.0.1", 0)
    try:
        player = BagPlayer(page, timeline, paused=True, foxglove=bridge,
                           fixed_frame="nowhere")
        player.seek(1.0)
        got = asyncio.run(collect(bridge.port, probe_channel(bridge), ["/tf"], player.render,
                                  1, need_status=4))
        core = timeline.buffer_at(player.time())
    finally:
        bridge.close()
    messages = {s["message"] for s in got["status"]}
    assert messages == {f"{name}: {core.try_lookup_transform('nowhere', name, Time(0))}"
                        for name in ("carrot", "turtle1", "turtle2", "world")}
    assert all(s["level"] == 1 for s in got["status"])  # warning


def test_scans_as_foxglove_laser_scan(page: TfPage) -> None:
    timeline = BagTimeline.read(LASER)
    track = ScanTrack.read(LASER, "/scan")
    bridge = FoxgloveBridge("127.0.0.1", 0)
    try:
        player = BagPlayer(page, timeline, paused=True, foxglove=bridge,
                           fixed_frame="odom", scans=[track])
        player.seek(0.5)
        n = sum(1 for t in track.times if t <= player.time().ns)
        got = asyncio.run(collect(bridge.port, probe_channel(bridge), ["/tf", "/scan"],
                                  player.render, 1,
                                  want_scans=n))
    finally:
        bridge.close()
    assert got["channels"]["/scan"]["schemaName"] == "foxglove.LaserScan"
    assert n > 0 and len(got["scan"]) == n
    # foxglove.LaserScan: timestamp=1, frame_id=2, pose=3, start_angle=4, end_angle=5,
    # ranges=6 (packed doubles), intensities=7
    f = fields(got["scan"][0][1])
    scan = track.scans[0]
    assert f[2][0].decode() == scan.header.frame_id
    assert _one(f, 4, 0.0) == pytest.approx(float(scan.angle_min))
    ranges = struct.unpack(f"<{len(f[6][0]) // 8}d", f[6][0])
    np.testing.assert_array_equal(np.asarray(ranges), scan.ranges.astype(np.float64))


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.mark.anyio
async def test_live_bus_relayed_to_foxglove(page: TfPage) -> None:
    """``tfbus view --bus --scan --foxglove``: /tf and /tf_static from a live bus reach a
    Foxglove client as foxglove.FrameTransforms (each equal to lookup_transform), the
    static one sent again for the client that subscribed after it was published (a latched
    topic), the scan as foxglove.LaserScan, the clock's time as server time."""
    from test_view_live import scan

    from tfbus import Header, Quaternion, Transform, TransformStamped, Vector3
    from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink, TfSummary
    from tfbus.view.live import LiveView

    clock = ManualClock(Time.from_sec(10.3))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    bridge = FoxgloveBridge("127.0.0.1", 0)

    def tf(parent: str, child: str, sec: float, x: float) -> TransformStamped:
        return TransformStamped(Header(Time.from_sec(sec), parent), child,
                                Transform(Vector3(x, 0.0, 0.2), Quaternion(0.0, 0.0, 0.0, 1.0)))

    try:
        view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"], foxglove=bridge)
        async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
                anyio.create_task_group() as tg:
            await tg.start(view.follow, bus)
            await StaticTransformBroadcaster(bus).send_transform(
                tf("base_link", "base_laser", 0.0, 0.1))  # before any client connects
            with anyio.fail_after(5):
                while view.relayed < 1:
                    await anyio.sleep(0)
            dyn = TransformBroadcaster(bus)

            async def step() -> None:
                await dyn.send_transform(tf("odom", "base_link", 10.0, 1.0))
                await dyn.send_transform(tf("odom", "base_link", 10.2, 3.0))
                await bus.publish("/scan", scan(10.1))
                with anyio.fail_after(5):
                    while view.relayed < 3:
                        await anyio.sleep(0)
                    view.render()  # the fixed frame (odom) is known: the scan's filter starts
                    await view.wait_passed("/scan", 1)
                view.render()

            got = await anyio.to_thread.run_sync(lambda: asyncio.run(collect(
                bridge.port, probe_channel(bridge), ["/tf", "/tf_static", "/scan"],
                lambda: anyio.from_thread.run(step), 3, want_scans=1)))
            tg.cancel_scope.cancel()
        assert got["channels"]["/tf_static"]["schemaName"] == "foxglove.FrameTransforms"
        assert got["channels"]["/scan"]["schemaName"] == "foxglove.LaserScan"
        assert [lt for lt, _ in got["/tf"]] == [clock.now().ns] * 2
        assert got["time"][-1] == clock.now().ns
        seen = []
        for topic in ("/tf", "/tf_static"):
            for _, payload in got[topic]:
                for item in fields(payload)[1]:
                    stamp, parent, child, xyz, xyzw = frame_transform(item)
                    ref = buffer.lookup_transform(parent, child, Time.from_ns(stamp))
                    v, q = ref.transform.translation, ref.transform.rotation
                    assert xyz == (v.x, v.y, v.z) and xyzw == (q.x, q.y, q.z, q.w)
                    seen.append((topic, parent, child, stamp, xyz[0]))
        assert seen == [("/tf", "odom", "base_link", 10_000_000_000, 1.0),
                        ("/tf", "odom", "base_link", 10_200_000_000, 3.0),
                        ("/tf_static", "base_link", "base_laser", 0, 0.1)]
        f = fields(got["scan"][0][1])
        assert f[2][0].decode() == "base_laser"
        ranges = struct.unpack(f"<{len(f[6][0]) // 8}d", f[6][0])
        assert ranges == (1.0, 2.0, 3.0)
        assert got["status"] == []  # every frame placed in odom
    finally:
        bridge.close()
        buffer.close()


@pytest.mark.anyio
async def test_stamps_foxglove_cannot_carry_are_dropped_and_the_rest_relayed(
    page: TfPage,
) -> None:
    """Stamps at 2**32 s (a Zenoh peer may send up to 2**63 ns; foxglove's Timestamp has
    uint32 seconds) on /tf, /tf_static and a scan: each such transform or scan is
    counted in ``dropped`` and not sent, the transforms beside it are, the static one is
    not sent again to a late /tf_static subscriber, later scans are relayed (before:
    OverflowError ended the relay and ``tfbus view``)."""
    from test_view_live import scan

    from tfbus import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink, TfSummary
    from tfbus.view.live import LiveView

    clock = ManualClock(Time.from_sec(10.3))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    bridge = FoxgloveBridge("127.0.0.1", 0)
    far = Time(2**32)

    def tf(parent: str, child: str, stamp: Time, x: float) -> TransformStamped:
        return TransformStamped(Header(stamp, parent), child,
                                Transform(Vector3(x, 0.0, 0.2), Quaternion(0.0, 0.0, 0.0, 1.0)))

    far_scan = scan(10.1)
    far_scan.header = Header(far, "base_laser")
    try:
        view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"], foxglove=bridge)
        feed = view.feeds["/scan"]
        async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
                anyio.create_task_group() as tg:
            await tg.start(view.follow, bus)
            await bus.publish("/tf_static", TFMessage((
                tf("base_link", "far_static", far, 0.5),
                tf("base_link", "base_laser", Time(0), 0.1))))
            await bus.publish("/scan", far_scan)  # the first scan: relayed on receipt
            with anyio.fail_after(5):
                while view.relayed < 1 or feed.received < 1:
                    await anyio.sleep(0)
            assert bridge.dropped == 2

            async def step() -> None:
                await bus.publish("/tf", TFMessage((tf("odom", "far", far, 7.0),
                                                    tf("odom", "base_link", Time.from_sec(10.0),
                                                       1.0))))
                await bus.publish("/tf", TFMessage((tf("odom", "base_link", Time.from_sec(10.2),
                                                       3.0),)))
                await bus.publish("/scan", scan(10.1))
                with anyio.fail_after(5):
                    while view.relayed < 3:
                        await anyio.sleep(0)
                    view.render()  # sends the statics again; the fixed frame is known
                    while feed.received < 2:
                        await anyio.sleep(0)
                view.render()

            got = await anyio.to_thread.run_sync(lambda: asyncio.run(collect(
                bridge.port, probe_channel(bridge), ["/tf", "/tf_static", "/scan"],
                lambda: anyio.from_thread.run(step), 3, want_scans=1)))
            tg.cancel_scope.cancel()
        seen = []
        for topic in ("/tf", "/tf_static"):
            for _, payload in got[topic]:
                for item in fields(payload)[1]:
                    stamp, parent, child, _xyz, _xyzw = frame_transform(item)
                    seen.append((topic, parent, child, stamp))
        assert seen == [("/tf", "odom", "base_link", 10_000_000_000),
                        ("/tf", "odom", "base_link", 10_200_000_000),
                        ("/tf_static", "base_link", "base_laser", 0)]
        assert len(got["scan"]) == 1
        ts = fields(fields(got["scan"][0][1])[1][0])
        assert _one(ts, 1, 0) * 1_000_000_000 + _one(ts, 2, 0) == 10_100_000_000
        assert bridge.dropped == 3
    finally:
        bridge.close()
        buffer.close()
