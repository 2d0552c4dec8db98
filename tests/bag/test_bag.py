"""tfbus.bag: reading real recordings, load_buffer lookups, damage, writing, replay, record.

Data (``tests/data/SOURCES.md``): real ROS 1 recordings (the webviz turtle_tf bag, the
two bz2 laser bags) and the project's own ROS 2 recordings written by
``scripts/data/make_test_bags.py`` with other writers than tfbus's (``nav2_like.mcap`` by the
mcap package, ``tf_example/`` by rosbags): their counts, rates and spans are the
script's constants, and the committed files are checked to be what the script writes.
"""

from __future__ import annotations

import importlib.util
import math
import sqlite3
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest

pytest.importorskip("rosbags")

import itertools

from tfbus import (
    Duration,
    Header,
    Quaternion,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus import bag as tfbag
from tfbus.bag import (
    BagFormat,
    BagFormatError,
    BagMessage,
    BagNotFoundError,
    BagReadError,
    BagRecorder,
    detect_format,
    load_buffer,
    read_messages,
    replay,
    summarize,
    write_bag,
)

pytestmark = pytest.mark.anyio

DATA = Path(__file__).resolve().parents[1] / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
NAV2 = DATA / "nav2_like.mcap"
EX_DIR = DATA / "tf_example"
LASER = DATA / "laser"
MAKE_BAGS = Path(__file__).resolve().parents[2] / "scripts" / "data" / "make_test_bags.py"


# --------------------------------------------------------------------------- helpers


def samples(path: Path) -> dict[tuple[str, str, bool], list[TransformStamped]]:
    """Every transform of a bag grouped by (parent, child, static), in bag order."""
    out: dict[tuple[str, str, bool], list[TransformStamped]] = defaultdict(list)
    for rec in read_messages(path):
        for ts in rec.message.transforms:
            out[(ts.header.frame_id, ts.child_frame_id, rec.is_static)].append(ts)
    return dict(out)


def rosbags_reference(path: Path) -> list[tuple[int, str, list[TransformStamped]]]:
    """The same messages through rosbags' generic deserializer (independent path)."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        for conn, t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            tss = [
                TransformStamped(
                    Header(Time(x.header.stamp.sec, x.header.stamp.nanosec), x.header.frame_id),
                    x.child_frame_id,
                    Transform(
                        Vector3(x.transform.translation.x, x.transform.translation.y,
                                x.transform.translation.z),
                        Quaternion(x.transform.rotation.x, x.transform.rotation.y,
                                   x.transform.rotation.z, x.transform.rotation.w),
                    ),
                )
                for x in msg.transforms  # type: ignore[attr-defined]
            ]
            out.append((t, conn.topic, tss))
    return out


def as_arrays(ts: TransformStamped) -> tuple[np.ndarray, np.ndarray]:
    t, q = ts.transform
    return np.array(t, dtype=float), np.array(q, dtype=float)


def slerp(q0: np.ndarray, q1: np.ndarray, r: float) -> np.ndarray:
    """Shortest-path slerp written out (Shoemake 1985), independent of tfbus."""
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 1 - 1e-12:
        q = q0 + r * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(d, 1.0))
    return (math.sin((1 - r) * th) * q0 + math.sin(r * th) * q1) / math.sin(th)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    p = qmul(qmul(q, np.array([*v, 0.0])), q * np.array([-1, -1, -1, 1]))
    return p[:3]


def same_rotation(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> bool:
    return bool(np.allclose(a, b, atol=tol) or np.allclose(a, -b, atol=tol))


# --------------------------------------------------------------------------- formats


def test_detect_format(tmp_path: Path) -> None:
    assert detect_format(TURTLE) is BagFormat.ROS1
    with pytest.raises(BagNotFoundError) as e:
        detect_format(tmp_path / "nope.bag")
    assert isinstance(e.value, FileNotFoundError)
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"hello, not a bag at all")
    with pytest.raises(BagFormatError, match="unknown format"):
        detect_format(junk)
    (tmp_path / "folder").mkdir()
    with pytest.raises(BagFormatError, match=r"metadata\.yaml"):
        detect_format(tmp_path / "folder")
    old = tmp_path / "old.bag"
    old.write_bytes(b"#ROSBAG V1.2\n....")
    with pytest.raises(BagFormatError, match="version"):
        list(read_messages(old))


def test_bag_format_is_a_str_enum() -> None:
    """``BagFormat(str, Enum)`` (Python 3.10) behaves as the StrEnum it replaced."""
    assert BagFormat("mcap") is BagFormat.MCAP and BagFormat.ROS1 == "ros1"
    assert str(BagFormat.SQLITE3) == "sqlite3" and f"{BagFormat.MCAP}" == "mcap"
    assert f"{BagFormat.ROS1:>6}" == "  ros1" and isinstance(BagFormat.ROS1, str)
    assert [f.value for f in BagFormat] == ["ros1", "sqlite3", "mcap"]


def test_detect_format_ros2() -> None:
    assert detect_format(NAV2) is BagFormat.MCAP
    assert detect_format(EX_DIR) is BagFormat.SQLITE3
    assert detect_format(EX_DIR / "tf_example.db3") is BagFormat.SQLITE3


def test_missing_and_unknown_errors_are_one_line(tmp_path: Path) -> None:
    with pytest.raises(BagNotFoundError) as e:
        list(read_messages(tmp_path / "missing.bag"))
    assert "\n" not in str(e.value) and "missing.bag" in str(e.value)
    junk = tmp_path / "x.mcap"
    junk.write_bytes(b"\x00" * 64)
    with pytest.raises(BagFormatError) as e2:
        load_buffer(junk)
    assert "\n" not in str(e2.value)


# --------------------------------------------------------------------------- turtle (ROS 1)


def test_turtle_frames_counts_and_span() -> None:
    s = samples(TURTLE)
    assert set(s) == {
        ("world", "turtle1", False),
        ("world", "turtle2", False),
        ("turtle1", "carrot", True),
    }
    assert len(s[("world", "turtle1", False)]) == 1344
    assert len(s[("world", "turtle2", False)]) == 1344
    assert len(s[("turtle1", "carrot", True)]) == 1
    recs = list(read_messages(TURTLE))
    assert sum(r.topic == "/tf" for r in recs) == 2688
    assert sum(r.topic == "/tf_static" for r in recs) == 1
    times = [r.time.ns for r in recs]
    assert times == sorted(times)
    assert recs[0].time == Time(1396293888, 46138414)  # the latched /tf_static
    assert recs[-1].time == Time(1396293909, 544779879)
    t1 = s[("world", "turtle1", False)]
    assert t1[0].header.stamp == Time(1396293888, 56102037)
    assert t1[-1].header.stamp == Time(1396293909, 544173002)
    authorities = {r.authority for r in recs}
    assert authorities == {
        "/turtle1_tf_broadcaster",
        "/turtle2_tf_broadcaster",
        "/static_transform_publisher_1396293887803024259",
    }


def test_turtle_matches_rosbags_generic_deserializer() -> None:
    ref = rosbags_reference(TURTLE)
    mine = [(r.time.ns, r.topic, list(r.message.transforms)) for r in read_messages(TURTLE)]
    assert mine == ref


def test_generic_fallback_decoder_matches_fast_path(monkeypatch: pytest.MonkeyPatch) -> None:
    fast = [list(r.message.transforms) for r in read_messages(TURTLE)]
    monkeypatch.setattr(tfbag.decode, "ROS1_TF_MD5", "not-the-standard-md5")
    slow = [list(r.message.transforms) for r in read_messages(TURTLE)]
    assert slow == fast


@pytest.mark.parametrize("fmt", ["sqlite3", "mcap"])
def test_generic_cdr_decoder_matches_fast_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fmt: str
) -> None:
    original = list(read_messages(TURTLE))[:200]
    write_bag(tmp_path / "b", original, format=fmt)
    bare = next((tmp_path / "b").glob(f"*.{'db3' if fmt == 'sqlite3' else 'mcap'}"))
    fast = [list(r.message.transforms) for r in read_messages(bare)]
    monkeypatch.setattr(tfbag.decode, "ROS2_TF_RIHS01", "RIHS01_not-the-standard-hash")
    slow = [list(r.message.transforms) for r in read_messages(bare)]
    assert slow == fast == [list(r.message.transforms) for r in original]


def test_summary_turtle() -> None:
    s = summarize(TURTLE)
    assert s.format is BagFormat.ROS1 and s.error is None
    assert set(s.frames) == {"turtle1", "turtle2", "carrot"}
    f = s.frames["turtle1"]
    assert (f.parent, f.static, f.count, f.authority) == (
        "world", False, 1344, "/turtle1_tf_broadcaster")
    assert f.rate == pytest.approx(62.5, rel=1e-3)
    assert 0 <= f.delay_avg <= f.delay_max < 0.01
    assert s.frames["carrot"].static and s.frames["carrot"].rate == 0.0
    assert s.messages == {"/tf": 2688, "/tf_static": 1}
    assert s.duration == pytest.approx(21.4986, abs=1e-3)
    assert s.transform_count == 2689


def test_summary_is_the_monitors_statistics() -> None:
    """bag-info, monitor and frames share one accounting: a BagSummary is tf_monitor's
    TfSummary with the bag's path, format and error."""
    from tfbus.monitor import AuthoritySummary, FrameSummary, TfSummary

    assert tfbag.FrameSummary is FrameSummary
    assert tfbag.AuthoritySummary is AuthoritySummary
    s = summarize(TURTLE)
    stats = TfSummary()
    for rec in read_messages(TURTLE):
        stats.add(rec.time, rec.message.transforms, rec.authority, static=rec.is_static)
    assert isinstance(s, TfSummary) and s.path == TURTLE
    assert s.frames == stats.frames and s.authorities == stats.authorities
    assert (s.start, s.end, s.messages) == (stats.start, stats.end, stats.messages)


def test_summary_rate_counts_distinct_stamps(tmp_path: Path) -> None:
    """A frame's rate is (distinct stamps - 1) / (newest - oldest stamp): 11 stamps
    0.1 s apart, each recorded twice (22 transforms), is 10 Hz -- not 21 Hz, what
    (transforms - 1) / span gave before the statistics moved to tfbus.monitor."""
    t0 = 1_700_000_000 * 10**9
    messages = []
    for i in range(22):
        stamp = Time.from_ns(t0 + (i // 2) * 100_000_000)
        ts = TransformStamped(Header(stamp, "odom"), "base_link",
                              Transform(Vector3(0.1 * i, 0.0, 0.0), Quaternion(0, 0, 0, 1)))
        messages.append(BagMessage(Time.from_ns(t0 + i * 50_000_000 + 1_000_000), "/tf",
                                   TFMessage((ts,)), "/odom"))
    write_bag(tmp_path / "repeated.bag", messages)
    f = summarize(tmp_path / "repeated.bag").frames["base_link"]
    assert (f.count, len(f.stamps)) == (22, 11)
    assert f.rate == pytest.approx(10.0, rel=1e-12)
    # delay = bag time - stamp: 1 ms for the first copy, 51 ms for the second
    assert f.delay_avg == pytest.approx(0.026, abs=1e-9)
    assert f.delay_max == pytest.approx(0.051, abs=1e-9)


def test_summary_of_a_sim_time_bag_measures_delay_against_bag_stamps() -> None:
    """The nav2-like bag's stamps are simulated time (928..988 s) while its bag times are
    wall time (~1.78e9 s): delays are measured against the newest stamp (tf_monitor's
    definition in tfbus.monitor), not reported as 1.78e9 s as before. map -> odom is
    stamped 0.1 s behind the sim clock (make_test_bags.MAP_ODOM_LAG_NS), the other
    links at it."""
    s = summarize(NAV2)
    assert s.sim_time is True
    dynamic = [f for f in s.frames.values() if not f.static]
    assert dynamic and all(0.0 <= f.delay_avg <= f.delay_max < 2.0 for f in dynamic)
    # Recomputed here: newest stamp seen so far (this message included) minus the stamp.
    newest, worst = 0, 0
    for rec in read_messages(NAV2, topics=["/tf"]):
        newest = max([newest, *(x.header.stamp.ns for x in rec.message.transforms)])
        for x in rec.message.transforms:
            if x.child_frame_id == "odom":
                worst = max(worst, newest - x.header.stamp.ns)
    assert s.frames["odom"].delay_max == pytest.approx(worst / 1e9, abs=1e-9)
    assert 0.05 < s.frames["odom"].delay_max < 0.1  # the lag, less the newest's own age
    assert s.frames["base_link"].delay_max < 0.05  # stamped at the sim clock


def test_topic_filter_and_empty_filter_quirk() -> None:
    only_static = list(read_messages(TURTLE, topics=["/tf_static"]))
    assert [r.topic for r in only_static] == ["/tf_static"]
    # rosbags returns *every* message for an empty connection list; we must return none.
    assert list(read_messages(TURTLE, topics=["/no_such_topic"])) == []
    assert list(read_messages(TURTLE, topics=["/turtle1/pose"])) == []  # not a tf type


def test_window_with_latched_statics() -> None:
    start, stop = Time(1396293900), Time(1396293901)
    recs = list(read_messages(TURTLE, start=start, stop=stop))
    assert recs[0].topic == "/tf_static" and recs[0].time < start  # latched
    dyn = [r for r in recs if r.topic == "/tf"]
    assert dyn and all(start <= r.time < stop for r in dyn)
    assert len(dyn) == pytest.approx(125, abs=2)  # 2 x 62.5 Hz for one second
    unlatched = list(read_messages(TURTLE, start=start, stop=stop, latched=False))
    assert all(r.topic == "/tf" for r in unlatched)


def test_load_buffer_lookups_at_samples_and_between() -> None:
    core = load_buffer(TURTLE)
    s = samples(TURTLE)
    assert set(core.get_frame_names()) == {"world", "turtle1", "turtle2", "carrot"}
    info = {c: (p, st, n, o, nw) for c, p, _a, st, n, o, nw in core.frame_info()}
    assert info["turtle1"][:3] == ("world", False, 1344)  # nothing pruned
    assert info["carrot"][:2] == ("turtle1", True)
    for child in ("turtle1", "turtle2"):
        recorded = s[("world", child, False)]
        for ts in recorded[::37]:
            got = core.lookup_transform("world", child, ts.header.stamp)
            assert got.header.stamp == ts.header.stamp
            assert got.transform == ts.transform  # exact at a sample stamp
        # Between two samples: linear translation and slerp, computed here.
        for a, b in zip(recorded[100:1300:97], recorded[101:1301:97], strict=True):
            ta, tb = a.header.stamp.ns, b.header.stamp.ns
            t = ta + (tb - ta) // 3
            r = ((t - ta) / 1e9) / ((tb - ta) / 1e9)
            pa, qa = as_arrays(a)
            pb, qb = as_arrays(b)
            got = core.lookup_transform("world", child, Time.from_ns(t))
            gp, gq = as_arrays(got)
            assert np.allclose(gp, pa + r * (pb - pa), atol=1e-12)
            assert same_rotation(gq, slerp(qa, qb, r))


def test_load_buffer_chain_through_static() -> None:
    core = load_buffer(TURTLE)
    s = samples(TURTLE)
    carrot = s[("turtle1", "carrot", True)][0]
    pc, qc = as_arrays(carrot)
    for ts in s[("world", "turtle1", False)][::200]:
        p1, q1 = as_arrays(ts)
        got = core.lookup_transform("world", "carrot", ts.header.stamp)
        gp, gq = as_arrays(got)
        assert np.allclose(gp, p1 + qrot(q1, pc), atol=1e-9)
        assert same_rotation(gq, qmul(q1, qc))


def test_load_buffer_cache_covers_the_whole_span() -> None:
    core = load_buffer(TURTLE)
    assert core.cache_time.to_sec() >= 21.0
    s = samples(TURTLE)
    first = s[("world", "turtle1", False)][0]
    assert core.lookup_transform("world", "turtle1", first.header.stamp).transform == (
        first.transform
    )
    short = load_buffer(TURTLE, cache_time=1.0)
    info = {c: n for c, _p, _a, _st, n, _o, _nw in short.frame_info()}
    assert info["turtle1"] < 1344  # a short cache prunes, as asked


# --------------------------------------------------------------------------- ROS 2 (ours)


def _make_test_bags() -> Any:
    """scripts/data/make_test_bags.py as a module (its constants are the expected numbers)."""
    spec = importlib.util.spec_from_file_location("make_test_bags", MAKE_BAGS)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_committed_ros2_recordings_are_what_the_script_writes(tmp_path: Path) -> None:
    """tests/data/nav2_like.mcap and tests/data/tf_example/ are regenerated by
    scripts/data/make_test_bags.py: the same messages, stamps and bag times."""
    subprocess.run([sys.executable, str(MAKE_BAGS), "--out", str(tmp_path)], check=True,
                   capture_output=True, timeout=120)  # fmt: skip
    for name in ("nav2_like.mcap", "tf_example"):
        assert list(read_messages(tmp_path / name)) == list(read_messages(DATA / name)), name


def test_nav2_mcap_frames_counts_span() -> None:
    g = _make_test_bags()
    s = samples(NAV2)
    frames = {c for (_p, c, _st) in s} | {p for (p, _c, _st) in s}
    assert len(frames) == 34  # map, odom, base_link, 2 wheels, 29 statics
    static = [k for k in s if k[2]]
    assert len(static) == 29 and all(len(s[k]) == 1 for k in static)
    assert {(p, c) for p, c, _st in static} == {(p, c) for p, c, _x, _r in g.STATICS}
    assert sum(len(v) for k, v in s.items() if not k[2]) == 1500 + 2 * 1200 + 480
    assert len(s[("odom", "base_link", False)]) == g.N_ODOM_BASE == 1500
    assert len(s[("map", "odom", False)]) == g.N_MAP_ODOM == 480
    assert len(s[("base_link", "left_wheel", False)]) == g.N_WHEELS == 1200
    recs = list(read_messages(NAV2))
    assert sum(r.topic == "/tf" for r in recs) == 1500 + 1200 + 480
    assert sum(r.topic == "/tf_static" for r in recs) == 1
    stamps = [ts.header.stamp.to_sec() for r in recs if r.topic == "/tf"
              for ts in r.message.transforms]
    assert min(stamps) == 927.907 and max(stamps) == 987.96  # sim time (map->odom lags)
    assert {r.authority for r in recs} == {tfbag.ROS2_AUTHORITY}
    # rates from the stamps: 25, 20 and 8 Hz exactly
    for edge, hz in ((("odom", "base_link"), 25.0), (("base_link", "right_wheel"), 20.0),
                     (("map", "odom"), 8.0)):  # fmt: skip
        e = s[(*edge, False)]
        span = (e[-1].header.stamp - e[0].header.stamp).to_sec()
        assert (len(e) - 1) / span == pytest.approx(hz, rel=1e-12)
    # the /odom topic (nav_msgs/Odometry) is not tf: filtered out, even when asked for
    assert list(read_messages(NAV2, topics=["/odom"])) == []


def test_nav2_matches_rosbags_and_lookups() -> None:
    ref = rosbags_reference(NAV2)
    mine = [(r.time.ns, r.topic, list(r.message.transforms)) for r in read_messages(NAV2)]
    assert mine == ref
    core = load_buffer(NAV2)
    s = samples(NAV2)
    for ts in s[("odom", "base_link", False)][::101]:
        got = core.lookup_transform("odom", "base_link", ts.header.stamp)
        assert got.transform == ts.transform
    # map -> odom at 8 Hz: interpolate between two samples independently.
    mo = s[("map", "odom", False)]
    a, b = mo[400], mo[401]
    ta, tb = a.header.stamp.ns, b.header.stamp.ns
    t = (ta + tb) // 2
    r = ((t - ta) / 1e9) / ((tb - ta) / 1e9)
    got = core.lookup_transform("map", "odom", Time.from_ns(t))
    pa, qa = as_arrays(a)
    pb, qb = as_arrays(b)
    gp, gq = as_arrays(got)
    assert np.allclose(gp, pa + r * (pb - pa), atol=1e-12)
    assert same_rotation(gq, slerp(qa, qb, r))
    # Static chain: base_link -> oakd_rgb_camera_optical_frame exists at any time.
    assert core.can_transform("base_link", "oakd_rgb_camera_optical_frame", Time(0))


def test_sqlite_folder_and_bare_db3() -> None:
    for path in (EX_DIR, EX_DIR / "tf_example.db3"):
        s = samples(path)
        assert set(s) == {("odom", "base_footprint", False), ("base_footprint", "base_link", True)}
        assert len(s[("odom", "base_footprint", False)]) == 517  # make_test_bags.EX_COUNT
    assert [(r.time.ns, r.topic, list(r.message.transforms)) for r in read_messages(EX_DIR)] == (
        rosbags_reference(EX_DIR)
    )
    core = load_buffer(EX_DIR)
    recorded = samples(EX_DIR)[("odom", "base_footprint", False)]
    for ts in recorded[::50]:
        assert core.lookup_transform("odom", "base_footprint", ts.header.stamp).transform == (
            ts.transform
        )
    span = (recorded[-1].header.stamp - recorded[0].header.stamp).to_sec()
    assert span == pytest.approx(51.6, abs=1e-9)  # 516 periods of 0.1 s


# --------------------------------------------------------------------------- laser (ROS 1, bz2)

#: From tests/data/SOURCES.md: /tf message counts and (parent, child, Hz) of the
#: fastest frame of each recording (2014, no /tf_static, bz2-compressed chunks).
LASER_BAGS = {
    "drl_guardian_3.bag": (22_998, ("odom", "base_footprint", 120.0), 10),
    "drl_jarvis_complex_path_fast.bag": (18_839, ("odom", "base_footprint", 25.0), 11),
}


@pytest.fixture(scope="module")
def laser_reads() -> dict[str, list[BagMessage]]:
    return {name: list(read_messages(LASER / name)) for name in LASER_BAGS}


@pytest.mark.parametrize("name", sorted(LASER_BAGS))
def test_laser_bags_tf_loads(name: str, laser_reads: dict[str, list[BagMessage]]) -> None:
    count, (parent, child, hz), n_frames = LASER_BAGS[name]
    recs = laser_reads[name]
    assert len(recs) == count and {r.topic for r in recs} == {"/tf"}
    core = load_buffer(LASER / name)
    assert len(core.get_frame_names()) == n_frames
    edge = [ts for r in recs for ts in r.message.transforms
            if (ts.header.frame_id, ts.child_frame_id) == (parent, child)]
    span = (edge[-1].header.stamp - edge[0].header.stamp).to_sec()
    assert (len(edge) - 1) / span == pytest.approx(hz, rel=0.01)
    for ts in edge[:: max(1, len(edge) // 20)]:
        assert core.lookup_transform(parent, child, ts.header.stamp).transform == ts.transform


def test_laser_bag_cut_is_salvaged_through_bz2_chunks(
    tmp_path: Path, laser_reads: dict[str, list[BagMessage]]
) -> None:
    """A cut bz2 bag is read record by record (tfbus's ROS 1 scanner, bz2 chunks): the
    same messages as rosbags' indexed read of the intact file, up to the damage."""
    name = "drl_jarvis_complex_path_fast.bag"
    full = laser_reads[name]
    cut = _truncate(LASER / name, tmp_path / "cut.bag", 0.6)
    got: list[BagMessage] = []
    with pytest.raises(BagReadError) as e:
        for rec in read_messages(cut):
            got.append(rec)
    assert 0.4 * len(full) < len(got) < 0.7 * len(full)
    assert got == full[: len(got)]
    assert e.value.offset is not None and e.value.offset < cut.stat().st_size


# --------------------------------------------------------------------------- damage


def _truncate(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])
    return dst


def test_truncated_ros1_returns_prefix_then_says_where(tmp_path: Path) -> None:
    full = list(read_messages(TURTLE))
    cut = _truncate(TURTLE, tmp_path / "cut.bag", 0.5)
    got: list[BagMessage] = []
    with pytest.raises(BagReadError) as e:
        for rec in read_messages(cut):
            got.append(rec)
    err = e.value
    assert 0 < len(got) < len(full)
    assert got == full[: len(got)]
    assert err.messages_read == len(got)
    assert err.last_time == got[-1].time
    assert err.offset is not None and 0 < err.offset <= cut.stat().st_size
    assert "reading stopped" in str(err) and "\n" not in str(err)


def test_truncated_ros1_load_buffer_partial(tmp_path: Path) -> None:
    cut = _truncate(TURTLE, tmp_path / "cut.bag", 0.5)
    with pytest.raises(BagReadError) as e:
        load_buffer(cut)
    partial = e.value.partial
    assert partial is not None and partial.frame_exists("turtle1")
    core = load_buffer(cut, errors="warn")
    assert core.frame_exists("carrot")
    recorded = samples(TURTLE)[("world", "turtle1", False)]
    first = recorded[0]
    assert core.lookup_transform("world", "turtle1", first.header.stamp).transform == (
        first.transform
    )
    s = summarize(cut)
    assert s.error is not None and 0 < s.frames["turtle1"].count < 1344


def test_truncated_right_after_header(tmp_path: Path) -> None:
    cut = _truncate(TURTLE, tmp_path / "tiny.bag", 0.002)
    with pytest.raises(BagReadError) as e:
        list(read_messages(cut))
    assert e.value.messages_read == 0


def test_truncated_mcap(tmp_path: Path) -> None:
    full = list(read_messages(NAV2))
    cut = _truncate(NAV2, tmp_path / "cut.mcap", 0.999)
    got = []
    with pytest.raises(BagReadError) as e:
        for rec in read_messages(cut):
            got.append(rec)
    assert len(got) > 0.9 * len(full)
    assert e.value.offset is not None


def test_corrupt_sqlite(tmp_path: Path) -> None:
    bad = tmp_path / "bad.db3"
    bad.write_bytes(b"SQLite format 3\x00" + b"\xff" * 4000)
    with pytest.raises(BagReadError) as e:
        list(read_messages(bad))
    assert e.value.messages_read == 0 and "bad.db3" in str(e.value)


def test_corrupt_message_stops_with_position(tmp_path: Path) -> None:
    con_path = tmp_path / "b.db3"
    write_bag(tmp_path / "b", list(read_messages(TURTLE))[:50], format="sqlite3")
    (tmp_path / "b" / "b.db3").rename(con_path)
    con = sqlite3.connect(con_path)
    rows = con.execute("select id from messages order by timestamp").fetchall()
    con.execute("update messages set data = ? where id = ?", (b"\x00\x01\x00\x00\xff", rows[20][0]))
    con.commit()
    con.close()
    got = []
    with pytest.raises(BagReadError, match="corrupt /tf message") as e:
        for rec in read_messages(con_path):
            got.append(rec)
    assert len(got) == 20 and e.value.last_time == got[-1].time


# --------------------------------------------------------------------------- writing


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
def test_write_bag_round_trip(tmp_path: Path, fmt: str) -> None:
    original = list(read_messages(TURTLE))
    out = tmp_path / ("out.bag" if fmt == "ros1" else "out")
    assert write_bag(out, original, format=fmt) == len(original)
    back = list(read_messages(out))
    assert [(r.time, r.topic, list(r.message.transforms)) for r in back] == [
        (r.time, r.topic, list(r.message.transforms)) for r in original
    ]
    assert detect_format(out).value == fmt


def test_written_ros1_bag_is_standard(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Reader

    out = tmp_path / "std.bag"
    write_bag(out, list(read_messages(TURTLE))[:10])
    with Reader(out) as reader:
        conns = {c.topic: c for c in reader.connections}
    assert conns["/tf_static"].ext.latching == 1
    assert conns["/tf"].ext.latching == 0
    for c in conns.values():
        assert c.msgtype == "tf2_msgs/msg/TFMessage"
        assert c.digest == "94810edda583a504dfda3829e70d7eec"
        assert "geometry_msgs/TransformStamped[] transforms" in c.msgdef.data


@pytest.mark.parametrize("fmt", ["sqlite3", "mcap"])
def test_written_ros2_bag_qos(tmp_path: Path, fmt: str) -> None:
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2 import Reader

    out = tmp_path / "ros2"
    write_bag(out, list(read_messages(TURTLE))[:10], format=fmt)
    assert (out / "metadata.yaml").exists()
    with Reader(out) as reader:
        conns = {c.topic: c for c in reader.connections}
    static_qos = conns["/tf_static"].ext.offered_qos_profiles[0]
    assert static_qos.durability == QosDurability.TRANSIENT_LOCAL and static_qos.depth == 1
    assert static_qos.reliability == QosReliability.RELIABLE
    assert conns["/tf"].ext.offered_qos_profiles[0].durability == QosDurability.VOLATILE
    assert conns["/tf"].msgtype == "tf2_msgs/msg/TFMessage"


def test_write_refuses_existing_and_bad_format(tmp_path: Path) -> None:
    out = tmp_path / "x.bag"
    write_bag(out, [])
    with pytest.raises(tfbag.BagError, match="cannot create"):
        write_bag(out, [])
    with pytest.raises(BagFormatError):
        write_bag(tmp_path / "y", [], format="ros3")


# --------------------------------------------------------------------------- replay / record


async def test_replay_drives_clock_and_buffer_sees_bag_time() -> None:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.listener import TransformListener

    recorded = samples(TURTLE)[("world", "turtle1", False)]
    target = recorded[700]
    clock = ManualClock(start=Time(1396293880))
    buf = Buffer(cache_time=30.0, clock=clock)
    resolved: list[tuple[Time, TransformStamped]] = []
    async with Bus() as bus, TransformListener(buf, bus, queue_size=10_000):

        async def waiter() -> None:
            ts = await buf.lookup_transform_async("world", "carrot", target.header.stamp)
            resolved.append((clock.now(), ts))

        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter)
            await anyio.wait_all_tasks_blocked()
            n = await replay(TURTLE, bus, clock=clock, rate=None)
    assert n == 2689
    assert clock.now() == Time(1396293909, 544779879)  # the last bag time
    (when, ts), = resolved
    # It resolved while the clock showed the bag time of a message after the target stamp.
    assert target.header.stamp <= when < Time(1396293909)
    assert ts.header.stamp == target.header.stamp
    assert buf.lookup_transform("world", "turtle1", target.header.stamp).transform == (
        target.transform
    )


async def test_replay_paces_at_rate_on_its_pace_clock() -> None:
    """Message i goes out when the pace clock reads p0 + (t_i - t_0) / rate, exactly
    (ManualClock deadlines are stepped through one by one: no wall time)."""
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    pace = ManualClock(start=Time(5000))
    published: list[tuple[Time, Time]] = []  # (pace clock, bag time)
    start, stop = Time(1396293900), Time(1396293902)
    done = anyio.Event()
    async with Bus() as bus:

        async def run() -> None:
            n = await replay(TURTLE, bus, rate=4.0, start=start, stop=stop, pace_clock=pace,
                             on_message=lambda rec: published.append((pace.now(), rec.time)))
            assert n == len(published)
            done.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            await pace.advance(10.0)  # more than the 2 s of bag time / 4
            await done.wait()
        with pytest.raises(ValueError, match="rate"):
            await replay(TURTLE, bus, rate=-1.0)
        with pytest.raises(ValueError, match="rate"):
            await replay(TURTLE, bus, rate=math.inf)
    recs = list(read_messages(TURTLE, start=start, stop=stop))
    assert [t for _p, t in published] == [r.time for r in recs]
    # The latched static (recorded 12 s before start) goes out at once; the window is
    # paced from ``start``.
    assert recs[0].time < start and published[0][0] == Time(5000)
    for p, t in published:
        assert p.ns == 5000 * 10**9 + max(round((t.ns - start.ns) / 4.0), 0)
    assert published[-1][0] - published[1][0] > Duration(0, 490_000_000)  # ~2 s / 4


async def test_replay_publishes_bag_time_on_clock_as_rosbag_play_clock() -> None:
    """``publish_clock=HZ``: /clock carries bag time at HZ per second of pace time,
    following pace time times the rate, reaching each message's bag time before that
    message and never going back (rosbag's TimePublisher)."""
    from tfbus.bag import DEFAULT_CLOCK_HZ
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock, SimClock
    from tfbus.messages import Clock
    from tfbus.topics import CLOCK_TOPIC, TF_TOPIC

    assert DEFAULT_CLOCK_HZ == 100.0  # rosbag play --clock's --hz default
    pace = ManualClock(start=Time(5000))
    start, stop = Time(1396293900), Time(1396293901)
    seen: list[tuple[str, Time, Time]] = []  # (topic, pace time, bag or clock time)
    done = anyio.Event()
    async with Bus() as bus, SimClock(bus) as sim:

        def on_clock(msg: object) -> None:
            assert isinstance(msg, Clock)
            seen.append((CLOCK_TOPIC, pace.now(), msg.clock))

        def on_tf(msg: object) -> None:
            seen.append((TF_TOPIC, pace.now(), max(ts.header.stamp for ts in msg.transforms)))

        bus.subscribe_callback(CLOCK_TOPIC, on_clock)
        bus.subscribe_callback(TF_TOPIC, on_tf)

        async def run() -> None:
            await replay(TURTLE, bus, rate=2.0, start=start, stop=stop, pace_clock=pace,
                         publish_clock=10.0)
            done.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            for _ in range(60):  # 0.6 s of pace time, 1 s of bag time at rate 2 (+ spare)
                await pace.advance(0.01)
            await done.wait()
        with pytest.raises(ValueError, match="publish_clock"):
            await replay(TURTLE, bus, rate=None, publish_clock=0)
        with pytest.raises(ValueError, match="publish_clock"):
            await replay(TURTLE, bus, rate=None, publish_clock=math.inf)
        clocks = [(p, t) for topic, p, t in seen if topic == CLOCK_TOPIC]
        # The first /clock is ``start`` itself, at once; never backwards; a SimClock on
        # the bus reads the last one.
        assert clocks[0] == (Time(5000), start)
        assert all(a[1] < b[1] for a, b in itertools.pairwise(clocks))
        assert sim.now() == clocks[-1][1]
        # At each 10 Hz tick (every 0.1 s of pace time) /clock reads start + 2 x the
        # elapsed pace time (rate 2): 0.2 s of bag time apart, between the messages.
        at_ticks = [max(t for p, t in clocks if p == Time(5000, k * 100_000_000))
                    for k in (1, 2, 3, 4)]
        assert [round((t.ns - start.ns) / 1e6) for t in at_ticks] == [200, 400, 600, 800]
        assert len(clocks) > len([x for x in seen if x[0] == TF_TOPIC])  # ticks between
        # Each /tf goes out after a /clock at its own bag time.
        last_clock = Time(0)
        for topic, _p, t in seen:
            if topic == CLOCK_TOPIC:
                last_clock = t
            else:
                assert last_clock >= t


async def test_replay_without_rate_never_sleeps() -> None:
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    pace = ManualClock()  # never advanced: any sleep on it would hang the test
    async with Bus() as bus:
        with anyio.fail_after(30):
            n = await replay(TURTLE, bus, rate=None, pace_clock=pace)
    assert n == 2689 and pace.pending == 0


async def test_replay_publishes_latched_statics_first() -> None:
    from tfbus.bus import Bus

    async with Bus() as bus:
        await replay(TURTLE, bus, rate=None, start=Time(1396293905), stop=Time(1396293906))
        with bus.subscribe("/tf_static") as late:
            msg = late.receive_nowait()
    assert [ts.child_frame_id for ts in msg.transforms] == ["carrot"]


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
async def test_record_bus_session_round_trip(tmp_path: Path, fmt: str) -> None:
    from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    clock = ManualClock(start=Time(1_700_000_000))
    out = tmp_path / ("session.bag" if fmt == "ros1" else "session")
    sent: list[tuple[Time, str, list[TransformStamped]]] = []
    static = TransformStamped(Header(clock.now(), "base_link"), "base_laser",
                              Transform(Vector3(0.1, 0.0, 0.2)))
    async with Bus() as bus:
        async with BagRecorder(bus, out, clock=clock, format=fmt) as rec:
            await StaticTransformBroadcaster(bus).send_transform(static)
            sent.append((clock.now(), "/tf_static", [static]))
            await anyio.wait_all_tasks_blocked()
            br = TransformBroadcaster(bus)
            for i in range(50):
                await clock.advance(0.01)
                ts = TransformStamped(
                    Header(clock.now(), "odom"), "base_link",
                    Transform(Vector3(0.01 * i, 0.0, 0.0),
                              Quaternion(0.0, 0.0, math.sin(i / 100), math.cos(i / 100))),
                )
                await br.send_transform(ts)
                sent.append((clock.now(), "/tf", [ts]))
                await anyio.wait_all_tasks_blocked()
        assert rec.count == 51
    back = [(r.time, r.topic, list(r.message.transforms)) for r in read_messages(out)]
    assert back == sent
    core = load_buffer(out)
    assert core.lookup_transform("odom", "base_laser", sent[10][0]).header.stamp == sent[10][0]


async def test_recorder_drains_queued_messages_on_exit(tmp_path: Path) -> None:
    from tfbus.bus import Bus

    out = tmp_path / "drain.bag"
    msgs = [r for r in read_messages(TURTLE)][:30]
    async with Bus() as bus:
        async with BagRecorder(bus, out) as rec:
            for m in msgs:
                bus.publish_nowait(m.topic, m.message)  # no checkpoint: still queued
        assert rec.count == 30
    # Without a clock the bag time is each message's first transform stamp.
    back = list(read_messages(out))
    assert sorted((r.time, r.message) for r in back) == sorted(
        (m.message.transforms[0].header.stamp, m.message) for m in msgs
    )


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
async def test_recorder_drops_a_stamp_the_format_cannot_hold(tmp_path: Path, fmt: str) -> None:
    """A transform stamped 2**31 s (message stamps are int32 seconds in the bag formats
    rosbags writes) between two good ones: that message is counted and dropped, the
    recorder keeps recording and the bag closes whole (before: the serialization error
    escaped the recorder's pump)."""
    from tfbus.bus import Bus

    out = tmp_path / ("far.bag" if fmt == "ros1" else "far")

    def msg(stamp: Time, x: float) -> TFMessage:
        return TFMessage((TransformStamped(Header(stamp, "odom"), "base_link",
                                           Transform(Vector3(x, 0.0, 0.0))),))

    good = [msg(Time(1_700_000_000), 1.0), msg(Time(1_700_000_001), 2.0)]
    async with Bus() as bus:
        async with BagRecorder(bus, out, format=fmt) as rec:
            bus.publish_nowait("/tf", good[0])
            await anyio.wait_all_tasks_blocked()
            bus.publish_nowait("/tf", msg(Time(2**31), 9.0))
            await anyio.wait_all_tasks_blocked()
            assert rec.dropped == 1
            bus.publish_nowait("/tf", good[1])
            await anyio.wait_all_tasks_blocked()
            bus.publish_nowait("/tf", msg(Time(2**32 + 7), 9.0))  # drained on exit
        assert (rec.count, rec.dropped) == (2, 2)
    assert [list(r.message.transforms) for r in read_messages(out)] == \
        [list(m.transforms) for m in good]


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
async def test_recorder_drops_a_bag_time_ros1_cannot_hold(tmp_path: Path, fmt: str) -> None:
    """A receive time past 2**32 s: a ROS 1 bag (uint32 seconds) drops and counts each
    such message and still closes readable (before: rosbags had indexed the time before
    failing, and closing the bag failed too); ROS 2 bags (int64 ns) write it."""
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    clock = ManualClock(start=Time(2**32 + 5))
    out = tmp_path / ("late.bag" if fmt == "ros1" else "late")
    m = TFMessage((TransformStamped(Header(Time(1_700_000_000), "odom"), "base_link",
                                    Transform()),))
    async with Bus() as bus:
        async with BagRecorder(bus, out, clock=clock, format=fmt) as rec:
            for _ in range(3):
                bus.publish_nowait("/tf", m)
                await anyio.wait_all_tasks_blocked()
        assert (rec.count, rec.dropped) == ((0, 3) if fmt == "ros1" else (3, 0))
    back = [(r.time, list(r.message.transforms)) for r in read_messages(out)]
    assert back == ([] if fmt == "ros1" else [(clock.now(), list(m.transforms))] * 3)


async def test_replay_pauses_and_resumes_with_its_control_and_clock_stands_still() -> None:
    """``ReplayControl``: while paused no message goes out and /clock repeats the paused
    time at its rate (rosbag's ``runStalledClock``); on resume the schedule shifts by
    the paused pace time, exactly (ManualClock deadlines: no wall time)."""
    from tfbus.bag import ReplayControl
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.messages import Clock
    from tfbus.topics import CLOCK_TOPIC, TF_TOPIC

    pace = ManualClock(start=Time(5000))
    start, stop = Time(1396293900), Time(1396293901)
    control = ReplayControl()
    assert not control.paused
    clocks: list[tuple[int, int]] = []  # (pace ns, /clock ns)
    sent: list[tuple[int, int]] = []  # (pace ns, bag ns) of /tf messages
    done = anyio.Event()
    async with Bus() as bus:

        def on_clock(msg: object) -> None:
            assert isinstance(msg, Clock)
            clocks.append((pace.now_ns(), msg.clock.ns))

        bus.subscribe_callback(CLOCK_TOPIC, on_clock)

        def on_message(rec: BagMessage) -> None:
            if rec.topic == TF_TOPIC:
                sent.append((pace.now_ns(), rec.time.ns))

        async def run() -> None:
            await replay(TURTLE, bus, rate=1.0, start=start, stop=stop, pace_clock=pace,
                         publish_clock=10.0, control=control, on_message=on_message)
            done.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            await pace.advance(0.3)
            assert control.toggle() is True and control.paused  # paused at 5000.3 s
            control.pause()  # already paused: nothing changes
            n_before = len(sent)
            await pace.advance(0.5)
            assert len(sent) == n_before  # nothing went out while paused
            assert control.toggle() is False  # resumed at 5000.8 s
            control.resume()
            await pace.advance(2.0)
            with anyio.fail_after(10):
                await done.wait()
    p0, s0, ms = 5000 * 10**9, start.ns, 10**6
    # the paused 10 Hz ticks (5000.4 ... 5000.8 s) repeat the paused time, start + 0.3 s
    assert [c for p, c in clocks if p0 + 300 * ms < p <= p0 + 800 * ms] == [s0 + 300 * ms] * 5
    # after the resume /clock runs on from there: start + 0.4 s at 5000.9 s
    assert max(c for p, c in clocks if p == p0 + 900 * ms) == s0 + 400 * ms
    assert all(a[1] <= b[1] for a, b in itertools.pairwise(clocks))
    recs = [r.time.ns for r in read_messages(TURTLE, start=start, stop=stop)
            if r.topic == TF_TOPIC]
    assert [t for _, t in sent] == recs and 0 < n_before < len(recs)
    for p, t in sent:  # before the pause on schedule; after it, 0.5 s later
        assert p == p0 + (t - s0) + (0 if t - s0 <= 300 * ms else 500 * ms)


async def test_replay_started_paused_publishes_nothing_until_resumed() -> None:
    """``ReplayControl(paused=True)`` (``rosbag play --pause``), as fast as possible."""
    from tfbus.bag import ReplayControl
    from tfbus.bus import Bus

    control = ReplayControl(paused=True)
    published: list[BagMessage] = []
    result: list[int] = []
    async with Bus() as bus:

        async def run() -> None:
            result.append(await replay(TURTLE, bus, rate=None, control=control,
                                       on_message=published.append))

        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            await anyio.wait_all_tasks_blocked()
            assert published == [] and control.paused
            control.resume()
    assert result == [2689] and len(published) == 2689
