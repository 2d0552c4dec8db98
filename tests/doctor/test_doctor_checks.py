"""``tfbus.doctor.diagnose`` on recordings: every check finds its fault (check, level,
frames, sender) on a recording that has exactly that fault and nothing else, the clean
robot and the repository's real recordings give no false positive (the findings on the
real ones are recomputed here from the messages), a damaged bag is a finding, the JSON
validates against the documented schema, and memory stays bounded."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from doctor_faults import (
    AMCL_DELAY_NS,
    CLOCK_AHEAD_NS,
    EXPECTED,
    FAULTS,
    LAG_NS,
    MS,
    ODOM_DELAY_NS,
    REPEATED,
    SWAPPED,
    T0,
    clean,
    static_and_dynamic,
    tf,
    write_ros1,
)

from tfbus import Time
from tfbus.bag import BagMessage, read_messages, write_bag
from tfbus.doctor import (
    CHECKS,
    REPORT_SCHEMA,
    Doctor,
    Finding,
    Level,
    Report,
    Thresholds,
    diagnose,
)
from tfbus.messages import TFMessage

DATA = Path(__file__).resolve().parents[1] / "data"

E, W, INFO = Level.ERROR, Level.WARNING, Level.INFO


def _only(report: Report) -> Finding:
    assert len(report.findings) == 1, [(f.check, f.message) for f in report.findings]
    return report.findings[0]


def _validate(report: Report) -> None:
    import jsonschema

    jsonschema.validate(json.loads(report.to_json()), REPORT_SCHEMA)


def test_every_check_has_a_recording_and_a_rule() -> None:
    """The fault table covers every check that a recording of a robot can show (the rest
    are tested below by hand), and each check names its rule and reference."""
    by_hand = {"damaged_recording", "post_dated", "too_many_frames"}
    assert set(FAULTS) | by_hand == set(CHECKS)
    assert all(c.rule and c.reference for c in CHECKS.values())


def test_the_clean_robot_has_no_finding(tmp_path: Path) -> None:
    report = diagnose(write_ros1(tmp_path / "clean.bag", clean()))
    assert report.findings == ()
    # Frame ids map, odom, base_link, base_footprint, laser; links: every one but map.
    assert (report.messages, report.transforms, report.frames, report.links) == (601, 602,
                                                                                5, 4)
    delays = {b.sender: b.median for b in report.broadcasters}
    assert delays == pytest.approx({"/amcl": AMCL_DELAY_NS / 1e9 + 1e-6,
                                    "/odometry": ODOM_DELAY_NS / 1e9 + 1e-6})
    _validate(report)


@pytest.mark.parametrize("check", sorted(FAULTS))
def test_each_fault_is_found_alone(tmp_path: Path, check: str) -> None:
    """The doctor names the fault, its frames and its sender, and nothing else."""
    report = diagnose(write_ros1(tmp_path / f"{check}.bag", FAULTS[check]()))
    found = _only(report)
    level, frames, senders = EXPECTED[check]
    assert (found.check, found.level, found.frames, found.senders) == (check, level, frames,
                                                                       senders)
    assert found.reference == CHECKS[check].reference and found.advice
    _validate(report)


def test_the_numbers_behind_the_findings(tmp_path: Path) -> None:
    """Counts and spans computed by hand from the generators' constants."""
    def one(check: str) -> Finding:
        return _only(diagnose(write_ros1(tmp_path / f"{check}.bag", FAULTS[check]())))

    f = one("several_authorities")  # /rogue: 10 Hz over [3 s, 6 s)
    assert dict(f.counts) == {"/odometry": 500, "/rogue": 30}
    assert "at the same time" in f.message
    f = one("repeated_stamps")
    assert dict(f.counts) == {"/odometry": REPEATED}
    f = one("out_of_order")
    assert dict(f.counts) == {"/odometry": SWAPPED, "old_data": 0}
    f = one("gap")  # last stamp before: 3.98 s, first after: 5.0 s
    assert (f.counts["longest_from_ns"], f.counts["longest_to_ns"]) == (T0 + 3980 * MS,
                                                                        T0 + 5000 * MS)
    f = one("rate_drop")
    assert f.counts["steady_hz"] == pytest.approx(50.0, rel=1e-3)
    assert f.counts["lowest_hz"] == pytest.approx(20.0, rel=1e-3)
    f = one("stopped")  # last odom->base_link received at 6.98 s + 5 ms, end at 9.9 s + 20 ms
    assert f.start_ns == T0 + 6980 * MS + ODOM_DELAY_NS + 1000
    assert f.end_ns == T0 + 9900 * MS + AMCL_DELAY_NS + 1000
    assert f.counts["period_s"] == pytest.approx(0.02)
    f = one("clock_offset")
    assert f.counts["median_delay_s"] == pytest.approx(-CLOCK_AHEAD_NS / 1e9, abs=1e-5)
    f = one("latency")
    assert f.counts["median_delay_s"] - f.counts["lowest_median_s"] == pytest.approx(
        (LAG_NS - ODOM_DELAY_NS) / 1e9, abs=1e-5)
    f = one("disconnected")
    assert dict(f.counts) == {"map": 4, "laser_mount": 2}
    assert f.lookups == (("map", "laser_mount"),)


