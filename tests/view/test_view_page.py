"""The page of ``tfbus view`` (tfbus/view/server.py, player.py; viser): the scene's numbers
read back from the server's scene handles, ids as text, an empty bag, port in use, the
command's errors."""

from __future__ import annotations

import math
import socket
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("viser")

from proc_lines import ProcLines

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.bag import load_buffer
from tfbus.cli import cli
from tfbus.core import BufferCore
from tfbus.view import build_scene
from tfbus.view.player import BagPlayer
from tfbus.view.server import PortInUseError, TfPage
from tfbus.view.timeline import BagTimeline

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"


def test_scene_numbers_equal_lookup_transform(page: TfPage) -> None:
    timeline = BagTimeline.read(TURTLE)
    full = load_buffer(TURTLE)
    player = BagPlayer(page, timeline, paused=True)
    assert player.duration == pytest.approx(21.498641465, abs=1e-6)
    checked = 0
    for k in range(1, 11):
        player.seek(player.duration * k / 10)
        scene = player.render()
        t = player.time()
        shown = timeline.buffer_at(t)
        assert scene.fixed_frame == "world"
        for f in scene.frames:
            handle = page.frames[f.frame_id]
            ref = shown.lookup_transform("world", f.frame_id, Time(0))
            tr, q = ref.transform.translation, ref.transform.rotation
            # viser sends a pose only when not np.allclose to the one sent before (rtol
            # 1e-5, atol 1e-8): the drawn pose is within that of the lookup, never further
            assert tuple(handle.position) == pytest.approx((tr.x, tr.y, tr.z),
                                                           rel=1e-5, abs=1e-8)
            assert tuple(handle.wxyz) == pytest.approx((q.w, q.x, q.y, q.z), rel=1e-5, abs=1e-8)
            assert handle.visible
            # the same pose the whole bag gives at the stamp drawn (replay's view == bag's)
            if ref.header.stamp.ns:
                whole = full.lookup_transform("world", f.frame_id, ref.header.stamp)
                assert whole.transform == ref.transform
                assert ref.header.stamp.ns <= t.ns
            checked += 1
    assert checked == 40
    assert [page.labels[f].text for f in ("carrot", "turtle1", "turtle2", "world")] == \
        ["carrot", "turtle1", "turtle2", "world"]
    assert "/turtle1_tf_broadcaster" in page.panel_html
    assert "<td>carrot</td><td>turtle1</td>" in page.panel_html and "static" in page.panel_html


def test_play_advances_bag_time_at_rate(page: TfPage) -> None:
    timeline = BagTimeline.read(TURTLE)
    player = BagPlayer(page, timeline, paused=False, rate=2.0)
    player.advance(1.5)
    assert player.position == pytest.approx(3.0)
    assert float(player.slider.value) == pytest.approx(3.0)
    player.playing.value = False
    player.advance(1.0)
    assert player.position == pytest.approx(3.0)
    player.playing.value = True
    player.advance(100.0)
    assert player.position == player.duration  # stops at the end
    with pytest.raises(ValueError, match="rate"):
        BagPlayer(page, timeline, rate=20.0)


def test_ids_with_markup_are_text(page: TfPage) -> None:
    core = BufferCore()
    odd = "<img src=x onerror=alert(1)>*b*\x1b[31m"
    core.set_transform(TransformStamped(Header(Time.from_sec(1.0), "world"), odd,
                                        Transform(Vector3(1.0, 2.0, 3.0),
                                                  Quaternion(0.0, 0.0, 0.0, 1.0))), "<script>")
    core.set_transform(TransformStamped(Header(Time.from_sec(1.0), "elsewhere"), "lost",
                                        Transform(Vector3(0.0, 0.0, 0.0),
                                                  Quaternion(0.0, 0.0, 0.0, 1.0))), "x")
    page.draw(build_scene(core, fixed_frame="world"))
    assert "<img" not in page.panel_html and "<script>" not in page.panel_html
    assert "&lt;img src=x onerror=alert(1)&gt;*b*\\x1b[31m" in page.panel_html
    assert "&lt;script&gt;" in page.panel_html
    assert page.labels[odd].text == "<img src=x onerror=alert(1)>*b*\\x1b[31m"
    assert tuple(page.frames[odd].position) == (1.0, 2.0, 3.0)
    # the frame in another tree: hidden, with the core's message in the panel
    assert not page.frames["lost"].visible
    err = str(core.try_lookup_transform("world", "lost", Time(0)))
    assert _html_text(err) in page.panel_html


