"""``tfbus view --bus SPEC --scan TOPIC`` (tfbus/view/live.py): LaserScans from a live bus
wait for their transforms in a MessageFilter, are projected into the fixed frame and drawn,
at most one projection per redraw; a bad message on the topic is counted and dropped."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import numpy as np
import pytest

pytest.importorskip("viser")

from proc_lines import ProcLines
from ros1_harness import master_fixture, ros1_fixture  # noqa: F401  (registers fixtures)

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.broadcaster import TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.laser import LaserProjection
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.sensor_msgs import LaserScan, read_points
from tfbus.view.live import LiveView, ScanFeed
from tfbus.view.server import TfPage

pytestmark = pytest.mark.anyio


def odom_to_laser(sec: float, x: float) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(sec), "odom"), "base_laser",
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def scan(sec: float) -> LaserScan:
    """Three beams at 0, 90 and 180 degrees, 10 ms apart (a 20 ms sweep)."""
    return LaserScan(header=Header(Time.from_sec(sec), "base_laser"), angle_min=0.0,
                     angle_max=math.pi, angle_increment=math.pi / 2, time_increment=0.01,
                     scan_time=0.1, range_min=0.1, range_max=10.0,
                     ranges=np.array([1.0, 2.0, 3.0], dtype=np.float32))


def xyz(cloud: Any) -> np.ndarray:
    pts = read_points(cloud, ["x", "y", "z"])
    return np.stack([pts["x"], pts["y"], pts["z"]], axis=1)


async def until(cond: Any) -> None:
    """Let the bus deliver until ``cond()`` (bounded: 5 s, then the test fails)."""
    with anyio.fail_after(5):
        while not cond():
            await anyio.sleep(0)


@dataclasses.dataclass
class Live:
    """A LiveView following ``/scan`` on an in-process bus, ``odom -> base_laser`` sent
    at 10 s (the fixed frame is ``odom``)."""

    view: LiveView
    buffer: Buffer
    bus: Bus
    tfb: TransformBroadcaster

    @property
    def feed(self) -> ScanFeed:
        return self.view.feeds["/scan"]


@asynccontextmanager
async def live_view(page: TfPage) -> AsyncIterator[Live]:
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"])
    async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:
        await tg.start(view.follow, bus)
        tfb = TransformBroadcaster(bus)
        await tfb.send_transform(odom_to_laser(10.0, 1.0))
        await until(lambda: stats.messages.get("/tf", 0) == 1)
        assert view.render().fixed_frame == "odom"
        yield Live(view, buffer, bus, tfb)
        tg.cancel_scope.cancel()
    buffer.close()


async def test_live_scans_wait_for_transforms_and_are_drawn(page: TfPage) -> None:
    async with live_view(page) as live:
        view, buffer, bus, tfb, feed = live.view, live.buffer, live.bus, live.tfb, live.feed
        assert feed.error == "/scan: no scan yet" and "/scan" not in page.clouds

        await bus.publish("/scan", scan(10.1))  # its transforms (10.1, 10.12) are not there
        await until(lambda: feed.received == 1)
        view.render()
        assert feed.passed == 0 and feed.drawn == 0 and "/scan" not in page.clouds
        assert feed.error == "/scan: waiting for the transforms of 1 scan(s)"
        assert "waiting for the transforms" in page.status_html

        await tfb.send_transform(odom_to_laser(10.2, 3.0))  # now they can be interpolated
        with anyio.fail_after(5):
            await view.wait_passed("/scan", 1)
        view.render()
        assert feed.drawn == 1 and feed.error is None
        drawn = np.asarray(page.clouds["/scan"].points)
        # beam k at 10.1 + 0.01 k: the laser at x = 2.0, 2.1, 2.2 (laser_geometry's slerp
        # between the first and last beam's transforms)
        np.testing.assert_allclose(drawn, [[3.0, 0.0, 0.0], [2.1, 2.0, 0.0], [-0.8, 0.0, 0.0]],
                                   atol=1e-5)
        ref = LaserProjection().transform_laser_scan_to_point_cloud("odom", scan(10.1), buffer)
        np.testing.assert_array_equal(drawn, xyz(ref).astype(np.float32))

        await bus.publish("/scan", "not a LaserScan")  # a bad message: counted, dropped
        await until(lambda: feed.bad == 1)

        for k in range(5):  # five more scans between two redraws: one projection drawn
            await bus.publish("/scan", scan(10.13 + 0.01 * k))
        with anyio.fail_after(5):
            await view.wait_passed("/scan", 6)
        view.render()
        view.render()
        assert (feed.received, feed.passed, feed.bad, feed.dropped, feed.drawn) == (6, 6, 1, 0, 2)
        newest = LaserProjection().transform_laser_scan_to_point_cloud("odom", scan(10.17),
                                                                       buffer)
        np.testing.assert_array_equal(np.asarray(page.clouds["/scan"].points),
                                      xyz(newest).astype(np.float32))
        assert page.clouds["/scan"].visible


async def test_a_first_scan_without_a_finite_sweep_is_dropped(page: TfPage) -> None:
    """The first scan of a topic sizes the filter's tolerance (its sweep); one with
    ``time_increment = inf`` and three beams has none: it is counted in ``dropped`` and
    the next scan sizes it, passes and is drawn (before: Duration.from_sec(inf) raised
    ValueError out of the view, and ``tfbus view`` exited)."""
    async with live_view(page) as live:
        view, bus, tfb, feed = live.view, live.bus, live.tfb, live.feed
        await bus.publish("/scan", dataclasses.replace(scan(10.1), time_increment=math.inf))
        await until(lambda: feed.dropped == 1)
        await bus.publish("/scan", scan(10.1))
        await tfb.send_transform(odom_to_laser(10.2, 3.0))
        with anyio.fail_after(5):
            await view.wait_passed("/scan", 1)
        view.render()
        assert (feed.received, feed.passed, feed.dropped, feed.drawn) == (2, 1, 1, 1)
        assert feed.error is None


async def test_live_view_draws_scans_from_another_zenoh_bus(page: TfPage) -> None:
    """``tfbus view --bus zenoh --scan /scan`` across processes: a LaserScan
    published on one Zenoh bus is drawn by a LiveView following another, on 127.0.0.1
    (no scouting), exactly as the same scan projected in-process."""
    pytest.importorskip("zenoh")
    import socket

    from tfbus.transports.zenoh import ZenohTransport

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"])
    feed = view.feeds["/scan"]
    robot = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="robot")
    viewer = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="viewer")
    async with Bus(transport=robot) as a, Bus(transport=viewer) as b, \
            TransformListener(sink, b, clock=clock), anyio.create_task_group() as tg:
        await tg.start(view.follow, b)
        with anyio.fail_after(5):
            await robot.wait_matching("/scan")
            await robot.wait_matching("/tf")
        tfb = TransformBroadcaster(a)
        await tfb.send_transform(odom_to_laser(10.0, 1.0))
        await tfb.send_transform(odom_to_laser(10.2, 3.0))
        await until(lambda: stats.messages.get("/tf", 0) == 2)
        assert view.render().fixed_frame == "odom"
        await a.publish("/scan", scan(10.1))
        with anyio.fail_after(5):
            await view.wait_passed("/scan", 1)
        view.render()
        assert (feed.received, feed.passed, feed.bad, feed.drawn) == (1, 1, 0, 1)
        drawn = np.asarray(page.clouds["/scan"].points)
        np.testing.assert_allclose(drawn, [[3.0, 0.0, 0.0], [2.1, 2.0, 0.0], [-0.8, 0.0, 0.0]],
                                   atol=1e-5)
        ref = LaserProjection().transform_laser_scan_to_point_cloud("odom", scan(10.1), buffer)
        np.testing.assert_array_equal(drawn, xyz(ref).astype(np.float32))
        tg.cancel_scope.cancel()
    buffer.close()


async def test_live_view_draws_a_real_ros1_laser(master: Any) -> None:
    """``tfbus view --bus ros1 --scan /scan``: Debian's ``rostopic pub``
    publishes a sensor_msgs/LaserScan and tf2_ros's static_transform_publisher the laser's
    pose on a loopback roscore; the bus opened from the spec with the scan topic receives
    both and the LiveView draws the scan where laser_geometry puts it."""
    pytest.importorskip("rosbags")
    from ros1_harness import assert_is_the_yaml_scan, rostopic_scan_publisher

    from tfbus.transports.spec import open_bus

    page = TfPage("127.0.0.1", 0)
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"])
    feed = view.feeds["/scan"]
    static = master.run("rosrun", "tf2_ros", "static_transform_publisher", "1", "0", "0",
                        "0", "0", "0", "1", "odom", "base_laser")
    laser = rostopic_scan_publisher(master)
    try:
        async with open_bus("ros1", default_name="tfbus-view", scan_topics=["/scan"]) as bus, \
                TransformListener(sink, bus, clock=clock), anyio.create_task_group() as tg:
            raw = bus.subscribe("/scan")
            await tg.start(view.follow, bus)
            await buffer.wait_for_transform("odom", "base_laser", Time(0), timeout=40.0)
            assert view.render().fixed_frame == "odom"
            with anyio.fail_after(40):
                got = await raw.receive()
                await view.wait_passed("/scan", 1)
            assert_is_the_yaml_scan(got)
            view.render()
            assert feed.drawn == 1 and feed.error is None and feed.bad == 0
            drawn = np.asarray(page.clouds["/scan"].points)
            # beams at 0, 90, 180 degrees (float32 angles); NaN and inf are not drawn
            np.testing.assert_allclose(drawn, [[2.0, 0.0, 0.0], [1.0, 2.0, 0.0],
                                               [-2.0, 0.0, 0.0]], atol=1e-5)
            ref = LaserProjection().transform_laser_scan_to_point_cloud("odom", got, buffer)
            np.testing.assert_array_equal(drawn, xyz(ref).astype(np.float32))
            tg.cancel_scope.cancel()
    finally:
        laser.stop()
        static.stop()
        buffer.close()
        page.close()


def test_command_view_bus_ros1_subscribes_to_the_scan(master: Any) -> None:
    """``tfbus view --bus ros1 --scan /scan`` as a process on a loopback roscore: its node
    registers as a subscriber of /scan, and its slave API lists /scan as a
    sensor_msgs/LaserScan subscription (the type rostopic's publisher must match);
    SIGINT ends it with status 0."""
    import signal
    import socket
    import subprocess
    import sys
    import time
    import xmlrpc.client
    from pathlib import Path

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    exe = Path(sys.executable).with_name("tfbus")
    proc = subprocess.Popen([str(exe), "view", "--bus", "ros1", "--scan", "/scan",
                             "--port", str(port)], env=master.env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert ProcLines(proc).first() == f"tfbus view: http://127.0.0.1:{port}/"
        nodes: list[str] = []
        deadline = time.monotonic() + 40
        while not nodes and time.monotonic() < deadline:  # bounded: registration
            subs = master.call("getSystemState", "/tfbus_test")[1]
            nodes = [n for t, ns in subs if t == "/scan" for n in ns]
            if not nodes:
                time.sleep(0.1)
        assert len(nodes) == 1 and nodes[0].startswith("/tfbus_view_")
        api = master.call("lookupNode", "/tfbus_test", nodes[0])
        code, _, subscribed = xmlrpc.client.ServerProxy(api).getSubscriptions("/tfbus_test")
        assert code == 1
        assert ["/scan", "sensor_msgs/LaserScan"] in subscribed
        assert ["/tf", "tf2_msgs/TFMessage"] in subscribed
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


async def test_redraws_wait_until_the_zenoh_intake_caught_up(page: TfPage) -> None:
    """A redraw costs milliseconds per frame; drawing at 30 Hz whatever the intake let a
    busy ``tfbus view --bus`` fall behind, and Zenoh's inbound queue grew by every
    message that arrived meanwhile (the soak: +52 MB in 28 min). Now a redraw is put off
    (counted in ``deferred``) while the transport holds received messages not delivered,
    for at most MAX_DRAW_STALL s on the view's clock; once delivered, the redraw shows
    the newest pose."""
    pytest.importorskip("zenoh")
    import socket
    import time

    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.view.live import MAX_DRAW_STALL

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    view = LiveView(page, buffer, stats, clock)
    robot = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="robot")
    viewer = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="viewer")

    def queued(n: int) -> None:
        """Block the event loop (nothing is delivered) until Zenoh's threads queued
        ``n`` messages for it (bounded: 20 s)."""
        deadline = time.monotonic() + 20.0
        while viewer.pending < n:
            assert time.monotonic() < deadline, f"{viewer.pending} of {n} queued"
            time.sleep(0.001)

    async with Bus(transport=robot) as a, Bus(transport=viewer) as b, \
            TransformListener(sink, b, clock=clock):
        with anyio.fail_after(10):
            await robot.wait_matching("/tf")
        tfb = TransformBroadcaster(a)
        await tfb.send_transform(odom_to_laser(10.0, 1.0))
        # the first /tf delivered and nothing else left in the intake (a liveliness or
        # latch sample may still be queued when the /tf is counted, on a loaded machine)
        await until(lambda: stats.messages.get("/tf", 0) == 1 and viewer.pending == 0)
        assert view.redraw(b) is not None and view.deferred == 0
        assert page.frames["base_laser"].position == pytest.approx((1.0, 0.0, 0.0))

        for k in range(1, 21):  # a burst the event loop has not delivered yet
            a.publish_nowait("/tf", TFMessage([odom_to_laser(10.0 + 0.01 * k, 1.0 + k)]))
        queued(20)
        assert view.redraw(b) is None and view.deferred == 1  # the intake goes first
        assert view.redraw(b) is None and view.deferred == 2
        assert page.frames["base_laser"].position == pytest.approx((1.0, 0.0, 0.0))
        await until(lambda: viewer.pending == 0 and stats.messages.get("/tf", 0) == 21)
        assert view.redraw(b) is not None and view.deferred == 2
        assert page.frames["base_laser"].position == pytest.approx((21.0, 0.0, 0.0))

        # behind for MAX_DRAW_STALL s of the view's clock: drawn all the same
        for k in range(21, 31):
            a.publish_nowait("/tf", TFMessage([odom_to_laser(10.0 + 0.01 * k, 1.0 + k)]))
        queued(10)
        clock.advance_nowait(MAX_DRAW_STALL * 0.5)
        assert view.redraw(b) is None and view.deferred == 3
        clock.advance_nowait(MAX_DRAW_STALL * 0.5)
        assert view.redraw(b) is not None and view.deferred == 3
        assert viewer.pending == 10  # drawn before the backlog: the older pose
        assert page.frames["base_laser"].position == pytest.approx((21.0, 0.0, 0.0))
    buffer.close()
