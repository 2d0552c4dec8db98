"""Real tf2 programs (installed by Debian's ``tf2-tools``; see
``tests/compat/programs/README.md``) run on ``tfbus.compat`` with only their import lines
changed (the ``.patch`` files there, applied at run time to a copy of the installed
program), next to the same program unmodified on Debian's ROS 1 tf2, on one roscore
(127.0.0.1, a free port) fed by Debian's ``static_transform_publisher`` and a
``rostopic pub`` of ``/tf`` at 20 Hz. Their outputs are compared number for number, and
each must end cleanly on SIGINT."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from peer_install import peer_unavailable
from ros1_harness import Master, Proc, module_master_fixture, ros1_fixture  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]
PROGRAMS = ROOT / "tests" / "compat" / "programs"
INSTALLED = Path("/usr/lib/tf2_tools")


@pytest.fixture(name="master")
def master_fixture(module_master: Master) -> Master:
    """The module's one roscore: each test starts and ends its own nodes on it."""
    return module_master


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
        pytest.skip("tf2-tools is not installed (scripts/install/install_ros1.sh installs it)")
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
    # side by side under their own node names (a ROS remapping): both call
    # rospy.init_node("echo"), and the master shuts down the first of two same-named nodes
    debian = master.run("/usr/bin/python3", str(INSTALLED / "echo.py"), *args,
                        "__name:=echo_debian")
    ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(program), *args, "__name:=echo_tfbus"],
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
    # both listeners record each publisher's caller id as the authority
    assert all(b.startswith(("/static_transform_publisher", "/rostopic")) for _, _, b in want)
    assert sorted(got) == sorted(want)
    assert (tmp_path / "tfbus" / "frames.pdf").stat().st_size > 0


# -- public rospy programs copied into tests/compat/programs (see its README) ----------

RECORDER = ROOT / "peers" / "ros1" / "ros1_tf_recorder.py"


def _upstream(name: str, into: Path) -> Path:
    """The upstream program, unmodified: the copy with its import diff undone."""
    into.mkdir(parents=True, exist_ok=True)
    shutil.copy(PROGRAMS / f"{name}.py", into / f"{name}.py")
    r = subprocess.run(["patch", "-R", "-s", "--no-backup-if-mismatch", str(into / f"{name}.py"),
                        str(PROGRAMS / f"{name}.imports.diff")],
                       capture_output=True, text=True, timeout=30, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    return into / f"{name}.py"


def _side_by_side(master: Master, name: str, tmp_path: Path,
                  count: int) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The upstream rospy program on Debian's python3 + tf2_ros and the copy on tfbus,
    both on ``master`` under their own node names; a rospy subscriber of /tf records
    ``count`` transforms of each (by caller id). Both must end on SIGINT with status 0
    and no traceback. Returns (Debian's, ours)."""
    recorder = master.run("/usr/bin/python3", str(RECORDER))
    recorder.wait_for(r"^READY$", timeout=60.0)
    debian = Proc(["/usr/bin/python3", str(_upstream(name, tmp_path / "debian")),
                   f"__name:={name}_debian"], master.env, cwd=tmp_path)
    ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(PROGRAMS / f"{name}.py"),
                 f"__name:={name}_tfbus"], _tfbus_env(master), cwd=tmp_path)
    got: dict[str, list[dict[str, Any]]] = {"debian": [], "tfbus": []}
    deadline = time.monotonic() + 60.0
    try:
        while min(len(v) for v in got.values()) < count:
            assert time.monotonic() < deadline, {k: len(v) for k, v in got.items()}
            line = recorder.wait_for(r"^\{.*\}$", timeout=max(0.1, deadline - time.monotonic()))
            message = json.loads(line.group(0))
            who = message["callerid"]
            for side in got:  # tfbus's ROS 1 node is the rospy node's name plus "_tf2"
                if who.startswith(f"/{name}_{side}"):
                    got[side].append(message)
        for proc in (ours, debian):
            start = time.monotonic()
            proc.proc.send_signal(signal.SIGINT)
            code = proc.proc.wait(timeout=20.0)
            print(f"{name} ({proc.args[0]}), SIGINT to exit: {time.monotonic() - start:.3f} s")
            lines = proc.seen + proc.drain()
            assert code == 0, lines[-20:]
            assert not [line for line in lines if "Traceback" in line], lines[-20:]
            assert time.monotonic() - start < 10.0  # a bound for a loaded machine (a hang)
    finally:
        ours.stop()
        debian.stop()
        recorder.stop()
    return got["debian"][:count], got["tfbus"][:count]


