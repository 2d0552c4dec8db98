"""``tfbus demo laser``: the laser demo (tfbus.demos.laser) from the command line.

The demo's own figures are tested in tests/demos/test_demo_laser.py under a ManualClock; here
the command: its options reach ``run_laser_demo``, it ends with the demo's summary line,
bad options are one-line errors, and an installation without the module says so.
"""

from __future__ import annotations

import re
import sys

import pytest

pytest.importorskip("click")

from click.testing import CliRunner

from tfbus.cli import cli

SUMMARY = re.compile(r"^(\d+) scans projected, \d+ dropped; wall error mean/max mm: "
                     r"stamp [\d.]+/[\d.]+  laser_geometry [\d.]+/[\d.]+  "
                     r"per_beam [\d.]+/[\d.]+$")


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_demo_laser_runs_for_its_duration_and_prints_the_summary(backend: str) -> None:
    pytest.importorskip("tfbus.demos.laser", reason="tfbus.demos.laser not present")
    if backend == "trio":
        pytest.importorskip("trio")
    # --duration given to the group applies to the role, as for listener/broadcaster
    code, out, err = run("demo", "--duration", "0.4", "laser", "--beams", "90",
                         "--scan-rate", "20", "--odom-rate", "100", "--backend", backend)
    assert code == 0, err
    match = SUMMARY.match(out.strip().splitlines()[-1])
    assert match, out
    assert int(match.group(1)) <= 0.4 * 20 + 1  # no more sweeps than the duration holds


@pytest.mark.parametrize(("args", "needle"), [
    (["--duration", "0"], "--duration must be above 0"),
    (["--beams", "1"], "--beams"),
    (["--scan-rate", "0"], "--scan-rate"),
    (["--odom-rate", "-5"], "--odom-rate"),
])
def test_demo_laser_bad_options_are_one_line(args: list[str], needle: str) -> None:
    code, _, err = run("demo", "laser", *args)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tfbus demo laser: error: "), err
    assert needle in lines[0]


def test_demo_laser_without_the_module_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "tfbus.demos.laser", None)  # import fails by name
    code, out, err = run("demo", "laser", "--duration", "1")
    assert code == 1 and out == ""
    assert err == ("tfbus demo laser: error: the laser demo (tfbus.demos.laser) is not "
                   "part of this installation\n")


def test_demo_laser_help_has_examples() -> None:
    code, out, _ = run("demo", "laser", "--help")
    assert code == 0 and "Examples:" in out and "tfbus demo laser" in out
    code, out, _ = run("demo", "--help")
    assert "tfbus demo laser" in out
