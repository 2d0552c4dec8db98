"""``tfbus echo`` (tf2_echo / tf_echo) on a bag or a live bus, its time arguments, and
tf2_echo's failure text with hostile ids and on two trees."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    RAW_CONTROL,
    TURTLE,
    assert_usage_error,
    numbers,
    run,
)

from tfbus import Time
from tfbus.bag import load_buffer, read_messages
from tfbus.cli import parse_time


def test_echo_at_time_matches_buffer() -> None:
    t = "1396293900.5"
    code, out, _ = run("echo", "world", "carrot", "--bag", str(TURTLE), "--time", t,
                       "--matrix", "-p", "6")
    assert code == 0
    expect = load_buffer(TURTLE).lookup_transform("world", "carrot", parse_time(t))
    lines = out.splitlines()
    assert lines[0] == "At time 1396293900.500000000"
    tr = numbers(lines[1])
    assert tr == pytest.approx(list(expect.transform.translation), abs=1e-6)
    q = numbers(lines[2])
    assert q == pytest.approx(list(expect.transform.rotation), abs=1e-6)
    x, y, z, w = expect.transform.rotation
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    assert numbers(lines[3])[2] == pytest.approx(yaw, abs=1e-6)
    assert numbers(lines[4])[2] == pytest.approx(math.degrees(yaw), abs=1e-5)
    assert lines[5] == "- Matrix:"
    row0 = numbers(lines[6])
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
    """``tfbus echo base_link base_laser`` with no --bag/--bus listens to
    the bus the publishers publish on by default, as tf2_echo listens to the running
    graph (no usage error). The live session is replaced by a Ctrl-C (exit 130)."""
    import importlib

    import tfbus.cli._bus_spec as sources

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
    """``tf2_echo source target [rate]``: RATE as the third argument is
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
    """tf2's validateFrameId message (as the conformance corpus records it
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


def test_echo_failure_path_is_literal(hostile_bag: Path) -> None:
    """The echo failure text keeps bracketed names and escapes
    control characters, including in the list of frames."""
    code, out, _ = run("echo", "[bold red]x[/]", "\x1b[2J", "--bag", str(hostile_bag),
                       "--time", "1")
    assert code == 1
    assert not RAW_CONTROL.search(out)
    assert "Failure at 1.000000000\nException thrown:" in out
    assert "[bold red]x[/]" in out.split("The current list of frames is:")[0]
    assert "Frame \\x1b[2J exists with parent world." in out


def test_echo_on_two_trees_prints_tf2_echo_failure(two_trees_bag: Path) -> None:
    """No KeyError; tf_echo's failure text with the frame names."""
    code, out, err = run("echo", "b", "d", "--bag", str(two_trees_bag))
    assert code == 1 and "Traceback" not in err
    assert out.startswith("Failure at 0.000000000\nException thrown:Could not find a "
                          "connection between 'b' and 'd' because they are not part of the "
                          "same tree.Tf has two or more unconnected trees.\n"
                          "The current list of frames is:\n")
    assert "Frame b exists with parent a." in out and "Frame d exists with parent c." in out
    assert out.endswith(".\n\n")  # tf_echo: allFramesAsString() << std::endl
