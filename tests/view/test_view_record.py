"""Recording what ``tfbus view`` receives to MCAP (tfbus/view/record.py): ``--record PATH``
and the page's "record" folder (names inside ``--record-dir`` only), written with the
Foxglove SDK as ROS 2 CDR messages, read back with tfbus.bag and the ``mcap`` library to
exactly the transforms received; bounded by size and duration; bad paths a clear error."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("viser")
pytest.importorskip("foxglove")

from proc_lines import ProcLines
from recordings import S45, tf, write_recording, xyz_cloud
from test_view_controls import _centre, _row, until

from tfbus import Header, Time
from tfbus.bag import read_messages
from tfbus.broadcaster import StaticTransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.cli import cli
from tfbus.clock import ManualClock
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage, TransformStamped
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField
from tfbus.view.clouds import CloudTrack
from tfbus.view.live import LiveView
from tfbus.view.player import BagPlayer
from tfbus.view.record import McapRecorder, RecordControl, RecordError, record_path
from tfbus.view.scans import ScanTrack
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
LIDAR = tf(0.0, "base", "lidar", (0.0, 0.0, 0.5), (0.0, 0.0, S45, S45))


def read_back(path: Path) -> list[tuple[int, str, tuple[TransformStamped, ...]]]:
    """(log time ns, topic, transforms) of every tf message, as tfbus.bag reads them."""
    return [(m.time.ns, m.topic, tuple(m.message.transforms)) for m in read_messages(path)]


def mcap_records(path: Path) -> list[tuple[str, str, str, str, int]]:
    """(topic, schema name, schema encoding, message encoding, log time) of every message,
    as the ``mcap`` library reads them."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        return [(ch.topic, sc.name, sc.encoding, ch.message_encoding, msg.log_time)
                for sc, ch, msg in reader.iter_messages(log_time_order=False)]


# ------------------------------------------------------------------ names and paths

@pytest.mark.parametrize("name", ["../x", "/etc/passwd", "a/b", "", ".hidden", "<b>x</b>",
                                  "x" * 101, "run 1", "a\x1bb", "..", "run\\1"])
def test_a_name_from_the_page_must_be_a_plain_file_name(tmp_path: Path, name: str) -> None:
    with pytest.raises(RecordError, match="a name inside the record directory, not a path"):
        record_path(tmp_path, name)


def test_a_name_is_a_new_mcap_file_inside_the_directory(tmp_path: Path) -> None:
    assert record_path(tmp_path, "run-1") == tmp_path / "run-1.mcap"
    assert record_path(tmp_path, "run_2.mcap") == tmp_path / "run_2.mcap"
    (tmp_path / "taken.mcap").write_bytes(b"")
    with pytest.raises(RecordError, match=r"record file 'taken\.mcap' exists already"):
        record_path(tmp_path, "taken")


def test_unwritable_and_missing_paths_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(RecordError, match=r"cannot record to /proc/tfbus-view\.mcap: "):
        McapRecorder(Path("/proc/tfbus-view.mcap"))  # a file system that refuses files
    with pytest.raises(RecordError, match=r"folder .*/nowhere does not exist"):
        McapRecorder(tmp_path / "nowhere" / "x.mcap")
    (tmp_path / "old.mcap").write_bytes(b"keep")
    with pytest.raises(RecordError, match="the file exists"):
        McapRecorder(tmp_path / "old.mcap")
    assert (tmp_path / "old.mcap").read_bytes() == b"keep"
    if os.geteuid() != 0:  # root writes into a read-only folder anyway
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        with pytest.raises(RecordError, match="is not writable"):
            McapRecorder(ro / "x.mcap")


def test_cli_refuses_an_unwritable_record_path_in_one_line(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE), "--port", "0",
                                      "--record", str(tmp_path / "no" / "x.mcap")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines()[-1].endswith(
        f"--record: cannot record to {tmp_path / 'no' / 'x.mcap'}: folder "
        f"{tmp_path / 'no'} does not exist")
    assert "Traceback" not in result.output
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE), "--port", "0",
                                      "--record-dir", str(tmp_path / "nodir")])
    assert result.exit_code == 2 and "'--record-dir'" in result.output
    result = CliRunner().invoke(cli, ["view", "--bus", "ros2", "--cloud", "/points"])
    assert result.exit_code == 2 and "--cloud: PointCloud2 topics are carried by --bus " \
        "zenoh and memory (and read from a --bag), not by 'ros2'" in result.output


