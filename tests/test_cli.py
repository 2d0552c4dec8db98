"""The ``tfbus`` command line, through click's CliRunner, plus one run of the installed
entry point. Bag data: tests/data/webviz_turtle_tf_example.bag (Apache-2.0)."""

from __future__ import annotations

import importlib.util
import itertools
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rosbags")

from click.testing import CliRunner

from tfbus import Time
from tfbus.bag import load_buffer, read_messages
from tfbus.cli import cli, frames_dot, main, parse_static_args, parse_time

DATA = Path(__file__).parent / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
NAV2 = DATA / "nav2_like.mcap"  # scripts/make_test_bags.py (tests/data/SOURCES.md)
COMMANDS = ["bag-info", "echo", "monitor", "frames", "static-transform", "replay",
            "robot-state-publisher", "joint-states", "demo", "view"]


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def assert_usage_error(code: int, err: str, *needles: str) -> None:
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert re.match(r"^tfbus( [a-z-]+)?: error: ", lines[0]), lines[0]
    for needle in needles:
        assert needle in lines[0]


# --------------------------------------------------------------------------- help


def test_group_help_lists_commands() -> None:
    code, out, _ = run("--help")
    assert code == 0
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_has_help_with_examples(command: str) -> None:
    code, out, _ = run(command, "--help")
    assert code == 0
    assert "Examples:" in out and f"tfbus {command}" in out


def test_version() -> None:
    from importlib.metadata import version

    from tfbus import _backend

    code, out, _ = run("--version")
    assert code == 0
    core = "compiled core" if _backend.COMPILED else "pure-Python core: "
    assert out.startswith(f"tfbus {version('tfbus')} ({core}")
    assert out == f"tfbus {version('tfbus')} ({_backend.core_description()})\n"