@pytest.mark.parametrize("fmt", ["sqlite3", "mcap"])
def test_ros2_recordings_are_diagnosed_too(tmp_path: Path, fmt: str) -> None:
    """ROS 2 bags carry no sender: the finding names tf2_ros's placeholder authority."""
    msgs = [BagMessage(Time.from_ns(t), topic, TFMessage(tfs))
            for t, topic, _, tfs in sorted(static_and_dynamic(), key=lambda r: r[0])]
    path = tmp_path / f"bag_{fmt}"
    write_bag(path, msgs, format=fmt)
    found = _only(diagnose(path))
    assert (found.check, found.frames, found.senders) == (
        "static_and_dynamic", ("laser", "base_link"), ("Authority undetectable",))


def test_a_damaged_recording_is_a_finding(tmp_path: Path) -> None:
    """A bag cut in the middle: what was read is diagnosed, the damage is one finding."""
    path = write_ros1(tmp_path / "whole.bag", clean())
    cut = tmp_path / "cut.bag"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    report = diagnose(cut)
    found = _only(report)
    assert (found.check, found.level) == ("damaged_recording", E)
    assert "truncated" in found.message and str(cut) in found.message
    assert 0 < report.messages < 601
    _validate(report)


@pytest.mark.parametrize("fmt", ["sqlite3", "mcap"])
def test_a_damaged_ros2_recording_is_a_finding(tmp_path: Path, fmt: str) -> None:
    msgs = [BagMessage(Time.from_ns(t), topic, TFMessage(tfs))
            for t, topic, _, tfs in sorted(clean(), key=lambda r: r[0])]
    path = tmp_path / f"bag_{fmt}"
    write_bag(path, msgs, format=fmt)
    (data,) = [f for f in path.iterdir() if f.suffix in (".db3", ".mcap")]
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    found = _only(diagnose(path))
    assert (found.check, found.level) == ("damaged_recording", E)
    assert str(path) in found.message


# --------------------------------------------------------------------------- real recordings


@pytest.mark.parametrize("name", ["webviz_turtle_tf_example.bag", "nav2_like.mcap",
                                  "tf_example"])
def test_real_recordings_without_faults(name: str) -> None:
    report = diagnose(DATA / name)
    assert report.findings == ()
    _validate(report)


def _mean_delays(path: Path) -> dict[str, float]:
    """Mean receive time - stamp (s) of each child frame, straight from the bag."""
    sums: dict[str, list[float]] = {}
    for rec in read_messages(path):
        for ts in rec.message.transforms:
            s = sums.setdefault(ts.child_frame_id.lstrip("/"), [0.0, 0])
            s[0] += (rec.time.ns - ts.header.stamp.ns) / 1e9
            s[1] += 1
    return {c: s / n for c, (s, n) in sums.items()}


def test_guardian_fixed_joints_are_post_dated_not_a_clock_offset() -> None:
    """drl_guardian_3.bag (2014, ROS 1, no /tf_static): robot_state_publisher stamped its
    fixed joints 0.5 s ahead (publishFixedTransforms: now + 0.5 s) while odometry is on
    time: one post_dated finding naming exactly the frames whose mean delay is below
    -10 ms, recomputed here from the messages; no clock_offset."""
    path = DATA / "laser" / "drl_guardian_3.bag"
    means = _mean_delays(path)
    ahead = sorted(c for c, m in means.items() if m < -0.01)
    assert len(ahead) == 7 and means["base_footprint"] > 0
    found = _only(diagnose(path))
    assert (found.check, found.level, found.frames) == ("post_dated", INFO, tuple(ahead))
    assert found.counts["base_link"] == pytest.approx(-means["base_link"])