def _html_text(s: str) -> str:
    import html

    return html.escape(s, quote=True)


def test_bag_without_tf_shows_empty_scene_and_message(page: TfPage, tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "chatter.bag"
    with Writer(bag) as w:
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hello")
        w.write(conn, 1_000_000_000, store.serialize_ros1(msg, "std_msgs/msg/String"))
    timeline = BagTimeline.read(bag)
    player = BagPlayer(page, timeline, paused=True)
    scene = player.render()
    assert scene.frames == () and page.frames == {}
    assert "no transforms received" in page.status_html


def test_served_on_loopback_and_port_in_use(page: TfPage) -> None:
    assert page.host == "127.0.0.1"
    with urllib.request.urlopen(f"http://127.0.0.1:{page.port}/", timeout=10) as resp:
        assert resp.status == 200 and b"<html" in resp.read().lower()
    with pytest.raises(PortInUseError, match=f"127.0.0.1:{page.port}"):
        TfPage("127.0.0.1", page.port)
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE), "--port", str(page.port)])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tfbus view: error: cannot serve on")


def test_without_viser_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser -> ImportError
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE)])
    assert result.exit_code == 2
    assert result.stderr.strip() == ("tfbus view: error: the 'viser' package is not "
                                     "installed: pip install 'tfbus[view]'")


def test_bag_and_bus_together_is_a_usage_error() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE), "--bus", "memory",
                                      "--port", str(port)])
    assert result.exit_code == 2 and "not both" in result.stderr


LASER = DATA / "laser" / "drl_guardian_3.bag"


def test_scan_points_equal_the_projection(page: TfPage) -> None:
    from tfbus.laser import LaserProjection
    from tfbus.sensor_msgs import read_points
    from tfbus.view.scans import ScanTrack

    track = ScanTrack.read(LASER, "/scan")
    assert len(track.scans) == 1036
    timeline = BagTimeline.read(LASER)
    player = BagPlayer(page, timeline, fixed_frame="odom", paused=True, scans=[track])
    drawn = 0
    for k in range(1, 6):
        player.seek(player.duration * k / 6)
        player.render()
        t = player.time()
        core = timeline.buffer_at(t)
        cloud = page.clouds["/scan"]
        assert "/scan" not in player.scan_errors and cloud.visible
        # the newest scan at or before t that tf can place (a fresh scan waits for its tf)
        placed = None
        for scan in reversed(track.scans[: sum(1 for x in track.times if x <= t.ns)]):
            try:
                placed = LaserProjection().transform_laser_scan_to_point_cloud(
                    "odom", scan, core)
                break
            except Exception:
                continue
        assert placed is not None
        ref = read_points(placed, ["x", "y", "z"])
        want = np.stack([ref["x"], ref["y"], ref["z"]], axis=1)
        assert want.shape[0] > 100
        np.testing.assert_array_equal(np.asarray(cloud.points), want)
        drawn += 1
    assert drawn == 5


def test_scan_topic_missing_is_a_usage_error() -> None:
    result = CliRunner().invoke(cli, ["view", "--bag", str(LASER), "--scan", "/nope",
                                      "--port", "0"])
    assert result.exit_code == 2
    assert result.stderr.strip().endswith(
        "no LaserScan topic of that name in " + str(LASER) +
        " (scan topics: /hokuyo_back_scan, /scan)")