def test_version_of_a_source_tree_that_is_not_installed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without package metadata, tfbus._version (the one source of the version) says
    ``0+unknown`` rather than a stale number, and --version shows that."""
    import importlib
    import importlib.metadata

    import tfbus._version

    def not_installed(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    try:
        importlib.reload(tfbus._version)
        code, out, _ = run("--version")
        assert (code, out.split(" (")[0]) == (0, "tfbus 0+unknown")
    finally:
        monkeypatch.undo()
        importlib.reload(tfbus._version)
    code, out, _ = run("--version")
    assert (code, out.split(" (")[0]) == (0, f"tfbus {importlib.metadata.version('tfbus')}")


def test_unknown_command_and_option_are_one_line() -> None:
    code, _, err = run("nope")
    assert_usage_error(code, err, "nope")
    code, _, err = run("bag-info", "--bogus", str(TURTLE))
    assert_usage_error(code, err, "--bogus")


# --------------------------------------------------------------------------- bag-info


def test_bag_info() -> None:
    code, out, _ = run("bag-info", str(TURTLE))
    assert code == 0
    assert "ros1" in out
    assert "/tf 2688, /tf_static 1" in out
    assert "1396293888.046138414" in out and "21.499 s" in out
    assert "4 (1 static links, 2 dynamic links, 2689 transforms)" in out
    rows = {line.split()[0]: line for line in out.splitlines() if "│" in line}
    assert "world" in rows["turtle1"] and "dynamic" in rows["turtle1"]
    assert "1344" in rows["turtle1"] and "62.50" in rows["turtle1"]
    assert "/turtle1_tf_broadcaster" in rows["turtle1"]
    assert "static" in rows["carrot"] and "turtle1" in rows["carrot"]


def test_bag_info_mcap() -> None:
    code, out, _ = run("bag-info", str(NAV2))
    assert code == 0
    assert "mcap" in out and "34 (29 static links, 4 dynamic links, 4409 transforms)" in out


def test_bag_info_errors(tmp_path: Path) -> None:
    code, _, err = run("bag-info", str(tmp_path / "missing.bag"))
    assert_usage_error(code, err, "missing.bag")
    junk = tmp_path / "junk.bag"
    junk.write_text("not a bag")
    code, _, err = run("bag-info", str(junk))
    assert_usage_error(code, err, "unknown format")


def test_bag_info_truncated_shows_prefix_and_warns(tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    data = TURTLE.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    code, out, err = run("bag-info", str(cut))
    assert code == 1
    assert "turtle1" in out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "warning" in lines[0] and "reading stopped" in lines[0]


# --------------------------------------------------------------------------- echo


def _numbers(line: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+\.\d+", line)]


def test_echo_at_time_matches_buffer() -> None:
    t = "1396293900.5"
    code, out, _ = run("echo", "world", "carrot", "--bag", str(TURTLE), "--time", t,
                       "--matrix", "-p", "6")
    assert code == 0
    expect = load_buffer(TURTLE).lookup_transform("world", "carrot", parse_time(t))
    lines = out.splitlines()
    assert lines[0] == "At time 1396293900.500000000"
    tr = _numbers(lines[1])
    assert tr == pytest.approx(list(expect.transform.translation), abs=1e-6)
    q = _numbers(lines[2])
    assert q == pytest.approx(list(expect.transform.rotation), abs=1e-6)
    x, y, z, w = expect.transform.rotation
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    assert _numbers(lines[3])[2] == pytest.approx(yaw, abs=1e-6)
    assert _numbers(lines[4])[2] == pytest.approx(math.degrees(yaw), abs=1e-5)
    assert lines[5] == "- Matrix:"
    row0 = _numbers(lines[6])
    assert row0[0] == pytest.approx(math.cos(yaw), abs=1e-6)
    assert row0[3] == pytest.approx(expect.transform.translation.x, abs=1e-6)


def test_echo_steps_through_bag() -> None:
    code, out, _ = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--rate", "2",
                       "-n", "5")
    assert code == 0
    stamps = [line.split()[-1] for line in out.splitlines() if line.startswith("At time")]
    assert len(stamps) == 5
    secs = [Time(int(s.split(".")[0]), int(s.split(".")[1])).ns for s in stamps]
    assert all(b - a == 500_000_000 for a, b in itertools.pairwise(secs))
    first = next(iter(read_messages(TURTLE, topics=["/tf"])))
    assert secs[0] >= first.message.transforms[0].header.stamp.ns


def test_echo_static_pair_prints_once() -> None:
    code, out, _ = run("echo", "turtle1", "carrot", "--bag", str(TURTLE))
    assert code == 0 and out.count("At time") == 1
    assert "- Translation: [1.000, 0.000, 0.000]" in out


def test_echo_failure_and_bad_arguments() -> None:
    code, out, _ = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--time", "100")
    assert code == 1 and "Failure at" in out and "Exception thrown" in out
    code, _, err = run("echo", "world", "nope", "--bag", str(TURTLE))
    assert_usage_error(code, err, "'nope'")
    code, _, err = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--time", "soon")
    assert_usage_error(code, err, "soon")
    code, _, err = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--rate", "0")
    assert_usage_error(code, err, "--rate")
    code, _, err = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--bus", "zenoh")
    assert_usage_error(code, err, "--bag", "--bus")


@pytest.mark.parametrize("command", ["echo", "monitor", "frames"])
def test_readers_listen_on_the_default_bus_without_a_source(
    command: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Issue 20, 2.6: ``tfbus echo base_link base_laser`` with no --bag/--bus listens to
    the bus the publishers publish on by default, as tf2_echo listens to the running
    graph (no usage error). The live session is replaced by a Ctrl-C (exit 130)."""
    import importlib

    import tfbus.cli._sources as sources

    parsed: list[str] = []
    real_parse = sources.parse_spec

    def parse(spec: str, **kwargs: str):  # type: ignore[no-untyped-def]
        parsed.append(spec)
        return real_parse(spec, **kwargs)

    monkeypatch.setattr(sources, "parse_spec", parse)
    module = importlib.import_module(f"tfbus.cli.{command}")
    opened: list[object] = []

    def interrupted(main: object, **_: object) -> int:
        opened.append(main)
        return 130

    monkeypatch.setattr(module, "run_live", interrupted)
    args = {"echo": ["base_link", "base_laser"], "monitor": [],
            "frames": ["-o", str(tmp_path / "f.gv")]}[command]
    code, _, err = run(command, *args)
    assert (code, len(opened)) == (130, 1), err
    reader = parsed[:]
    sources.publish_bus(None, False, name="static_transform_publisher")
    assert reader == [sources.DEFAULT_BUS] == parsed[1:] == ["zenoh"]


