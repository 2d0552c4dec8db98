"""Tests for ``tfbus robot-state-publisher`` and ``tfbus joint-states``
(tfbus/cli/robot_state_publisher.py, tfbus/cli/joint_states.py).

In-process with click's CliRunner, and as processes over Zenoh on 127.0.0.1 (explicit
endpoints on a free port): joint-states -> robot-state-publisher -> a Buffer in this
test, then SIGTERM / SIGINT and the summary lines. Cross-process waits are bounded.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import anyio
import pytest

pytest.importorskip("click")
pytest.importorskip("urdf_parser_py")

from click.testing import CliRunner

from tfbus.buffer import Buffer
from tfbus.cli import cli, main
from tfbus.listener import TransformListener
from tfbus.time import Time

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "demos" / "robot.urdf"
PR2 = ROOT / "tests" / "data" / "urdf" / "rsp_pr2.urdf"
RSP_SUMMARY = re.compile(r"^\[ INFO\] summary: (\d+) joint states received, (\d+) published "
                         r"\((\d+) transforms\), (\d+) rate-limited, 0 invalid, "
                         r"0 positions refused$")
JS_SUMMARY = re.compile(r"^\[ INFO\] summary: (\d+) joint states published$")


def test_commands_run_for_a_duration_and_print_a_summary() -> None:
    runner = CliRunner()
    out = runner.invoke(cli, ["robot-state-publisher", str(PR2), "--local", "--duration", "0",
                              "--frame-prefix", "pr2/"])
    assert out.exit_code == 0, out.output
    assert RSP_SUMMARY.match(out.stdout.strip().splitlines()[-1])
    assert "pr2: 82 joints (40 moving), root base_footprint, on an in-process bus" in out.stderr
    out = runner.invoke(cli, ["joint-states", str(ROBOT), "--local", "--duration", "0",
                              "--rate", "5"])
    assert out.exit_code == 0, out.output
    assert JS_SUMMARY.match(out.stdout.strip().splitlines()[-1])
    assert "tutorial_robot: 2 joints at 5 Hz" in out.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["/no/such.urdf"], "cannot read the URDF file '/no/such.urdf'"),
    ([str(ROBOT), "--bus", "carrier-pigeon"], "unsupported bus 'carrier-pigeon'"),
    ([str(ROBOT), "--bus", "zenoh", "--local"], "give --bus SPEC or --local, not both"),
    ([str(ROBOT), "--publish-frequency", "0"], "--publish-frequency"),
])
@pytest.mark.parametrize("command", ["robot-state-publisher", "joint-states"])
def test_bad_arguments_are_one_line_errors(command: str, args: list[str], message: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    if command == "joint-states" and args[-2:] == ["--publish-frequency", "0"]:
        args = [str(ROBOT), "--rate", "0"]
        message = "--rate"
    assert main([command, *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"tfbus {command}: error: "), err
    assert message in err


def test_a_hostile_urdf_cannot_reach_the_terminal(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.urdf"
    # C1 CSI (U+009B) is valid XML 1.0 and a terminal escape; XML forbids C0 controls
    bad.write_text('<robot name="r"><link name="a\u009b31m\u202e"/><link name="b"/>'
                   '</robot>', encoding="utf-8")
    assert main(["robot-state-publisher", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "\u009b" not in err and "\u202e" not in err
    assert err.startswith("tfbus robot-state-publisher: error: ")
    assert "two root links" in err and "\\x9b31m\\u202e" in err
    assert main(["joint-states", "--help"]) == 0
    assert "sinusoidally" in capsys.readouterr().out


# --------------------------------------------------------------------------- processes


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Child:
    """``python -m tfbus.cli ARGS``; output collected by threads."""

    def __init__(self, *args: str) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=env, cwd=ROOT)
        self.out: list[str] = []
        self.err: list[str] = []
        self.started = threading.Event()
        self._threads = [threading.Thread(target=self._read, args=(s, lines), daemon=True)
                         for s, lines in ((self.proc.stdout, self.out),
                                          (self.proc.stderr, self.err))]
        for t in self._threads:
            t.start()

    def _read(self, stream: object, lines: list[str]) -> None:
        for line in stream:  # type: ignore[attr-defined]
            lines.append(line.rstrip("\n"))
            if line.startswith("[ INFO]") and lines is self.err:
                self.started.set()

    def finish(self, sig: int) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        code = self.proc.wait(timeout=20)
        for t in self._threads:
            t.join(timeout=5)
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)


def test_joint_states_drive_the_publisher_across_processes() -> None:
    pytest.importorskip("zenoh")
    from tfbus.transports.spec import open_bus

    port = free_port()
    listen, connect = (f"zenoh?{k}=tcp/127.0.0.1:{port}" for k in ("listen", "connect"))
    children: list[Child] = []
    try:
        rsp = Child("robot-state-publisher", str(ROBOT), "--bus", listen,
                    "--publish-frequency", "50")
        children.append(rsp)
        assert rsp.started.wait(30), rsp.err
        js = Child("joint-states", str(ROBOT), "--bus", connect, "--rate", "20")
        children.append(js)

        async def watch() -> tuple[Time, float]:
            buffer = Buffer(cache_time=10.0)
            async with open_bus(connect, default_name="test") as bus, \
                    TransformListener(buffer, bus):
                with anyio.fail_after(30):
                    laser = await buffer.wait_for_transform("base_link", "base_laser", Time(0))
                    first = await buffer.wait_for_transform("base_link", "left_wheel", Time(0))
                    # the wheel turns: wait for a sample after the first one
                    later = await buffer.wait_for_transform(
                        "base_link", "left_wheel", Time.from_ns(first.header.stamp.ns + 1))
            assert laser.transform.translation == (0.1, 0.0, 0.2)
            # an interpolated lookup (tf2's lerp between two equal samples may round)
            assert later.transform.translation == pytest.approx((0.0, 0.2, 0.0), abs=1e-15)
            return later.header.stamp, later.transform.rotation.y

        stamp, qy = anyio.run(watch)
        assert stamp > Time(0) and -1.0 <= qy <= 1.0
        assert js.finish(signal.SIGTERM) == 0
        assert rsp.finish(signal.SIGINT) == 0
        published = JS_SUMMARY.match(js.out[-1])
        summary = RSP_SUMMARY.match(rsp.out[-1])
        assert published and summary, (js.out, rsp.out, rsp.err)
        assert int(published.group(1)) >= 2
        received, sent = int(summary.group(1)), int(summary.group(2))
        assert 2 <= sent <= received <= int(published.group(1))
        assert int(summary.group(3)) == 2 * sent
    finally:
        for child in children:
            child.kill()


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e309"])
def test_a_limit_that_is_not_finite_is_one_line(
    tmp_path: Path, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """joint-states and robot-state-publisher took a URDF whose
    <limit> is nan / inf and published NaN / inf positions; now one line naming the
    joint and the attribute, exit status 2, as urdfdom refuses it."""
    bad = tmp_path / "bad.urdf"
    bad.write_text(f"""<robot name="r"><link name="a"/><link name="b"/>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
        <limit lower="{value}" upper="1" effort="1" velocity="1"/></joint></robot>""")
    for command in ("joint-states", "robot-state-publisher"):
        assert main([command, str(bad), "--local", "--duration", "0"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"tfbus {command}: error: "), err
        shown = "inf" if value == "1e309" else value  # read as a double: overflows to inf
        assert f"joint 'j': <limit lower=\"{shown}\"> is not a finite number" in err, err