def test_bad_bus_is_one_usage_line() -> None:
    result = CliRunner().invoke(cli, ["view", "--bus", "nope", "--scan", "/scan",
                                      "--port", "0"])
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and "nope" in result.stderr
    assert "Traceback" not in result.stderr


def test_command_live_bus_with_scan_and_foxglove() -> None:
    """``tfbus view --bus memory --scan /scan --foxglove PORT`` as a process: both
    addresses printed, the page served, the Foxglove server advertising /tf, /tf_static and
    /scan to a client (subprotocol foxglove.sdk.v1); SIGINT ends it with status 0."""
    import asyncio
    import json
    import signal
    import subprocess

    import anyio
    import websockets

    ports = []
    for _ in range(2):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            ports.append(s.getsockname()[1])
    exe = Path(sys.executable).with_name("tfbus")
    proc = subprocess.Popen([str(exe), "view", "--bus", "memory", "--scan", "/scan",
                             "--port", str(ports[0]), "--foxglove", str(ports[1])],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    async def advertised() -> set[str]:
        topics: set[str] = set()
        async with websockets.connect(f"ws://127.0.0.1:{ports[1]}",
                                      subprotocols=["foxglove.sdk.v1"], close_timeout=1) as ws:
            with anyio.fail_after(10):
                while not {"/tf", "/tf_static", "/scan"} <= topics:
                    raw = await ws.recv()
                    if isinstance(raw, bytes):  # a binary op (the server's time, data)
                        continue
                    m = json.loads(raw)
                    if m["op"] == "advertise":
                        topics |= {c["topic"] for c in m["channels"]}
        return topics

    try:
        lines = ProcLines(proc).until(lambda ls: len(ls) >= 2)
        assert lines[:2] == [f"tfbus view: http://127.0.0.1:{ports[0]}/",
                         f"tfbus view: Foxglove ws://127.0.0.1:{ports[1]}"]
        with urllib.request.urlopen(f"http://127.0.0.1:{ports[0]}/", timeout=10) as resp:
            assert resp.status == 200
        assert asyncio.run(advertised()) >= {"/tf", "/tf_static", "/scan"}
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


def test_command_serves_a_bag_and_stops_on_sigint() -> None:
    """``tfbus view --bag`` as a process: it prints its address, serves the page on
    127.0.0.1, and SIGINT ends it with status 0 (waits bounded; killed by PID if not)."""
    import signal
    import subprocess

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    exe = Path(sys.executable).with_name("tfbus")
    proc = subprocess.Popen([str(exe), "view", "--bag", str(TURTLE), "--port", str(port),
                             "--paused"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert ProcLines(proc).first() == f"tfbus view: http://127.0.0.1:{port}/"
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as resp:
            assert resp.status == 200
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


def test_axes_segments_are_the_turned_unit_axes_for_every_frame_at_once() -> None:
    """The axes of many frames, made in one matrix product of the quaternions' pairwise
    products: each frame's segment k runs from its origin to origin + length x column k
    of its rotation matrix, as transforms3d's ``quat2mat`` gives it (w, x, y, z order
    there), for random unit quaternions of either sign; no frames, no segments."""
    import transforms3d.quaternions as tq

    from tfbus.view.server import _axes

    rng = np.random.default_rng(20261128)
    quats = rng.normal(size=(200, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    origins = rng.uniform(-50.0, 50.0, size=(200, 3))
    segs = _axes(origins, quats, 0.4).reshape(200, 3, 2, 3)
    for i, (x, y, z, w) in enumerate(quats):
        rot = tq.quat2mat([w, x, y, z])
        for k in range(3):
            np.testing.assert_allclose(segs[i, k, 0], origins[i], rtol=0, atol=1e-12)
            np.testing.assert_allclose(segs[i, k, 1], origins[i] + 0.4 * rot[:, k],
                                       rtol=0, atol=1e-12)
    assert _axes(np.zeros((0, 3)), np.zeros((0, 4))).shape == (0, 2, 3)


def test_colour_blocks_of_many_frames_are_each_frames_block_in_order() -> None:
    """The axes' and links' colours of a redraw, made once per distinct fade and gathered:
    exactly each frame's own block one after the other, whether every fade is the same,
    a few differ (0.0 and -0.0 alike), or there are none."""
    import random

    from tfbus.view.server import _axes_block, _blocks, _link_block

    rng = random.Random(20261128)
    pool = [1.0, 0.0, -0.0, 0.5, 0.25, 0.123456]
    for _ in range(200):
        fades = [rng.choice(pool[:rng.randint(1, len(pool))])
                 for _ in range(rng.randint(1, 60))]
        for block in (_axes_block, _link_block):
            expected = np.concatenate([block(f) for f in fades])
            got = _blocks(fades, block)
            assert got.dtype == np.uint8 and np.array_equal(got, expected)
    assert _blocks([], _axes_block).shape == (0, 2, 3)


def test_axes_fade_to_grey_then_hide_as_rviz(page: TfPage) -> None:
    """rviz's TF display: full colour for a third of the frame timeout, then fading to
    grey, then hidden; the axes' colours and ends are read back from the server's node."""
    from tfbus.clock import ManualClock
    from tfbus.view.server import AXES_COLOURS

    clock = ManualClock(Time.from_sec(100.0))
    core = BufferCore()
    s = math.sqrt(0.5)  # "a" rotated +90 degrees about z: its x axis points along +y
    core.set_transform(TransformStamped(Header(clock.now(), "world"), "a", Transform(
        Vector3(1.0, 2.0, 3.0), Quaternion(0.0, 0.0, s, s))), "test")
    last = {"a": clock.now()}

    def drawn() -> tuple[tuple[int, int, int], ...] | None:
        page.draw(build_scene(core, fixed_frame="world", now=clock.now(), last_update=last))
        shown = page.axes_colours("a")
        if shown is not None:  # what the scene node holds: viser's linear colour values
            row = page.axes_rows["a"]
            held = np.asarray(page.axes.colors)[row:row + 3]
            lin = [[round(255 * ((c / 255 + 0.055) / 1.055) ** 2.4) for c in rgb]
                   for rgb in shown]
            assert held.tolist() == [[rgb, rgb] for rgb in lin]
        return shown

    assert drawn() == AXES_COLOURS == ((230, 30, 30), (30, 190, 30), (40, 80, 240))
    assert np.asarray(page.axes.colors)[page.axes_rows["a"]][0].tolist() == [202, 3, 3]
    row = page.axes_rows["a"]
    ends = np.asarray(page.axes.points)[row:row + 3]
    np.testing.assert_allclose(ends, [
        [[1.0, 2.0, 3.0], [1.0, 2.25, 3.0]],   # x along +y
        [[1.0, 2.0, 3.0], [0.75, 2.0, 3.0]],   # y along -x
        [[1.0, 2.0, 3.0], [1.0, 2.0, 3.25]],   # z up
    ], atol=1e-6)
    clock.advance_nowait(5.0)   # the first third of 15 s: still full colour
    assert drawn() == AXES_COLOURS
    clock.advance_nowait(5.0)   # 10 s: half way to grey (128, 128, 128)
    assert drawn() == ((179, 79, 79), (79, 159, 79), (84, 104, 184))
    clock.advance_nowait(5.0)   # 15 s: grey
    assert drawn() == ((128, 128, 128),) * 3
    clock.advance_nowait(0.5)   # beyond the timeout: hidden
    assert drawn() is None and page.frames["a"].visible is False
    last["a"] = clock.now()     # it comes back in full colour
    assert drawn() == AXES_COLOURS and page.frames["a"].visible is True