def test_echo_takes_tf2_echos_positional_rate() -> None:
    """Issue 20, 2.7: ``tf2_echo source target [rate]``: RATE as the third argument is
    --rate (steps of 1/rate s of bag time through the turtle bag's 21.5 s of chain)."""
    base = ["echo", "world", "turtle1", "--bag", str(TURTLE)]
    counts = {}
    for extra in ([], ["4"], ["--rate", "4"]):
        code, out, _ = run(*base[:3], *extra, *base[3:])
        assert code == 0
        counts[" ".join(extra)] = out.count("At time")
    assert counts["4"] == counts["--rate 4"] > 3.5 * counts[""] > 0
    code, _, err = run(*base[:3], "4", "--rate", "2", *base[3:])
    assert_usage_error(code, err, "RATE 4", "--rate 2")
    code, _, err = run(*base[:3], "0", *base[3:])
    assert_usage_error(code, err, "RATE")


@pytest.mark.parametrize(("args", "label", "frame"), [
    (["/world", "turtle1"], "target_frame", "/world"),
    (["world", "/turtle1"], "source_frame", "/turtle1"),
])
def test_echo_leading_slash_is_tf2s_own_message(
    args: list[str], label: str, frame: str
) -> None:
    """Issue 20, 2.7: tf2's validateFrameId message (as the conformance corpus records it
    from tf2 0.7.6), one line, exit status 1 as a failed lookup; with --bag and on a
    live bus alike (nothing is opened for a frame id that can never be found)."""
    expected = (f'tfbus echo: error: Invalid argument "{frame}" passed to lookupTransform '
                f"argument {label} in tf2 frame_ids cannot start with a '/' like:")
    for source in (["--bag", str(TURTLE)], []):
        code, out, err = run("echo", *args, *source)
        assert (code, out, err.rstrip("\n").splitlines()) == (1, "", [expected])
    from tfbus import BufferCore, InvalidArgumentException
    from tfbus.messages import Header, Transform, TransformStamped

    core = BufferCore()
    core.set_transform(TransformStamped(Header(Time(1), "world"), "turtle1", Transform()), "t")
    with pytest.raises(InvalidArgumentException) as info:
        core.lookup_transform(*args, Time(0))
    assert expected.endswith(str(info.value).strip())


def test_parse_time() -> None:
    assert parse_time("latest") == Time(0)
    assert parse_time("1396293909.544282913") == Time(1396293909, 544282913)
    assert parse_time("12.5") == Time(12, 500_000_000)
    assert parse_time("1e3") == Time(1000)
    assert parse_time("42ns") == Time.from_ns(42)
    for bad in ("-1", "abc", "nan"):
        with pytest.raises(ValueError):
            parse_time(bad)


# --------------------------------------------------------------------------- monitor


def test_monitor() -> None:
    code, out, _ = run("monitor", "--bag", str(TURTLE))
    assert code == 0
    assert "RESULTS: for all Frames" in out
    rows = {line.split()[0]: line for line in out.splitlines() if "│" in line}
    assert "/turtle1_tf_broadcaster" in rows["turtle1"]
    assert _numbers(rows["turtle1"])[0] == pytest.approx(62.5, abs=0.05)
    assert "static" in rows["carrot"]
    assert "/turtle2_tf_broadcaster" in rows
    code, out, _ = run("monitor", "world", "carrot", "--bag", str(TURTLE))
    assert code == 0 and "turtle2 " not in out.split("All Broadcasters")[0]
    code, _, err = run("monitor", "world", "--bag", str(TURTLE))
    assert_usage_error(code, err, "two")


# --------------------------------------------------------------------------- frames


def test_frames_dot_text(tmp_path: Path) -> None:
    out = tmp_path / "tree.gv"
    code, stdout, _ = run("frames", "--bag", str(TURTLE), "-o", str(out))
    assert code == 0 and str(out) in stdout
    dot = out.read_text()
    assert dot.startswith("digraph G {")
    assert "world -> turtle1" in dot and "world -> turtle2" in dot and "turtle1 -> carrot" in dot
    assert "Broadcaster: /turtle1_tf_broadcaster" in dot
    assert "Most recent transform: 1396293909.544" in dot
    assert "Oldest transform: 1396293888.056" in dot
    assert "Average rate: static" in dot
    assert "view_frames Result" in dot
    assert frames_dot(load_buffer(TURTLE)) == dot


