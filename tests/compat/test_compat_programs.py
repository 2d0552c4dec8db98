"""Real tf2 programs (installed by Debian's ``tf2-tools``; see
``tests/compat/programs/README.md``) run on ``tfbus.compat`` with only their import lines
changed (the ``.patch`` files there, applied at run time to a copy of the installed
program), next to the same program unmodified on Debian's ROS 1 tf2, on one roscore
(127.0.0.1, a free port) fed by Debian's ``static_transform_publisher`` and a
``rostopic pub`` of ``/tf`` at 20 Hz. Their outputs are compared number for number, and
each must end cleanly on SIGINT."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros1_harness import Master, Proc, master_fixture, ros1_fixture  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]
PROGRAMS = ROOT / "tests" / "compat" / "programs"
INSTALLED = Path("/usr/lib/tf2_tools")

# the project's Python, Debian's ROS 1 packages appended after its own
RUN_ON_TFBUS = (
    "import runpy, sys; sys.path.append('/usr/lib/python3/dist-packages'); "
    "sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')"
)

TF_YAML = (
    "transforms: [{header: {stamp: now, frame_id: laser}, child_frame_id: tool, "
    "transform: {translation: {x: 0.5, y: -0.25, z: 0.125}, "
    "rotation: {x: 0.0, y: 0.7071067811865476, z: 0.0, w: 0.7071067811865476}}}]"
)


def _patched(name: str, into: Path) -> Path:
    """A copy of the installed program with its import patch applied."""
    into.mkdir(parents=True, exist_ok=True)
    shutil.copy(INSTALLED / name, into / name)
    r = subprocess.run(["patch", "-s", str(into / name), str(PROGRAMS / f"{name}.patch")],
                       capture_output=True, text=True, timeout=30, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    return into / name


def _tfbus_env(master: Master) -> dict[str, str]:
    env = dict(master.env)
    env["PYTHONPATH"] = str(ROOT)
    return env


@pytest.fixture(name="feed")
def feed_fixture(master: Master) -> object:
    """Debian's static_transform_publisher (map → laser) and rostopic pub (/tf,
    laser → tool, stamped now, 20 Hz)."""
    if not (INSTALLED / "echo.py").exists():
        pytest.skip("tf2-tools is not installed (scripts/install_ros1.sh installs it)")
    static = master.run("rosrun", "tf2_ros", "static_transform_publisher", "1", "2", "3",
                        "0", "0", "0.3826834323650898", "0.9238795325112867", "map", "laser")
    dynamic = master.run("rostopic", "pub", "-s", "-r", "20", "/tf", "tf2_msgs/TFMessage",
                         "--", TF_YAML)
    yield
    dynamic.stop()
    static.stop()


def _echo_block(proc: Proc) -> list[float]:
    """The numbers of echo.py's first full answer: translation, quaternion, RPY (rad, deg)."""
    numbers = []
    for pattern in (r"- Translation: \[(.*)\]", r"- Rotation: in Quaternion \[(.*)\]",
                    r"in RPY \(radian\) \[(.*)\]", r"in RPY \(degree\) \[(.*)\]"):
        m = proc.wait_for(pattern, timeout=60.0)
        numbers += [float(v) for v in m.group(1).split(",")]
    return numbers


def test_echo_matches_debian(master: Master, feed: object, tmp_path: Path) -> None:
    program = _patched("echo.py", tmp_path / "tfbus")
    args = ["map", "tool", "-r", "5", "-p", "9"]
    debian = master.run("/usr/bin/python3", str(INSTALLED / "echo.py"), *args)
    ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(program), *args],
                _tfbus_env(master), cwd=tmp_path)
    try:
        want, got = _echo_block(debian), _echo_block(ours)
        # map → laser (static, 45° about z) then laser → tool: the same 14 numbers
        assert got == want
        r = 0.7071067811865476  # (0.5, -0.25, 0.125) turned 45° about z, plus (1, 2, 3)
        assert want[:3] == pytest.approx([1.0 + 0.75 * r, 2.0 + 0.25 * r, 3.125], abs=1e-9)
        start = time.monotonic()
        ours.proc.send_signal(signal.SIGINT)
        code = ours.proc.wait(timeout=20.0)
        print(f"echo.py on tfbus, SIGINT to exit: {time.monotonic() - start:.3f} s")
        assert code == 0
        assert time.monotonic() - start < 5.0  # a bound for a loaded machine
        assert not [line for line in ours.drain() if "Traceback" in line]
    finally:
        ours.stop()
        debian.stop()


def _edges(gv: str) -> set[tuple[str, str, str]]:
    """(parent, child, broadcaster) of each edge view_frames wrote."""
    return {(m.group(1), m.group(2), m.group(3)) for m in re.finditer(
        r'"([^"]+)" -> "([^"]+)"\[label=" Broadcaster: ([^\\]+)\\n', gv)}


def test_view_frames_matches_debian(master: Master, feed: object, tmp_path: Path) -> None:
    program = _patched("view_frames.py", tmp_path / "tfbus")
    (tmp_path / "debian").mkdir()
    # side by side, each in its own directory, under its own node name (a ROS remapping)
    debian = Proc(["/usr/bin/python3", str(INSTALLED / "view_frames.py"),
                   "__name:=view_frames_debian"], master.env, cwd=tmp_path / "debian")
    ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(program), "__name:=view_frames_tfbus"],
                _tfbus_env(master), cwd=tmp_path / "tfbus")
    assert debian.proc.wait(60) == 0, debian.drain()
    assert ours.proc.wait(60) == 0, ours.drain()
    want = _edges((tmp_path / "debian" / "frames.gv").read_text())
    got = _edges((tmp_path / "tfbus" / "frames.gv").read_text())
    assert {(p, c) for p, c, _ in want} == {("map", "laser"), ("laser", "tool")}
    assert {(p, c) for p, c, _ in got} == {(p, c) for p, c, _ in want}
    # the one difference (docs/moving-from-tf2-ros.md): Debian's listener records each
    # publisher's caller id as the authority; tfbus's ROS 1 transport does not pass it on
    assert all(b.startswith(("/static_transform_publisher", "/rostopic")) for _, _, b in want)
    assert {b for _, _, b in got} == {"default_authority"}
    assert (tmp_path / "tfbus" / "frames.pdf").stat().st_size > 0