def test_the_page_starts_at_most_its_number_of_recordings(page: TfPage,
                                                         tmp_path: Path) -> None:
    from tfbus.view.record import MAX_PAGE_RECORDINGS

    ctl = RecordControl(page, directory=tmp_path)
    ctl.name_box.value = "first"
    ctl._on_start(None)
    assert ctl.active is not None and ctl.page_starts == 1
    ctl.page_starts = MAX_PAGE_RECORDINGS - 1
    ctl.name_box.value = "last"
    ctl._on_start(None)  # the previous one ended, this one started
    assert ctl.active is not None and ctl.active.path == tmp_path / "last.mcap"
    ctl.name_box.value = "one-more"
    ctl._on_start(None)
    assert "100 recordings started from the page already" in ctl.status_html
    assert ctl.active is not None and ctl.active.path == tmp_path / "last.mcap"
    ctl.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.mcap", "last.mcap"]


# ------------------------------------------------------------------ caps

def test_the_size_and_duration_caps_end_a_recording_that_stays_readable(
        tmp_path: Path) -> None:
    msgs = [[tf(float(k), "odom", "base", (float(k), 0.0, 0.0))] for k in range(100)]
    size = len(__import__("tfbus.codecs.cdr", fromlist=["encode_tf"]).encode_tf(msgs[0]))
    rec = McapRecorder(tmp_path / "size.mcap", max_bytes=10 * size)
    written = [rec.write_tf(m, False, Time.from_sec(k).ns) for k, m in enumerate(msgs)]
    assert written == [True] * 10 + [False] * 90
    assert rec.stopped == f"reached its cap of {10 * size} bytes"
    assert [t for _, _, t in read_back(tmp_path / "size.mcap")] == [tuple(m) for m in msgs[:10]]

    rec = McapRecorder(tmp_path / "time.mcap", max_seconds=2.5)
    written = [rec.write_tf(m, False, Time.from_sec(100 + k).ns) for k, m in enumerate(msgs)]
    assert written == [True] * 3 + [False] * 97  # 100, 101, 102 s; 103 is past 2.5 s
    assert rec.stopped == "reached its cap of 2.5 s"
    assert len(read_back(tmp_path / "time.mcap")) == 3
    rec.close()  # idempotent
    assert rec.stopped == "reached its cap of 2.5 s"


# ------------------------------------------------------------------ a bag

def test_a_bag_recorded_as_it_plays_reads_back_to_its_messages(page: TfPage,
                                                                tmp_path: Path) -> None:
    timeline = BagTimeline.read(TURTLE)
    out = tmp_path / "turtle.mcap"
    ctl = RecordControl(path=out)
    player = BagPlayer(page, timeline, paused=True, record=ctl)
    player.render()  # at the bag's start, as ``tfbus view --bag --record`` starts
    half = player.duration / 2
    player.seek(half)
    player.render()
    player.seek(half / 2)  # a jump back: nothing written twice
    player.render()
    player.seek(player.duration)
    player.render()
    ctl.close()
    want = [(m.time.ns, m.topic, tuple(m.message.transforms)) for m in read_messages(TURTLE)]
    got = read_back(out)
    assert got == want and len(got) > 100
    recs = mcap_records(out)
    assert {(t, s, e, me) for t, s, e, me, _ in recs} == {
        (topic, "tf2_msgs/msg/TFMessage", "ros2msg", "cdr") for topic in ("/tf", "/tf_static")}
    assert sorted(r[4] for r in recs) == [w[0] for w in want]