def test_frames_pdf_renders_or_explains(tmp_path: Path) -> None:
    out = tmp_path / "frames.pdf"
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(out))
    assert (tmp_path / "frames.gv").exists()
    if shutil.which("dot"):
        assert code == 0, f"Graphviz failed: {err}"  # issue 10 §4: its error text shown
        assert out.read_bytes().startswith(b"%PDF")
    else:
        assert code == 1 and "'dot' not found" in err and len(err.strip().splitlines()) == 1


def test_frames_bad_output() -> None:
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", "frames.jpg")
    assert_usage_error(code, err, "frames.jpg")


# --------------------------------------------------------------------------- static-transform


def test_parse_static_args_rpy_and_quaternion() -> None:
    ts = parse_static_args(["0.1", "0", "0.2", "1.5707963267948966", "0", "0", "a", "b"])
    assert ts.header.frame_id == "a" and ts.child_frame_id == "b"
    assert tuple(ts.transform.translation) == (0.1, 0.0, 0.2)
    q = ts.transform.rotation  # yaw 90 deg about Z
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    ts = parse_static_args(["0", "0", "0", "0", "0.5", "0", "a", "b"])  # pitch about Y
    assert tuple(ts.transform.rotation) == pytest.approx((0, math.sin(0.25), 0, math.cos(0.25)))
    ts = parse_static_args(["0", "0", "0", "0", "0", "0.5", "a", "b"])  # roll about X
    assert tuple(ts.transform.rotation) == pytest.approx((math.sin(0.25), 0, 0, math.cos(0.25)))
    ts = parse_static_args(["1", "2", "3", "0", "0", "0", "2", "p", "c"])  # quaternion, scaled
    assert tuple(ts.transform.rotation) == (0.0, 0.0, 0.0, 1.0)
    ts = parse_static_args(["0", "0", "0", "0", "0", "0", "p", "c", "100"])  # ROS 1 period
    assert ts.child_frame_id == "c"
    for bad in (["1", "2"], ["x", "0", "0", "0", "0", "0", "a", "b"],
                ["0", "0", "0", "0", "0", "0", "a", "a"],
                ["0", "0", "0", "0", "0", "0", "0", "a", "b"]):
        with pytest.raises(ValueError):
            parse_static_args(bad)


def test_static_transform_publishes_once() -> None:
    code, out, _ = run("static-transform", "-1", "0", "0.2", "0", "0", "0",
                       "base_link", "base_laser", "--once", "--local")
    assert code == 0
    assert "base_link -> base_laser" in out and "(-1.0, 0.0, 0.2)" in out


def test_static_transform_publishes_on_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    import tfbus.cli.static_transform as tcli

    seen = []

    async def fake(open_bus: object, ts: object, once: bool) -> None:
        seen.append((ts, once))

    monkeypatch.setattr(tcli, "_publish_static", fake)
    code, _, _ = run("static-transform", "0", "0", "1", "0", "0", "0", "1", "world", "cam",
                     "--local")
    assert code == 0 and len(seen) == 1 and seen[0][1] is False


async def _published_static() -> list[object]:
    from tfbus.broadcaster import StaticTransformBroadcaster
    from tfbus.bus import Bus

    ts = parse_static_args(["0", "0", "1", "0", "0", "0", "world", "cam"])
    async with Bus() as bus:
        await StaticTransformBroadcaster(bus).send_transform(ts)
        with bus.subscribe("/tf_static") as sub:
            return list(sub.receive_nowait().transforms)


def test_static_transform_message_is_latched() -> None:
    import anyio

    (ts,) = anyio.run(_published_static)
    assert ts.child_frame_id == "cam"  # type: ignore[attr-defined]


def test_static_transform_bad_arguments() -> None:
    code, _, err = run("static-transform", "1", "2", "3")
    assert_usage_error(code, err, "expected 8 arguments")
    code, _, err = run("static-transform", "1", "2", "x", "0", "0", "0", "a", "b")
    assert_usage_error(code, err, "'x' is not a number")