def test_jarvis_control_points_start_with_a_slash() -> None:
    """drl_jarvis_complex_path_fast.bag: four frames are named '/ControlPoint/N' (a real
    leading '/': every other id has none) and stamped 50 ms ahead (post-dated; the rest of
    the sender's frames are on time), recomputed here from the messages."""
    path = DATA / "laser" / "drl_jarvis_complex_path_fast.bag"
    slashed = sorted({ts.child_frame_id for rec in read_messages(path)
                      for ts in rec.message.transforms if ts.child_frame_id.startswith("/")})
    means = _mean_delays(path)
    ahead = tuple(sorted(c for c, m in means.items() if m < -0.01))
    report = diagnose(path)
    assert [(f.check, f.frames) for f in report.findings] == [
        *(("leading_slash", (s,)) for s in slashed), ("post_dated", ahead)]
    assert slashed == [f"/ControlPoint/{k}" for k in range(4)]


# --------------------------------------------------------------------------- by hand


def _feed(doctor: Doctor, t_ns: int, *tfs: object, sender: str = "/a",
          static: bool = False) -> None:
    doctor.add(t_ns, tfs, sender, static=static)  # type: ignore[arg-type]


def test_every_slashed_id_is_counted_whatever_came_before_it() -> None:
    """A leading '/' is counted on every transform that has one: also after the same
    link arrived again and again without it, and after ids slashed twice ("//b", "//p",
    whose link is stored as "/b" under "/p": the very strings a once-slashed "/p" ->
    "/b" carries before its slash is stripped)."""
    d = Doctor()
    for k in range(3):
        _feed(d, T0 + k * MS, tf("p", "b", T0 + k * MS))
    _feed(d, T0 + 3 * MS, tf("/p", "/b", T0 + 3 * MS))
    for k in range(4, 6):
        _feed(d, T0 + k * MS, tf("//p", "//b", T0 + k * MS))
    for k in range(6, 9):
        _feed(d, T0 + k * MS, tf("/p", "/b", T0 + k * MS))
    found = {f.frames[0]: f.counts["transforms"] for f in d.report().by_check("leading_slash")}
    assert found == {"/b": 4, "/p": 4, "//b": 2, "//p": 2}
    assert d.transforms == 9


def test_stamps_older_than_the_cache_are_an_error() -> None:
    """A stamp 11 s behind the frame's newest (tf2's cache_time 10 s): TF_OLD_DATA."""
    d = Doctor()
    for k in range(20):
        _feed(d, T0 + k * 100 * MS, tf("odom", "base", T0 + k * 100 * MS))
    _feed(d, T0 + 2000 * MS, tf("odom", "base", T0 - 9100 * MS))
    found = _only(d.report())
    assert (found.check, found.level, dict(found.counts)) == (
        "out_of_order", E, {"/a": 1, "old_data": 1})


def test_one_broadcaster_after_another_is_info() -> None:
    d = Doctor()
    for k in range(10):
        _feed(d, T0 + k * 100 * MS, tf("odom", "base", T0 + k * 100 * MS), sender="/old")
    for k in range(10, 20):
        _feed(d, T0 + k * 100 * MS, tf("odom", "base", T0 + k * 100 * MS), sender="/new")
    found = _only(d.report())
    assert (found.check, found.level, found.senders) == ("several_authorities", INFO,
                                                         ("/old", "/new"))


def test_a_self_transform_is_a_loop_and_world_frames_below_the_robot_break_rep105() -> None:
    d = Doctor()
    _feed(d, T0, tf("cam", "cam", T0), static=True)
    _feed(d, T0, tf("base_footprint", "odom", T0), static=True)
    got = [(f.check, f.level, f.frames) for f in d.report().findings]
    assert got == [("loop", E, ("cam",)), ("rep105", E, ("odom", "base_footprint"))]


def test_a_loop_of_three_is_named_in_parent_order_once() -> None:
    """b below a, c below b, then a below c: one loop, a -> c -> b -> a (each frame then
    its parent), seen from the link that closed it; sent again, still one finding."""
    d = Doctor()
    _feed(d, T0, tf("a", "b", T0), tf("b", "c", T0), static=True)
    _feed(d, T0 + MS, tf("c", "a", T0), sender="/closer", static=True)
    _feed(d, T0 + 2 * MS, tf("c", "a", T0), sender="/closer", static=True)
    found = _only(d.report())
    assert (found.check, found.frames, found.senders) == ("loop", ("a", "c", "b"),
                                                          ("/closer",))
    assert found.message == "loop: a -> c -> b -> a"
    assert (found.start_ns, found.end_ns) == (T0 + MS, T0 + MS)