def test_a_recording_started_mid_bag_begins_with_its_statics(page: TfPage,
                                                             tmp_path: Path) -> None:
    path = write_recording(tmp_path / "b", "mcap", [
        (9.0, "/tf_static", [LIDAR]),
        (10.0, "/tf", [tf(10.0, "odom", "base", (1.0, 0.0, 0.0))]),
        (10.6, "/points", xyz_cloud(10.0, "lidar", [(1, 2, 3), (4, 5, 6)])),
        (11.0, "/tf", [tf(11.0, "odom", "base", (2.0, 0.0, 0.0))]),
        (11.5, "/points", xyz_cloud(11.0, "lidar", [(7, 8, 9)])),
        (12.0, "/tf", [tf(12.0, "odom", "base", (3.0, 0.0, 0.0))]),
    ])
    timeline = BagTimeline.read(path)
    track = CloudTrack.read(path, "/points")
    ctl = RecordControl(directory=tmp_path)
    player = BagPlayer(page, timeline, paused=True, clouds=[track], record=ctl)
    player.seek(10.8 - 9.0)
    player.render()
    out = ctl.start(record_path(tmp_path, "mid")).path
    player.seek(3.0)
    player.render()
    ctl.stop()
    assert read_back(out) == [
        (Time.from_sec(9.0).ns, "/tf_static", (LIDAR,)),
        (Time.from_sec(11.0).ns, "/tf", (tf(11.0, "odom", "base", (2.0, 0.0, 0.0)),)),
        (Time.from_sec(12.0).ns, "/tf", (tf(12.0, "odom", "base", (3.0, 0.0, 0.0)),)),
    ]
    back = CloudTrack.read(out, "/points")  # the cloud shown after the start, as drawn
    assert back.times == [Time.from_sec(11.5).ns] and back.frames == ["lidar"]
    assert back.stamps == [Time.from_sec(11.0)]
    np.testing.assert_array_equal(back.points[0], [[7, 8, 9]])


# ------------------------------------------------------------------ live