def _period(sent: list[dict[str, Any]]) -> float:
    ns = [s * 1_000_000_000 + n for s, n in (t["stamp"] for t in sent)]
    assert ns == sorted(ns) and len(set(ns)) == len(ns)
    return (ns[-1] - ns[1]) / (len(ns) - 2) / 1e9


def test_fixed_tf2_broadcaster_matches_debian(master: Master, tmp_path: Path) -> None:
    """turtle_tf2's fixed_tf2_broadcaster (ROS 1's ``TransformBroadcaster()``, no node):
    the same transform at the same rate as the unmodified program on Debian's tf2_ros."""
    debian, ours = _side_by_side(master, "fixed_tf2_broadcaster", tmp_path, 12)
    for sent in (debian, ours):
        assert {(t["parent"], t["child"], tuple(t["t"]), tuple(t["r"])) for t in sent} == {
            ("turtle1", "carrot1", (0.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0))}
        assert 0.05 < _period(sent) < 0.5  # rospy.Rate(10.0) on a loaded machine


def test_dynamic_tf2_broadcaster_matches_debian(master: Master, tmp_path: Path) -> None:
    """turtle_tf2's dynamic_tf2_broadcaster: carrot1 on a 10 m circle, angle π·t of the
    time t read just before the stamp; the same for the unmodified program on Debian."""
    debian, ours = _side_by_side(master, "dynamic_tf2_broadcaster", tmp_path, 12)
    for sent in (debian, ours):
        assert {(t["parent"], t["child"]) for t in sent} == {("turtle1", "carrot1")}
        for t in sent:
            x, y, z = t["t"]
            assert x * x + y * y == pytest.approx(100.0, abs=1e-9)
            assert (z, t["r"]) == (0.0, [0.0, 0.0, 0.0, 1.0])
            stamp = t["stamp"][0] + t["stamp"][1] * 1e-9
            # sin(x)/cos(x) of x = π·t: the angle atan2(x, y) is π·t (mod 2π), read a
            # moment before the stamp (0.2 rad: 64 ms, a bound for a loaded machine)
            lag = (math.pi * stamp - math.atan2(x, y)) % (2 * math.pi)
            assert lag < 0.2, (t, lag)
        assert 0.05 < _period(sent) < 0.5


TURTLE_PEER = ROOT / "peers" / "ros1" / "ros1_turtle_peer.py"
GENSRV = Path("/usr/lib/genpy/gensrv_py.py")
GENMSG = Path("/usr/lib/genpy/genmsg_py.py")


def _turtlesim_srv(into: Path) -> Path:
    """``turtlesim.srv`` (Spawn) and ``turtlesim.msg`` (Pose) generated by Debian's genpy
    from turtlesim's own ``Spawn.srv`` and ``Pose.msg`` (``tests/compat/programs/turtlesim/``):
    the directory to put on PYTHONPATH."""
    for tool, kind, source in ((GENSRV, "srv", "Spawn.srv"), (GENMSG, "msg", "Pose.msg")):
        out = into / "turtlesim" / kind
        for extra in ([str(PROGRAMS / "turtlesim" / source)], ["--initpy"]):
            r = subprocess.run(["/usr/bin/python3", str(tool), "-p", "turtlesim", "-o",
                                str(out), *extra],
                               capture_output=True, text=True, timeout=60, check=False)
            assert r.returncode == 0, r.stdout + r.stderr
    (into / "turtlesim" / "__init__.py").write_text("")
    return into


