"""``tfbus view --cloud TOPIC`` (tfbus/view/clouds.py): sensor_msgs/PointCloud2 from a bag
(ROS 1, .db3, .mcap) and live, decoded (x, y, z; subsampled to a cap), placed in the fixed
frame at the cloud's stamp with the buffer; a cloud whose fields or sizes do not describe
its data is counted with its reason and dropped, the others kept."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest

pytest.importorskip("viser")

from recordings import S45, Cloud, serialize_cloud, tf, write_recording, xyz_cloud

from tfbus import Header, Time
from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.listener import TransformListener
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.sensor_msgs import PointCloud2, PointField, create_cloud_xyz32
from tfbus.view.clouds import MAX_CLOUD_POINTS, CloudTrack, cloud_points
from tfbus.view.live import LiveView
from tfbus.view.player import BagPlayer
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

NAN = float("nan")
# base -> lidar: 0.5 m up, turned 90 degrees about z; odom -> base: x = 1 at 10 s, 2 at 11 s
LIDAR = tf(0.0, "base", "lidar", (0.0, 0.0, 0.5), (0.0, 0.0, S45, S45))
CLOUD_1 = xyz_cloud(10.5, "lidar", [(1, 0, 0), (0, 2, 0), (NAN, 1, 1), (0, 0, 3)], pad=4)
# at 10.5 s the base is at x = 1.5: lidar (x, y, z) is odom (1.5 - y, x, z + 0.5)
PLACED_1 = [[1.5, 1.0, 0.5], [-0.5, 0.0, 0.5], [1.5, 0.0, 3.5]]
CLOUD_2 = xyz_cloud(11.5, "lidar", [(1, 0, 0)])
PLACED_2 = [[2.5, 1.0, 0.5]]  # at 11.5 s, x = 2.5

# clouds whose fields or sizes do not describe their data, and the reason each is dropped
GOOD = xyz_cloud(10.5, "lidar", [(1, 0, 0), (0, 2, 0), (0, 0, 3)])
HOSTILE: list[tuple[Cloud | bytes, str]] = [
    (dataclasses.replace(GOOD, point_step=8, row_step=24), "do not fit point_step 8"),
    (dataclasses.replace(GOOD, data=GOOD.data[:20]), "data has 20 bytes"),
    (dataclasses.replace(GOOD, width=2**31), "width 2147483648"),
    (dataclasses.replace(GOOD, row_step=8), "row_step 8"),
    (dataclasses.replace(GOOD, fields=[("x", 0, 7, 1), ("y", 4, 7, 1)]), "no field 'z'"),
    (dataclasses.replace(GOOD, fields=[("x", 0, 1, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]),
     "field 'x' must be one float32 or float64"),
    (dataclasses.replace(GOOD, fields=[("x", 0, 99, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]),
     "field 'x' must be one float32 or float64"),
]


def recording(tmp_path: Path, fmt: str) -> Path:
    ros1 = fmt == "ros1"
    items: list[tuple[float, str, Any]] = [
        (9.0, "/tf_static", [LIDAR]),
        (10.0, "/tf", [tf(10.0, "odom", "base", (1.0, 0.0, 0.0))]),
        (10.55, "/tf", [tf(11.0, "odom", "base", (2.0, 0.0, 0.0))]),
        (10.6, "/points", CLOUD_1),
    ]
    for k, (cloud, _) in enumerate(HOSTILE):
        items.append((10.7 + 0.01 * k, "/points", cloud))
    items.append((10.8, "/points", serialize_cloud(GOOD, ros1)[:30]))  # cut short
    items += [(11.0, "/points", CLOUD_2),
              (11.2, "/tf", [tf(12.0, "odom", "base", (3.0, 0.0, 0.0))])]
    return write_recording(tmp_path / f"clouds_{fmt}", fmt, items)


@pytest.mark.parametrize("fmt", ["ros1", "db3", "mcap"])
def test_bag_clouds_placed_at_their_stamp_and_hostile_ones_counted(
        page: TfPage, tmp_path: Path, fmt: str, capsys: pytest.CaptureFixture[str]) -> None:
    path = recording(tmp_path, fmt)
    track = CloudTrack.read(path, "/points")
    assert track.dropped.bad == len(HOSTILE) + 1 and track.not_kept == 0
    assert len(track.times) == 2  # the two valid clouds kept, around the hostile ones
    reasons = list(track.dropped.reasons)
    for (_, why), reason in zip(HOSTILE, reasons, strict=False):
        assert why in reason, (why, reason)
    assert sum(track.dropped.reasons.values()) == len(HOSTILE) + 1

    timeline = BagTimeline.read(path)
    player = BagPlayer(page, timeline, fixed_frame="odom", paused=True, clouds=[track])
    start = timeline.start.to_sec()
    player.seek(10.52 - start)
    player.render()
    assert "/points" not in page.clouds
    assert player.scan_errors["/points"] == "/points: no cloud yet"
    player.seek(10.65 - start)
    player.render()
    np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_1,
                               atol=1e-6)
    # the file's dropped clouds are said in the status line (read once, at the start)
    assert f"/points: {len(HOSTILE) + 1} cloud(s) dropped (ValueError: fields do not fit " \
        "point_step 8" in page.status_html
    # at 11.0 cloud 2 (stamp 11.5) cannot be placed yet (odom -> base ends at 11.0): the
    # newest that can, cloud 1, stays drawn
    player.seek(11.05 - start)
    player.render()
    np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_1,
                               atol=1e-6)
    player.seek(11.25 - start)
    player.render()
    np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_2,
                               atol=1e-6)
    assert page.clouds["/points"].visible
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err


def test_a_bag_without_the_topic_is_a_clear_error(tmp_path: Path) -> None:
    path = recording(tmp_path, "mcap")
    with pytest.raises(ValueError, match=r"--cloud '/scan': no PointCloud2 topic of that "
                                         r"name .* \(cloud topics: /points\)"):
        CloudTrack.read(path, "/scan")


def test_cloud_points_decodes_rows_padding_and_byte_order() -> None:
    # two rows of two points, row padding of 3 bytes, big-endian float64 x y z
    fields = [PointField("x", 0, PointField.FLOAT64), PointField("y", 8, PointField.FLOAT64),
              PointField("z", 16, PointField.FLOAT64)]
    pts = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12]], dtype=">f8")
    row = 2 * 24 + 3
    data = b"".join(pts[2 * r:2 * r + 2].tobytes() + b"\0\0\0" for r in range(2))
    cloud = PointCloud2(Header(Time(1), "f"), 2, 2, fields, True, 24, row, data)
    np.testing.assert_array_equal(cloud_points(cloud), pts.astype(np.float32))
    # subsampled: every ceil(4 / 3) = 2nd point, row-major
    np.testing.assert_array_equal(cloud_points(cloud, cap=3), pts[[0, 2]].astype(np.float32))


def test_a_large_cloud_is_subsampled_to_the_cap() -> None:
    n = 250_000
    pts = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
    cloud = create_cloud_xyz32(Header(Time(1), "f"), pts)
    got = cloud_points(cloud)
    k = math.ceil(n / MAX_CLOUD_POINTS)  # 3
    assert len(got) == len(range(0, n, k)) == 83_334 <= MAX_CLOUD_POINTS
    np.testing.assert_array_equal(got, pts[::k])


# ------------------------------------------------------------------ live

def to_cloud(c: Cloud) -> PointCloud2:
    return PointCloud2(Header(Time.from_sec(c.stamp), c.frame_id), c.height, c.width,
                       [PointField(*f) for f in c.fields], c.is_bigendian, c.point_step,
                       c.row_step, c.data)


@asynccontextmanager
async def live_view(page: TfPage) -> AsyncIterator[tuple[LiveView, Bus, TransformBroadcaster]]:
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    view = LiveView(page, buffer, stats, clock, fixed_frame="odom", cloud_topics=["/points"])
    async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:
        await tg.start(view.follow, bus)
        await StaticTransformBroadcaster(bus).send_transform(LIDAR)
        tfb = TransformBroadcaster(bus)
        await tfb.send_transform(tf(10.0, "odom", "base", (1.0, 0.0, 0.0)))
        with anyio.fail_after(5):
            while stats.messages.get("/tf", 0) < 1 or stats.messages.get("/tf_static", 0) < 1:
                await anyio.sleep(0)
        assert view.render().fixed_frame == "odom"
        yield view, bus, tfb
        tg.cancel_scope.cancel()
    buffer.close()


async def until(cond: Any) -> None:
    with anyio.fail_after(5):
        while not cond():
            await anyio.sleep(0)


@pytest.mark.anyio
async def test_live_clouds_wait_for_their_transforms_and_hostile_ones_are_counted(
        page: TfPage) -> None:
    async with live_view(page) as (view, bus, tfb):
        feed = view.cloud_feeds["/points"]
        assert feed.error == "/points: no cloud yet"
        await bus.publish("/points", to_cloud(CLOUD_1))
        await until(lambda: feed.received == 1)
        view.render()  # odom -> base only at 10.0: the cloud at 10.5 waits
        assert "/points" not in page.clouds and feed.drawn == 0
        why = ("/points: Lookup would require extrapolation at time 10.500000000, but only "
               "time 10.000000000 is in the buffer, when looking up transform from frame "
               "[lidar] to frame [odom]")
        assert feed.error == why
        assert "Lookup would require extrapolation at time 10.500000000" in page.status_html

        hostile: list[object] = [to_cloud(c) for c, _ in HOSTILE if isinstance(c, Cloud)]
        hostile += ["not a PointCloud2",
                    dataclasses.replace(to_cloud(GOOD), data="text, not bytes"),
                    dataclasses.replace(to_cloud(GOOD), width=-3),
                    dataclasses.replace(to_cloud(GOOD), header=None)]
        for msg in hostile:
            await bus.publish("/points", msg)
        await until(lambda: feed.received == 1 + len(hostile))
        assert feed.dropped.bad == len(hostile) and len(feed.ready) == 1
        reasons = " | ".join(feed.dropped.reasons)
        for _, why in HOSTILE:
            assert why in reasons
        assert "not a PointCloud2: str" in reasons and "width must be a count" in reasons

        await tfb.send_transform(tf(11.0, "odom", "base", (2.0, 0.0, 0.0)))
        await until(lambda: view.buffer.can_transform("odom", "lidar", Time.from_sec(10.5)))
        view.render()
        np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_1,
                                   atol=1e-6)
        assert feed.drawn == 1 and feed.error is None
        view.render()  # nothing new: not placed again
        assert feed.drawn == 1
        assert f"/points: {len(hostile)} cloud(s) dropped" in page.status_html

        await bus.publish("/points", to_cloud(CLOUD_2))  # 11.5: not placeable yet
        await until(lambda: feed.received == 2 + len(hostile))
        view.render()
        assert feed.drawn == 1  # cloud 1 stays drawn
        await tfb.send_transform(tf(12.0, "odom", "base", (3.0, 0.0, 0.0)))
        await until(lambda: view.buffer.can_transform("odom", "lidar", Time.from_sec(11.5)))
        view.render()
        np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_2,
                                   atol=1e-6)
        assert feed.drawn == 2


async def across(cond: Any) -> None:
    """Wait for what another thread (Zenoh's) delivers until ``cond()`` (bounded: 30 s,
    generous for a loaded machine)."""
    with anyio.fail_after(30):
        while not cond():
            await anyio.sleep(0.005)


@pytest.mark.anyio
async def test_live_clouds_from_another_zenoh_bus(page: TfPage) -> None:
    """``tfbus view --bus zenoh --cloud /points``: PointCloud2s published on one Zenoh bus
    (tfbus's wire, data bit for bit) are drawn by a LiveView following another, on
    127.0.0.1 (no scouting); one the wire refuses (a negative width) is counted by the
    transport as malformed, ones whose layout does not fit by the feed, the valid ones
    drawn."""
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
    view = LiveView(page, buffer, stats, clock, fixed_frame="odom", cloud_topics=["/points"])
    feed = view.cloud_feeds["/points"]
    robot = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="robot")
    viewer = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="viewer")
    async with Bus(transport=robot) as a, Bus(transport=viewer) as b, \
            TransformListener(sink, b, clock=clock), anyio.create_task_group() as tg:
        await tg.start(view.follow, b)
        with anyio.fail_after(10):
            await robot.wait_matching("/points")
            await robot.wait_matching("/tf")
            await robot.wait_matching("/tf_static")
        await StaticTransformBroadcaster(a).send_transform(LIDAR)
        tfb = TransformBroadcaster(a)
        await tfb.send_transform(tf(10.0, "odom", "base", (1.0, 0.0, 0.0)))
        await tfb.send_transform(tf(11.0, "odom", "base", (2.0, 0.0, 0.0)))
        # The static transform can arrive twice: live, and again in the late-join reply
        # of the latched topic when that query crosses the publication (the same
        # transform; storing it again changes nothing).
        await across(lambda: stats.messages.get("/tf", 0) == 2
                     and stats.messages.get("/tf_static", 0) >= 1)
        await a.publish("/points", dataclasses.replace(to_cloud(GOOD), width=-1))
        for cloud, _ in HOSTILE[:3]:
            assert isinstance(cloud, Cloud)
            await a.publish("/points", to_cloud(cloud))
        await a.publish("/points", to_cloud(CLOUD_1))
        await across(lambda: feed.received == 4 and viewer.statistics().malformed == 1)
        assert feed.dropped.bad == 3 and len(feed.ready) == 1
        view.render()
        np.testing.assert_allclose(np.asarray(page.clouds["/points"].points), PLACED_1,
                                   atol=1e-6)
        (_, header, pts) = feed.ready[0]
        assert header == Header(Time.from_sec(10.5), "lidar")
        np.testing.assert_array_equal(pts, cloud_points(to_cloud(CLOUD_1)))
        tg.cancel_scope.cancel()
    buffer.close()


def test_the_wire_carries_a_cloud_bit_for_bit_and_refuses_wrong_types() -> None:
    from tfbus.codecs.native import WireCodec
    from tfbus.errors import WireDecodeError, WireLimitError

    codec = WireCodec()
    cloud = to_cloud(CLOUD_1)
    back = codec.decode(codec.encode(cloud, sender=7, seq=3))
    assert (back.sender, back.seq) == (7, 3)
    got = back.message
    assert isinstance(got, PointCloud2) and got.header == cloud.header
    assert (got.height, got.width, got.fields, got.point_step, got.row_step, got.data,
            got.is_bigendian, got.is_dense) == (
        cloud.height, cloud.width, cloud.fields, cloud.point_step, cloud.row_step,
        cloud.data, cloud.is_bigendian, cloud.is_dense)
    bad = [dataclasses.replace(cloud, width=-1), dataclasses.replace(cloud, point_step=2**32),
           dataclasses.replace(cloud, fields=[PointField("x", 0, 300)])]
    for msg in bad:
        with pytest.raises(WireDecodeError):
            codec.decode(codec.encode(msg, sender=1, seq=1))
    many = dataclasses.replace(cloud, fields=[PointField(f"f{k}", 0, 7) for k in range(257)])
    with pytest.raises(WireLimitError):
        codec.decode(codec.encode(many, sender=1, seq=1))


def test_a_bag_cloud_in_chromium_and_hostile_names_as_text(chromium: str, page: TfPage,
                                                           tmp_path: Path) -> None:
    """A ring of 2 000 points 2 m around the lidar, drawn in headless Chromium (the
    screenshot shows it: magenta points around the base); a cloud whose field is named
    ``<b>z</b>`` is dropped and its reason shown as text, no element made from it."""
    from cdp import Chromium

    angles = np.linspace(0.0, 2 * np.pi, 2000, endpoint=False)
    ring = np.stack([2 * np.cos(angles), 2 * np.sin(angles), np.zeros_like(angles)], axis=1)
    odd = dataclasses.replace(GOOD, fields=[("x", 0, 7, 1), ("y", 4, 7, 1),
                                            ("<b>z</b>", 8, 7, 1)])
    path = write_recording(tmp_path / "ring", "mcap", [
        (9.0, "/tf_static", [LIDAR]),
        (10.0, "/tf", [tf(10.0, "odom", "base", (1.0, 0.0, 0.0))]),
        (10.1, "/points", odd),
        (10.2, "/points", xyz_cloud(10.0, "lidar", ring.tolist())),
    ])
    track = CloudTrack.read(path, "/points")
    player = BagPlayer(page, BagTimeline.read(path), fixed_frame="odom", paused=True,
                       clouds=[track])
    player.seek(10.5 - 9.0)
    player.render()
    assert "/points" in page.clouds, (player.scan_errors, track)
    drawn = np.asarray(page.clouds["/points"].points)
    # lidar (x, y, 0) is odom (1 - y, x, 0.5)
    np.testing.assert_allclose(drawn, np.stack([1 - ring[:, 1], ring[:, 0],
                                                np.full(len(ring), 0.5)], axis=1), atol=1e-6)
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("document.body && document.body.innerText.includes('cloud(s) dropped')")
        text = c.js("document.body.innerText")
        assert "/points: 1 cloud(s) dropped (ValueError: PointCloud2 has no field 'z' " \
            "(fields: ['<b>z</b>', 'x', 'y']))" in text
        assert c.js("[...document.querySelectorAll('b')].filter(e => e.textContent === 'z')"
                    ".length") == 0
        shot = c.screenshot(tmp_path.parent / "cloud_ring.png")
        assert len(shot) > 10_000