@pytest.mark.anyio
async def test_live_recording_reads_back_to_exactly_what_was_received(
        page: TfPage, tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    clock = ManualClock(Time.from_sec(100.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    static_early = tf(0.0, "map", "odom", (5.0, 0.0, 0.0))
    ctl = RecordControl(directory=tmp_path)
    view = LiveView(page, buffer, stats, clock, scan_topics=["/scan"],
                    cloud_topics=["/points"], record=ctl)
    sent: list[tuple[int, str, tuple[TransformStamped, ...]]] = []
    scan = LaserScan(header=Header(Time.from_sec(100.5), "lidar"), angle_min=0.0,
                     angle_max=1.0, angle_increment=0.5, time_increment=0.0, scan_time=0.1,
                     range_min=0.1, range_max=10.0,
                     ranges=np.array([1.0, 2.0, 3.0], dtype=np.float32))
    cloud = PointCloud2(Header(Time.from_sec(100.5), "lidar"), 1, 2,
                        [PointField("x", 0, 7), PointField("y", 4, 7), PointField("z", 8, 7)],
                        False, 12, 24, np.array([1, 2, 3, 4, 5, 6], "<f4").tobytes())
    async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:
        await tg.start(view.follow, bus)
        stb = StaticTransformBroadcaster(bus)
        await stb.send_transform(static_early)  # before the recording: written at its start
        with anyio.fail_after(5):
            while stats.messages.get("/tf_static", 0) < 1:
                await anyio.sleep(0)
        await clock.advance(0.25)
        ctl.start(out)
        for k in range(3):
            msg = [tf(100.25 + k, "odom", "base", (float(k), 0.0, 0.0)),
                   tf(100.25 + k, "base", "arm", (0.0, float(k), 0.0))]
            await bus.publish("/tf", TFMessage(msg))
            with anyio.fail_after(5):
                while stats.messages.get("/tf", 0) < k + 1:
                    await anyio.sleep(0)
            if k == 0:
                sent.append((clock.now().ns, "/tf_static", (static_early,)))
            sent.append((clock.now().ns, "/tf", tuple(msg)))
            await clock.advance(1.0)
        await stb.send_transform(LIDAR)
        await bus.publish("/scan", scan)
        await bus.publish("/points", cloud)
        await bus.publish("/points", "not a cloud")  # counted, not recorded
        with anyio.fail_after(5):
            while view.cloud_feeds["/points"].received < 2 \
                    or stats.messages.get("/tf_static", 0) < 2 \
                    or view.feeds["/scan"].received < 1:
                await anyio.sleep(0)
        sent.append((clock.now().ns, "/tf_static", (LIDAR,)))  # as received
        view.render()
        ctl.stop()
        await bus.publish("/tf", TFMessage([tf(200.0, "odom", "base", (9.0, 0.0, 0.0))]))
        with anyio.fail_after(5):
            while stats.messages.get("/tf", 0) < 4:
                await anyio.sleep(0)
        tg.cancel_scope.cancel()
    buffer.close()
    assert ctl.status_html == "" or "recorded (stopped) live.mcap" in ctl.status_html
    assert read_back(out) == sent
    recs = mcap_records(out)
    assert [(t, s) for t, s, _, _, _ in recs if t not in ("/tf", "/tf_static")] == [
        ("/scan", "sensor_msgs/msg/LaserScan"), ("/points", "sensor_msgs/msg/PointCloud2")]
    (got,) = ScanTrack.read(out, "/scan").scans
    assert got.header == scan.header
    np.testing.assert_array_equal(got.ranges, scan.ranges)
    back = CloudTrack.read(out, "/points")
    np.testing.assert_array_equal(back.points[0], [[1, 2, 3], [4, 5, 6]])
    assert back.stamps == [Time.from_sec(100.5)] and back.frames == ["lidar"]


# ------------------------------------------------------------------ the page's control

def _button(label: str) -> str:
    return (f"[...document.querySelectorAll('button')].find(e => e.textContent === "
            f"{json.dumps(label)})")


def _name(c: Any, text: str) -> None:
    box = f"{_row('file name')}?.querySelector('input')"
    c.click(*_centre(c, box))
    c.js(f"(() => {{ const e = {box}; e.focus(); e.select(); }})()")
    c.type_text(text)
    c.wait(f"{box}.value === {json.dumps(text)}")


@pytest.fixture
def playing(page: TfPage, tmp_path: Path) -> Iterator[BagPlayer]:
    """The turtle bag paused at 5 s, with a record folder, its loop running as ``tfbus
    view --bag --record-dir`` runs it."""
    ctl = RecordControl(page, directory=tmp_path)
    player = BagPlayer(page, BagTimeline.read(TURTLE), paused=True, record=ctl)
    player.seek(5.0)
    stop = threading.Event()
    runner = threading.Thread(target=player.run, args=(stop,), daemon=True)
    runner.start()
    try:
        yield player
    finally:
        stop.set()
        runner.join(timeout=10)
        ctl.close()


def test_record_control_in_chromium_on_a_bag(chromium: str, page: TfPage,
                                             playing: BagPlayer, tmp_path: Path) -> None:
    from cdp import Chromium

    ctl = playing.record
    assert ctl is not None
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("document.body && document.body.innerText.includes('bag time 5.00')")
        # a name that is a path, with markup: refused, shown as text, nothing written
        _name(c, "../<b>x</b>")
        c.click(*_centre(c, _button("start recording")))
        c.wait("document.body.innerText.includes(\"record file name '../<b>x</b>'\")")
        assert ctl.recorder is None and sorted(p.name for p in tmp_path.iterdir()) == []
        assert c.js("document.querySelectorAll('b').length") == c.js(
            "[...document.querySelectorAll('b')].filter(e => e.textContent !== 'x').length")
        _name(c, "turtle-run")
        c.click(*_centre(c, _button("start recording")))
        until(lambda: ctl.active is not None, "recording started")
        until(lambda: playing._rec_upto > 0, "statics up to 5 s written")
        playing.seek(playing.duration)  # the slider dragged to the end
        until(lambda: playing._rec_upto == len(playing.timeline.times), "the bag written")
        c.wait("document.body.innerText.includes('recording turtle-run.mcap')")
        c.click(*_centre(c, _button("stop recording")))
        until(lambda: ctl.active is None, "recording stopped")
        c.wait("document.body.innerText.includes('recorded (stopped) turtle-run.mcap')")
        shot = c.screenshot(tmp_path.parent / "record_bag.png")
        assert len(shot) > 10_000
    tl = playing.timeline
    n5 = int(np.searchsorted(tl.times, tl.start.ns + 5_000_000_000, side="right"))
    want = [(tl.times[i], "/tf_static" if tl.messages[i][2] else "/tf",
             tuple(tl.messages[i][0])) for i in range(len(tl.times))
            if i >= n5 or tl.messages[i][2]]
    assert read_back(tmp_path / "turtle-run.mcap") == want


async def press(c: Any, label: str, done: Callable[[], bool]) -> None:
    """Click the button ``label`` until ``done()`` (the page may still move while the
    redraws that follow a message arrive: a click that missed is made again; bounded)."""
    for _ in range(5):
        xy = await anyio.to_thread.run_sync(_centre, c, _button(label))
        await anyio.to_thread.run_sync(c.click, *xy)
        with anyio.move_on_after(5):
            while not done():
                await anyio.sleep(0.01)
        if done():
            return
    raise AssertionError(f"{label!r} clicked five times, to no effect")


@pytest.mark.anyio
async def test_record_control_in_chromium_live(chromium: str, page: TfPage,
                                               tmp_path: Path) -> None:
    from cdp import Chromium

    clock = ManualClock(Time.from_sec(100.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    ctl = RecordControl(page, directory=tmp_path)
    view = LiveView(page, buffer, stats, clock, record=ctl)
    sent = []
    async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:
        tg.start_soon(view.run, bus)
        with Chromium(chromium) as c:
            await anyio.to_thread.run_sync(c.open, f"http://127.0.0.1:{page.port}/")
            await anyio.to_thread.run_sync(
                c.wait, "document.body && document.body.innerText.includes('start recording')")
            await anyio.to_thread.run_sync(_name, c, "live-run")
            await press(c, "start recording", lambda: ctl.active is not None)
            for k in range(5):
                msg = TFMessage([tf(100.0 + k, "odom", "base", (float(k), 0.0, 0.0))])
                await bus.publish("/tf", msg)
                with anyio.fail_after(5):
                    while stats.messages.get("/tf", 0) < k + 1:
                        await anyio.sleep(0)
                sent.append((clock.now().ns, "/tf", tuple(msg.transforms)))
                await clock.advance(0.1)
            await press(c, "stop recording", lambda: ctl.active is None)
            await anyio.to_thread.run_sync(
                c.wait, "document.body.innerText.includes('recorded (stopped) live-run.mcap: "
                        "5 messages')")
            await anyio.to_thread.run_sync(c.screenshot, tmp_path.parent / "record_live.png")
        tg.cancel_scope.cancel()
    buffer.close()
    assert read_back(tmp_path / "live-run.mcap") == sent


def test_command_records_a_bag_until_its_cap_and_says_so(tmp_path: Path) -> None:
    """``tfbus view --bag TURTLE --record OUT --record-max-seconds 2 --rate 10`` as a
    process, no browser: the bag plays undrawn and is recorded until 2 s of log time; the
    line saying so is printed when the cap is reached (waited for, bounded), the file
    holds the bag's messages of its first 2 s; SIGINT ends the view with status 0."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "cli.mcap"
    exe = Path(sys.executable).with_name("tfbus")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([str(exe), "view", "--bag", str(TURTLE), "--port", str(port),
                             "--rate", "10", "--record", str(out),
                             "--record-max-seconds", "2"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    bag = [(m.time.ns, m.topic, tuple(m.message.transforms)) for m in read_messages(TURTLE)]
    want = [m for m in bag if m[0] - bag[0][0] <= 2_000_000_000]
    try:
        lines = ProcLines(proc).until(lambda ls: any("recorded (" in line for line in ls), 120)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert lines[0] == f"tfbus view: http://127.0.0.1:{port}/"
    ended = [line for line in lines if "recorded (" in line]
    assert len(ended) == 1, lines
    assert ended[0].startswith(f"tfbus view: recorded (reached its cap of 2 s) cli.mcap: "
                                f"{len(want)} messages, ")
    assert read_back(out) == want