def _pose(parent: str, child: str, x: float, y: float, yaw: float) -> str:
    return (f"{{header: {{stamp: now, frame_id: {parent}}}, child_frame_id: {child}, "
            f"transform: {{translation: {{x: {x!r}, y: {y!r}, z: 0.0}}, rotation: "
            f"{{x: 0.0, y: 0.0, z: {math.sin(yaw / 2)!r}, w: {math.cos(yaw / 2)!r}}}}}}}")


def test_turtle_tf2_listener_matches_debian(master: Master, tmp_path: Path) -> None:
    """turtle_tf2's turtle_tf2_listener (ROS 1's ``TransformListener(buffer)`` and
    ``lookup_transform`` of the latest turtle2 ← turtle1 in a loop, its exceptions caught):
    it spawns turtle2 through turtlesim's /spawn and steers it with the Twist its formula
    gives; on tfbus the Twists equal the unmodified program's on Debian's tf2_ros."""
    if not GENSRV.exists():
        peer_unavailable("ros1", "Debian's genpy (gensrv_py.py) is not installed")
    generated = _turtlesim_srv(tmp_path / "gen")
    env = dict(master.env, PYTHONPATH=str(generated))
    peer = Proc(["/usr/bin/python3", str(TURTLE_PEER)], env, cwd=tmp_path)
    poses = master.run("rostopic", "pub", "-s", "-r", "20", "/tf", "tf2_msgs/TFMessage", "--",
                       "transforms: [" + _pose("world", "turtle1", 5.5, 5.0, 0.4) + ", "
                       + _pose("world", "turtle2", 4.0, 2.0, 1.1) + "]")
    name = "turtle_tf2_listener"
    debian = ours = None
    try:
        peer.wait_for(r"^READY$", timeout=60.0)
        debian = Proc(["/usr/bin/python3", str(_upstream(name, tmp_path / "debian")),
                       f"__name:={name}_debian"], env, cwd=tmp_path)
        ours_env = _tfbus_env(master)
        ours_env["PYTHONPATH"] += os.pathsep + str(generated)
        ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(PROGRAMS / f"{name}.py"),
                     f"__name:={name}_tfbus"], ours_env, cwd=tmp_path)
        twists: dict[str, list[dict[str, Any]]] = {"debian": [], "tfbus": []}
        deadline = time.monotonic() + 60.0
        while min(len(v) for v in twists.values()) < 5:
            assert time.monotonic() < deadline, ({k: len(v) for k, v in twists.items()},
                                                 ours.seen[-10:], debian.seen[-10:])
            m = peer.wait_for(r"^\{.*\}$", timeout=max(0.1, deadline - time.monotonic()))
            twist = json.loads(m.group(0))
            for side in twists:
                if twist["callerid"] == f"/{name}_{side}":
                    twists[side].append(twist)
        # turtle1 seen from turtle2: (1.5, 3.0) turned by -1.1 rad
        c, s = math.cos(1.1), math.sin(1.1)
        x, y = c * 1.5 + s * 3.0, -s * 1.5 + c * 3.0
        for side, got in twists.items():
            for twist in got:
                assert twist["linear"] == [pytest.approx(0.5 * math.hypot(x, y), abs=1e-12),
                                           0.0, 0.0], side
                assert twist["angular"] == [0.0, 0.0,
                                            pytest.approx(4 * math.atan2(y, x), abs=1e-12)], side
        for proc in (ours, debian):
            start = time.monotonic()
            proc.proc.send_signal(signal.SIGINT)
            code = proc.proc.wait(timeout=20.0)
            print(f"{name} ({proc.args[0]}), SIGINT to exit: {time.monotonic() - start:.3f} s")
            lines = proc.seen + proc.drain()
            assert code == 0, lines[-20:]
            assert not [line for line in lines if "Traceback" in line], lines[-20:]
            assert time.monotonic() - start < 10.0  # a bound (a hang)
    finally:
        for proc in (ours, debian):
            if proc is not None:
                proc.stop()
        poses.stop()
        peer.stop()


