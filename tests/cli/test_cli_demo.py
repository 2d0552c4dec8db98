"""``tfbus demo``: options parsed once by click and forwarded to the roles, the demo
script, the role help; and ``tfbus demo laser`` (tfbus.demos.laser): its options reach
``run_laser_demo``, it ends with the demo's summary line, bad options are one-line errors,
and an installation without the module says so. The demos' own figures are tested in
tests/demos/ under a ManualClock."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rosbags")

from cli_support import (
    assert_usage_error,
    run,
)


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
    """The options reach the runners as values (no argv rebuilt for a second
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
    code, _, _ = run("demo", "listener", "--use-sim-time")
    assert code == 0
    assert calls == [
        ("listener", "zenoh?port=9000", {"duration": 2.0, "rate": 100.0, "listen_rate": 1.0,
                                         "backend": "asyncio", "use_sim_time": False}),
        ("broadcaster", "zenoh", {"duration": 3.0, "rate": 50.0, "listen_rate": 1.0,
                                  "backend": "asyncio", "use_sim_time": False}),
        ("listener", "zenoh", {"duration": None, "rate": 100.0, "listen_rate": 1.0,
                               "backend": "asyncio", "use_sim_time": True}),
    ]
    code, _, err = run("demo", "broadcaster", "--listen-rate", "2")  # not a broadcaster's
    assert code == 2 and "--listen-rate" in err
    if importlib.util.find_spec("zenoh") is not None:
        code, _, err = run("demo", "listener", "--bus", "zenoh?bogus=1")
        assert code == 2 and err.strip() == (
            "tfbus demo listener: error: unknown bus option 'bogus' (known: config, "
            "congestion_control, connect, connect_timeout, express, listen, mode, name, namespace, "
            "port, prefix)"
        )
    assert len(calls) == 3


def test_demo_script_runs_the_click_command(tmp_path: Path) -> None:
    """demos/robot_setup_tf.py stays runnable and parses with the same click command."""
    script = Path(__file__).resolve().parents[2] / "demos" / "robot_setup_tf.py"
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


SUMMARY = re.compile(r"^(\d+) scans projected, \d+ dropped; wall error mean/max mm: "
                     r"stamp [\d.]+/[\d.]+  laser_geometry [\d.]+/[\d.]+  "
                     r"per_beam [\d.]+/[\d.]+$")


@pytest.mark.parametrize("backend", ["asyncio", "trio", "uvloop"])
def test_demo_laser_runs_for_its_duration_and_prints_the_summary(backend: str) -> None:
    pytest.importorskip("tfbus.demos.laser", reason="tfbus.demos.laser not present")
    if backend != "asyncio":
        pytest.importorskip(backend)
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
