"""``tfbus monitor`` (tf_monitor) on a bag: the tables, a chain's net delay, two trees,
names never cut off, sim-time delays."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    T0,
    TURTLE,
    assert_one_line_error,
    assert_usage_error,
    numbers,
    run,
    tf,
)

from tfbus import Time
from tfbus.bag import BagMessage, write_bag
from tfbus.messages import TFMessage


def test_monitor() -> None:
    code, out, _ = run("monitor", "--bag", str(TURTLE))
    assert code == 0
    assert "RESULTS: for all Frames" in out
    rows = {line.split()[0]: line for line in out.splitlines() if "│" in line}
    assert "/turtle1_tf_broadcaster" in rows["turtle1"]
    assert numbers(rows["turtle1"])[0] == pytest.approx(62.5, abs=0.05)
    assert "static" in rows["carrot"]
    assert "/turtle2_tf_broadcaster" in rows
    code, out, _ = run("monitor", "world", "carrot", "--bag", str(TURTLE))
    assert code == 0 and "turtle2 " not in out.split("All Broadcasters")[0]
    code, _, err = run("monitor", "world", "--bag", str(TURTLE))
    assert_usage_error(code, err, "two")


def test_monitor_chain_and_net_delay_lines(tmp_path: Path) -> None:
    """tf_monitor's ``Chain is:`` and ``Net delay`` lines, exactly.

    Hand-computed: world -> base at 10 Hz (stamps k*0.1 s, received 0.01 s later) and
    base -> cam static. Net delay at each /tf message = 0.01 s."""
    path = tmp_path / "chain.bag"
    msgs = [BagMessage(Time.from_ns(T0), "/tf_static",
                       TFMessage([tf("base", "cam", 0)]), "")]
    msgs += [BagMessage(Time.from_ns(T0 + k * 10**8 + 10**7), "/tf",
                        TFMessage([tf("world", "base", T0 + k * 10**8)]), "") for k in range(5)]
    write_bag(path, msgs)
    code, out, _ = run("monitor", "world", "cam", "--bag", str(path))
    assert code == 0
    lines = out.splitlines()
    assert lines[:3] == ["RESULTS: for world to cam", "Chain is: world -> base -> cam",
                         "Net delay     avg = 0.01: max = 0.01"]
    code, _, err = run("monitor", "b", "d", "--bag", str(tmp_path / "chain.bag"))
    assert code == 2 and "'b'" in err


def test_monitor_two_trees_is_one_line(two_trees_bag: Path) -> None:
    """Frames in different trees: a one-line error, not a crash."""
    code, _, err = run("monitor", "b", "d", "--bag", str(two_trees_bag))
    assert_one_line_error(code, err)
    assert "not connected" in err


def test_names_never_cut_off_in_80_columns(hostile_bag: Path) -> None:
    """In an 80-column terminal, long names wrap inside their cell."""
    from io import StringIO

    from rich.console import Console

    from tfbus.cli._bag_source import BagSource
    from tfbus.cli.monitor import print_monitor

    name = "a_very_long_frame_name_" * 6
    path = hostile_bag.parent / "long.bag"
    path.unlink(missing_ok=True)
    write_bag(path, [BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                                TFMessage([tf("world", name, T0 + k * 10**8)]), "")
                     for k in range(3)])
    buf = StringIO()
    out = Console(file=buf, width=80, markup=False, highlight=False, emoji=False)
    print_monitor(out, BagSource(path).summary(), ())
    lines = buf.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 80
    first_cells = "".join(line.split("│")[0].strip() for line in lines if "│" in line)
    assert name in first_cells


def test_sim_time_delays_are_relative_to_the_bag_clock(tmp_path: Path) -> None:
    """Stamps in simulated time (10 s) recorded at 1.7e9 s: delays
    against the newest stamp, with a note, not 1.7e9 s. Hand-computed: every message
    stamps the newest time, so every delay is 0."""
    path = tmp_path / "sim.bag"
    write_bag(path, [BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                                TFMessage([tf("map", "odom", 10 * 10**9 + k * 10**8)]), "")
                     for k in range(4)])
    code, out, _ = run("monitor", "--bag", str(path))
    assert code == 0
    assert "note: header stamps are simulated time" in out
    row = next(line for line in out.splitlines() if line.lstrip().startswith("odom"))
    assert row.split("│")[4].strip() == "0.000000"
    assert "1700000000" not in row