def test_turtle_tf2_broadcaster_matches_debian(master: Master, tmp_path: Path) -> None:
    """turtle_tf2's turtle_tf2_broadcaster (a new ``TransformBroadcaster()`` for each
    ``turtlesim/Pose`` received, its quaternion from ``tf.transformations``): world → turtle1
    at the pose turtlesim publishes; the same transforms as the unmodified program's on
    Debian's tf2_ros."""
    if not GENMSG.exists():
        peer_unavailable("ros1", "Debian's genpy (genmsg_py.py) is not installed")
    generated = _turtlesim_srv(tmp_path / "gen")
    env = dict(master.env, PYTHONPATH=str(generated))
    peer = Proc(["/usr/bin/python3", str(TURTLE_PEER), "turtle1", "5.5", "4.25", "0.75"], env,
                cwd=tmp_path)
    recorder = master.run("/usr/bin/python3", str(RECORDER))
    name = "turtle_tf2_broadcaster"
    debian = ours = None
    try:
        peer.wait_for(r"^READY$", timeout=60.0)
        recorder.wait_for(r"^READY$", timeout=60.0)
        debian = Proc(["/usr/bin/python3", str(_upstream(name, tmp_path / "debian")),
                       f"__name:={name}_debian", "_turtle:=turtle1"], env, cwd=tmp_path)
        ours_env = _tfbus_env(master)
        ours_env["PYTHONPATH"] += os.pathsep + str(generated)
        ours = Proc([sys.executable, "-c", RUN_ON_TFBUS, str(PROGRAMS / f"{name}.py"),
                     f"__name:={name}_tfbus", "_turtle:=turtle1"], ours_env, cwd=tmp_path)
        sent: dict[str, list[dict[str, Any]]] = {"debian": [], "tfbus": []}
        deadline = time.monotonic() + 60.0
        while min(len(v) for v in sent.values()) < 10:
            assert time.monotonic() < deadline, ({k: len(v) for k, v in sent.items()},
                                                 ours.seen[-10:], debian.seen[-10:])
            m = recorder.wait_for(r"^\{.*\}$", timeout=max(0.1, deadline - time.monotonic()))
            t = json.loads(m.group(0))
            for side in sent:
                if t["callerid"].startswith(f"/{name}_{side}"):
                    sent[side].append(t)
        # the pose's float32 values; yaw θ about z: (0, 0, sin θ/2, cos θ/2)
        theta = float(np.float32(0.75))
        want = {("world", "turtle1", (5.5, 4.25, 0.0),
                 (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)))}
        for side, got in sent.items():
            values = {(t["parent"], t["child"], tuple(t["t"]), tuple(t["r"])) for t in got}
            assert values == want, side
            assert 0.02 < _period(got) < 0.25, side  # one per pose, turtlesim's 20 Hz
        for proc in (ours, debian):
            start = time.monotonic()
            proc.proc.send_signal(signal.SIGINT)
            code = proc.proc.wait(timeout=20.0)
            print(f"{name} ({proc.args[0]}), SIGINT to exit: {time.monotonic() - start:.3f} s")
            lines = proc.seen + proc.drain()
            assert code == 0, lines[-20:]
            assert not [line for line in lines if "Traceback" in line], lines[-20:]
            assert time.monotonic() - start < 10.0  # a bound (a hang)
    finally:
        for proc in (ours, debian):
            if proc is not None:
                proc.stop()
        recorder.stop()
        peer.stop()