def test_static_transform_takes_ros2_flags(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 20, 2.7: ROS 2's flag form (tf2_ros static_transform_broadcaster_program.cpp):
    every flag optional (translation 0, quaternion (0, 0, 0, 1), RPY 0) but the frame
    ids; quaternion and RPY flags together, flags mixed with positional arguments or a
    flag without its value are errors."""
    ts = parse_static_args(["--x", "0.1", "--z", "0.2", "--frame-id", "base_link",
                            "--child-frame-id", "base_laser"])
    assert (ts.header.frame_id, ts.child_frame_id) == ("base_link", "base_laser")
    assert tuple(ts.transform.translation) == (0.1, 0.0, 0.2)
    assert tuple(ts.transform.rotation) == (0.0, 0.0, 0.0, 1.0)
    ts = parse_static_args(["--yaw", "1.5707963267948966", "--y", "-1", "--frame-id", "a",
                            "--child-frame-id", "b"])
    assert tuple(ts.transform.translation) == (0.0, -1.0, 0.0)
    assert tuple(ts.transform.rotation) == pytest.approx(
        (0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    rpy = parse_static_args(["--roll", "0.3", "--pitch", "-0.2", "--yaw", "1.1",
                             "--frame-id", "a", "--child-frame-id", "b"])
    old = parse_static_args(["0", "0", "0", "1.1", "-0.2", "0.3", "a", "b"])  # yaw pitch roll
    assert rpy == old
    ts = parse_static_args(["--qz", "1", "--frame-id", "a", "--child-frame-id", "b"])
    assert tuple(ts.transform.rotation) == pytest.approx((0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    for bad, needle in [
        (["--x", "1", "--frame-id", "a"], "--child-frame-id"),
        (["--child-frame-id", "b"], "--frame-id"),
        (["--qx", "1", "--roll", "1", "--frame-id", "a", "--child-frame-id", "b"],
         "both quaternion"),
        (["0", "0", "0", "0", "0", "0", "a", "b", "--x", "1"], "new-style"),
        (["--frame-id", "a", "--child-frame-id", "b", "--x"], "--x"),
        (["--x", "--frame-id", "a", "--child-frame-id", "b"], "--x"),
        (["--x", "one", "--frame-id", "a", "--child-frame-id", "b"], "--x: 'one'"),
        (["--frame-id", "a", "--child-frame-id", "a"], "both 'a'"),
    ]:
        with pytest.raises(ValueError, match=re.escape(needle)):
            parse_static_args(bad)
    import tfbus.cli.static_transform as tcli

    seen = []

    async def fake(open_bus: object, ts: object, once: bool) -> None:
        seen.append(ts)

    monkeypatch.setattr(tcli, "_publish_static", fake)
    code, _, err = run("static-transform", "--x", "0.1", "--z", "0.2", "--frame-id",
                       "base_link", "--child-frame-id", "base_laser", "--local")
    assert code == 0, err
    assert seen == [parse_static_args(["0.1", "0", "0.2", "0", "0", "0", "base_link",
                                       "base_laser"])]
    code, _, err = run("static-transform", "--x", "0.1", "--frame-id", "a", "--local")
    assert_usage_error(code, err, "--child-frame-id")


# --------------------------------------------------------------------------- replay


def test_replay_fast() -> None:
    code, out, _ = run("replay", str(TURTLE), "--rate", "0", "-q", "--local")
    assert code == 0 and "replayed 2689 messages" in out
    code, out, _ = run("replay", str(TURTLE), "--rate", "0", "-q", "--local",
                       "--start", "1396293900", "--stop", "1396293901")
    assert code == 0
    n = int(re.search(r"replayed (\d+)", out).group(1))  # type: ignore[union-attr]
    assert n == 1 + len(list(read_messages(TURTLE, start=Time(1396293900),
                                           stop=Time(1396293901), latched=False)))


def test_replay_progress_bar() -> None:
    code, _, err = run("replay", str(TURTLE), "--rate", "0", "--local")
    assert code == 0 and "2689/2689" in err


def test_replay_truncated_and_bad_args(tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    data = TURTLE.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    code, _, err = run("replay", str(cut), "--rate", "0", "-q", "--local")
    assert code == 1 and "reading stopped" in err and len(err.strip().splitlines()) == 1
    code, _, err = run("replay", str(TURTLE), "--rate", "-2")
    assert_usage_error(code, err, "--rate")


# --------------------------------------------------------------------------- demo


def _fake_runners(monkeypatch: pytest.MonkeyPatch) -> list[tuple[object, ...]]:
    import tfbus.cli.demo as cdemo

    calls: list[tuple[object, ...]] = []

    def both(**options: object) -> int:
        calls.append(("both", options))
        return 0

    def role(name: str, spec: str, **options: object) -> int:
        calls.append((name, spec, options))
        return 0

    monkeypatch.setattr(cdemo, "run_both", both)
    monkeypatch.setattr(cdemo, "run_role", role)
    return calls


def test_demo_options_are_parsed_once_by_click(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 10 §3: the options reach the runners as values (no argv rebuilt for a second
    parser)."""
    calls = _fake_runners(monkeypatch)
    code, _, _ = run("demo", "--duration", "3", "--rate", "50", "--listen-rate", "2")
    assert code == 0
    assert calls == [("both", {"duration": 3.0, "rate": 50.0, "listen_rate": 2.0,
                               "backend": "asyncio"})]
    code, _, err = run("demo", "--rate", "-5")
    assert_usage_error(code, err, "--rate")


def test_demo_roles_forward_options(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _fake_runners(monkeypatch)
    code, _, _ = run("demo", "listener", "--bus", "zenoh?port=9000", "--duration", "2")
    assert code == 0
    code, _, _ = run("demo", "--duration", "3", "broadcaster", "--rate", "50")  # inherited
    assert code == 0
    assert calls == [
        ("listener", "zenoh?port=9000", {"duration": 2.0, "rate": 100.0, "listen_rate": 1.0,
                                         "backend": "asyncio"}),
        ("broadcaster", "zenoh", {"duration": 3.0, "rate": 50.0, "listen_rate": 1.0,
                                  "backend": "asyncio"}),
    ]
    code, _, err = run("demo", "broadcaster", "--listen-rate", "2")  # not a broadcaster's
    assert code == 2 and "--listen-rate" in err
    if importlib.util.find_spec("zenoh") is not None:
        code, _, err = run("demo", "listener", "--bus", "zenoh?bogus=1")
        assert code == 2 and err.strip() == (
            "tfbus demo listener: error: unknown bus option 'bogus' (known: config, connect, "
            "express, listen, mode, name, namespace, port, prefix)"
        )
    assert len(calls) == 2


def test_demo_script_runs_the_click_command(tmp_path: Path) -> None:
    """demos/robot_setup_tf.py stays runnable and parses with the same click command."""
    script = Path(__file__).resolve().parents[1] / "demos" / "robot_setup_tf.py"
    proc = subprocess.run([sys.executable, str(script), "--rate", "-1"], capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("tfbus demo: error: ") and "--rate" in proc.stderr
    proc = subprocess.run([sys.executable, str(script), "--help"], capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 0 and "tfbus demo listener" in proc.stdout


@pytest.mark.parametrize("role", ["broadcaster", "listener"])
def test_demo_role_help(role: str) -> None:
    code, out, _ = run("demo", role, "--help")
    assert code == 0
    assert "Examples:" in out and f"tfbus demo {role}" in out and "--bus" in out


# --------------------------------------------------------------------------- live --bus


@pytest.mark.parametrize("command", ["echo", "monitor", "frames"])
def test_bus_option_is_documented(command: str) -> None:
    code, out, _ = run(command, "--help")
    assert code == 0
    assert "--bus SPEC" in out and "--bus zenoh" in out and "--duration" in out


def test_bus_argument_errors() -> None:
    pytest.importorskip("zenoh")
    code, _, err = run("monitor", "--bag", str(TURTLE), "--bus", "zenoh")
    assert_usage_error(code, err, "not both")
    code, _, err = run("echo", "a", "b", "--bus", "carrier-pigeon")
    assert_usage_error(code, err, "unsupported bus")
    code, _, err = run("monitor", "--bus", "zenoh?bogus=1")
    assert_usage_error(code, err, "bogus")
    code, _, err = run("monitor", "--bag", str(TURTLE), "--duration", "1")
    assert_usage_error(code, err, "--duration applies to --bus")
    code, _, err = run("frames", "--bag", str(TURTLE), "--wait", "1", "-o", "x.gv")
    assert_usage_error(code, err, "--bus")
    code, _, err = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--duration", "1")
    assert_usage_error(code, err, "--bus")


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.anyio
async def test_bus_source_collects_attributes_and_sees_a_broadcaster_go() -> None:
    """BusSource in process, against a broadcaster on a second Zenoh session (127.0.0.1
    only, bounded waits); the subprocess versions are in tests/test_three_terminals.py."""
    pytest.importorskip("zenoh")
    import anyio
    import anyio.abc

    from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
    from tfbus.bus import Bus
    from tfbus.cli import BusSource
    from tfbus.cli.monitor import liveliness_table
    from tfbus.messages import Header, Transform, TransformStamped, Vector3
    from tfbus.transports.zenoh import ZenohTransport

    port = _free_port()
    events: list[tuple[str, str]] = []
    src = BusSource(f"zenoh?connect=tcp/127.0.0.1:{port}", name="test-monitor")
    assert src.name == "test-monitor" and src.label.startswith("the bus")
    publisher = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="robot_tf_publisher")
    stop = anyio.Event()

    async def broadcaster(*, task_status: anyio.abc.TaskStatus[Bus]) -> None:
        async with Bus(transport=publisher) as bus:
            await StaticTransformBroadcaster(bus).send_transform(
                parse_static_args(["0", "0", "1", "0", "0", "0", "base_link", "camera"])
            )
            task_status.started(bus)
            await stop.wait()

    async with anyio.create_task_group() as tg:
        bus: Bus = await tg.start(broadcaster)
        async with src.attach(lambda what, info: events.append((what, info.name))):
            tf = TransformBroadcaster(bus)

            def laser(ns: int) -> TransformStamped:
                return TransformStamped(Header(Time.from_ns(ns), "base_link"), "base_laser",
                                        Transform(Vector3(0.1, 0.0, 0.2)))

            with anyio.fail_after(15):
                ns = 1
                while ("alive", "robot_tf_publisher") not in events or not src.buffer(
                ).can_transform("camera", "base_laser", Time(0)):
                    await tf.send_transform(laser(ns))
                    ns += 1
                    await anyio.sleep(0.02)
                for _ in range(30):  # now attributed: the majority is the broadcaster
                    await tf.send_transform(laser(ns))
                    ns += 1
                    await anyio.sleep(0.005)
                while src.statistics().frames["base_laser"].count < ns - 1 - 5:
                    await anyio.sleep(0.02)
            s = src.statistics()
            # Issue 10 §3: the live source is a TransformListener feeding the Buffer and
            # tfbus.monitor's statistics, not a second feed loop.
            from tfbus.listener import TransformListener

            assert isinstance(src.listener, TransformListener)
            assert src.listener.statistics().stored >= s.transform_count - 1
            assert s.frames["base_laser"].authority == "robot_tf_publisher"
            assert s.frames["camera"].static
            got = src.buffer().lookup_transform("base_link", "base_laser", Time(0))
            assert got.transform.translation.z == 0.2
            assert [p.name for p in src.alive_broadcasters().values()] == ["robot_tf_publisher"]
            stop.set()  # the broadcaster goes away
            with anyio.fail_after(10):
                while ("gone", "robot_tf_publisher") not in events:
                    await anyio.sleep(0.02)
            assert not src.alive_broadcasters()
            assert [p.name for p in src.gone.values()] == ["robot_tf_publisher"]
            assert liveliness_table(src).row_count == 1
    assert src.transport is None and not src.alive_broadcasters()


# --------------------------------------------------------------------------- entry points


def test_main_returns_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bag-info", str(TURTLE)]) == 0
    assert main(["echo", "world"]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith("tfbus echo: error: ")
    assert main(["--help"]) == 0


def test_installed_entry_point() -> None:
    exe = Path(sys.executable).parent / "tfbus"
    if not exe.exists():
        pytest.skip("the tfbus entry point is not installed in this environment")
    proc = subprocess.run([str(exe), "bag-info", str(TURTLE)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "/tf 2688, /tf_static 1" in proc.stdout
    proc = subprocess.run([str(exe), "echo", "world"], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "tfbus echo: error: Missing argument 'TARGET'."