def test_identical_statics_from_two_senders_are_fine_different_ones_are_not() -> None:
    d = Doctor()
    _feed(d, T0, tf("base", "cam", T0), sender="/a", static=True)
    _feed(d, T0, tf("base", "cam", T0), sender="/b", static=True)
    assert d.report().findings == ()
    _feed(d, T0 + MS, tf("base", "cam", T0, x=2.0), sender="/b", static=True)
    found = _only(d.report())
    assert (found.check, found.level, found.senders) == ("several_authorities", W,
                                                         ("/a", "/b"))


def test_renaming_the_unknown_sender_topic_by_topic() -> None:
    """Live, messages come as "unknown" until liveliness names their broadcaster: the
    /tf_static ones go to the static publisher, the /tf ones to the dynamic one."""
    d = Doctor()
    _feed(d, T0, tf("base", "cam", T0), sender="unknown", static=True)
    for k in range(12):
        _feed(d, T0 + k * 10 * MS, tf("base", "cam", T0 + k * 10 * MS), sender="unknown")
    d.rename_authority("unknown", "/static_pub", static=True)
    d.rename_authority("unknown", "/driver", static=False)
    found = _only(d.report())
    assert (found.check, found.senders) == ("static_and_dynamic", ("/driver", "/static_pub"))
    assert [b.sender for b in d.report().broadcasters] == ["/driver"]


def test_memory_is_bounded_by_frames_and_senders_not_messages() -> None:
    """100 000 messages on 3 frames keep a bounded sample; frames past max_frames are
    counted, not tracked."""
    import tracemalloc

    th = Thresholds(max_frames=3, delay_samples=64)
    d = Doctor(th)
    items = [tf("map", f"f{k}", T0) for k in range(5)]
    tracemalloc.start()
    try:
        for k in range(100_000):
            ts = items[k % 5]
            _feed(d, T0 + k * MS, ts._replace(header=ts.header._replace(
                stamp=Time.from_ns(T0 + k * MS))))
        snapshot = tracemalloc.take_snapshot().filter_traces(
            [tracemalloc.Filter(True, "*/tfbus/doctor/*")])
    finally:
        tracemalloc.stop()
    held = sum(stat.size for stat in snapshot.statistics("filename"))
    assert 0 < held < 50_000  # bytes the doctor allocated and holds: per frame, not message
    report = d.report()
    assert (report.frames, report.links) == (4, 3)  # map and f0..f2; the tracked links
    assert all(b.samples <= 64 for b in report.broadcasters)
    assert report.broadcasters[0].transforms == 60_000
    (found,) = report.by_check("too_many_frames")
    assert found.counts["untracked_transforms"] == 40_000


def test_a_peer_making_loops_at_random_cannot_grow_memory() -> None:
    """Frames re-parented into ever new loops: MAX_LOOPS are remembered, the rest counted."""
    from tfbus.doctor.checks import MAX_LOOPS

    d = Doctor()
    for k in range(MAX_LOOPS + 50):
        _feed(d, T0 + k, tf(f"a{k}", f"b{k}", T0), tf(f"b{k}", f"a{k}", T0), static=True)
    report = d.report()
    assert len(report.by_check("loop")) == MAX_LOOPS
    (found,) = report.by_check("too_many_frames")
    assert found.counts["untracked_loops"] == 50


@pytest.mark.parametrize(("field", "value"), [("stale_periods", 0), ("gap_min", float("nan")),
                                              ("rate_drop", 1.5), ("max_frames", 2.5),
                                              ("lag", True)])
def test_bad_thresholds_name_the_field_and_value(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"Thresholds.{field} .*{value!r}"):
        Thresholds(**{field: value})  # type: ignore[arg-type]


def test_at_least_and_level_names() -> None:
    d = Doctor()
    _feed(d, T0, tf("cam", "cam", T0), static=True)
    _feed(d, T0, tf("/x", "y", T0), static=True)
    _feed(d, T0, tf("a", "b", T0), static=True)
    report = d.report()
    assert [f.check for f in report.at_least("error")] == ["leading_slash", "loop"]
    assert [f.check for f in report.at_least(Level.WARNING)] == ["leading_slash", "loop",
                                                                "disconnected"]
    with pytest.raises(ValueError, match="'fatal'"):
        report.at_least("fatal")
