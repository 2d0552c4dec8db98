"""Public ROS 2 tf2 programs (ros2/geometry2 ``examples_tf2_py``, ros/geometry_tutorials
``turtle_tf2_py``; copies in ``tests/compat/programs/``, see its README) run on
``tfbus.compat`` with only their import lines changed, under the real rclpy (the ROS 2
venv, ``scripts/install/install_ros2_env.sh``), as ``ros2 run`` runs them (their ``main()``).

Their output is compared numerically with Debian's ``tf2_py`` (tf2's C++ ``BufferCore``,
``peers/debian/debian_tf2_py_side.py``) fed the same stream: what a real rclpy subscriber
(``peers/ros2/tf_peer.py --echo``) received from them, or what they received. There
is no ROS 2 ``tf2_ros`` wheel to run them unmodified. The waiters wait on transforms a
real rclpy publisher (``peers/ros2/gated_tf_feeder.py``) starts sending only after
they logged that they wait. Each program must end on SIGINT with status 0, no traceback.
Fast DDS is kept on 127.0.0.1 (``peers/ros2/fastdds_lo.xml``), on a random domain."""

from __future__ import annotations

import json
import math
import os
import queue
import re
import signal
import subprocess
import sys
import sysconfig
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from dds_domains import new_domain
from peer_install import peer_unavailable, require
from ros1_harness import Proc, ros1_fixture  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]
PROGRAMS = ROOT / "tests" / "compat" / "programs"
PEERS = ROOT / "peers" / "ros2"
ROS_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
DEBIAN_SIDE = ROOT / "peers" / "debian" / "debian_tf2_py_side.py"
WAIT = 60.0  # bound on any one wait, for a loaded machine

# as ``ros2 run`` runs a console script: the module's main()
RUN_MAIN = (
    "import runpy, sys; sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0])['main']()"
)

# examples_tf2_py's static_broadcaster: base_link -> platform -> camera, sonar_0..2
S45 = 0.05 * math.sin(math.radians(45))
C45 = 0.05 * math.cos(math.radians(45))
STATIC_EXAMPLE = {
    ("base_link", "platform"): ([0.0, 0.0, 0.1], [0.0, 0.0, 0.0, 1.0]),
    ("platform", "camera"): ([0.05, 0.0, 0.01], [0.0, 0.0, 0.0, 1.0]),
    ("platform", "sonar_0"): ([S45, C45, 0.0], [0.0, 0.0, -0.4871745124605095,
                                                 -0.8733046400935156]),
    ("platform", "sonar_1"): ([0.05, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]),
    ("platform", "sonar_2"): ([S45, -C45, 0.0], [0.0, 0.0, -0.4871745124605095,
                                                  0.8733046400935156]),
}
# the wheel frame as the example's dynamic_broadcaster computes it from a joint position
WHEEL_POSITION = 0.7
WHEELS = [{"parent": "base_link", "child": "starboard_wheel", "t": [0.0, -0.05, 0.0],
           "r": [0.0, math.sin(WHEEL_POSITION / 2), 0.0, math.cos(WHEEL_POSITION / 2)]}]


@pytest.fixture(scope="module", name="ros_python")
def ros_python_fixture(ros1: None) -> Path:
    """The ROS 2 venv's python (installed when missing); Debian's ROS 1 (its tf2_py, the
    reference) is there too (the ``ros1`` fixture)."""
    if sys.platform != "linux":
        peer_unavailable("ros2-env", "the ROS 2 wheels are manylinux only")
    require("ros2-env", "install_ros2_env.sh", timeout=1200)
    assert ROS_PYTHON.exists()
    if sys.version_info[:2] != (3, 11):
        pytest.skip("the ROS 2 venv is Python 3.11: this environment's packages cannot be shared")
    return ROS_PYTHON


@pytest.fixture(name="ros2")
def ros2_fixture(ros_python: Path) -> Iterator[dict[str, str]]:
    """The environment of this test's rclpy processes: a random domain, loopback only."""
    paths = sysconfig.get_paths()  # the test runner's own packages (anyio, numpy, ...)
    site = os.pathsep.join(dict.fromkeys([paths["purelib"], paths["platlib"]]))
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(new_domain()),
        RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        FASTDDS_DEFAULT_PROFILES_FILE=str(PEERS / "fastdds_lo.xml"),
        PYTHONPATH=os.pathsep.join([str(ROOT), site]),
        PYTHONUNBUFFERED="1",
    )
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.pop("CYCLONEDDS_URI", None)
    yield env


class Procs:
    """The processes a test started (ended at its end, by PID)."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.started: list[Proc] = []

    def program(self, name: str, *args: str) -> Proc:
        """The copy ``tests/compat/programs/NAME.py`` run on tfbus.compat: its main()."""
        return self._start([str(ROS_PYTHON), "-c", RUN_MAIN, str(PROGRAMS / f"{name}.py"),
                            *args])

    def program_interrupted_in_take(self, name: str) -> Proc:
        """The program ``NAME`` as :meth:`program` runs it, sent SIGINT at the first Python
        code rclpy runs inside a ``take_message`` (``peers/ros2/sigint_in_take.py``)."""
        return self._start([str(ROS_PYTHON), str(PEERS / "sigint_in_take.py"),
                            str(PROGRAMS / f"{name}.py")])

    def peer(self, script: str, *args: str) -> Proc:
        p = self._start([str(ROS_PYTHON), str(PEERS / script), *args])
        p.wait_for(r"^READY$", timeout=WAIT)
        return p

    def _start(self, args: list[str]) -> Proc:
        p = Proc(args, self.env, cwd=ROOT)
        self.started.append(p)
        return p

    def stop_all(self) -> None:
        for p in reversed(self.started):
            p.stop()


@pytest.fixture(name="procs")
def procs_fixture(ros2: dict[str, str]) -> Iterator[Procs]:
    procs = Procs(ros2)
    try:
        yield procs
    finally:
        procs.stop_all()


def _ends_on_sigint(p: Proc) -> float:
    """SIGINT to ``p``: it must exit with status 0 and print no traceback. The seconds it
    took are returned."""
    start = time.monotonic()
    p.proc.send_signal(signal.SIGINT)
    code = p.proc.wait(timeout=30.0)
    took = time.monotonic() - start
    rest = p.drain()
    tail = "\n".join(rest[-30:])  # the program's last lines, whole (a traceback's end)
    assert code == 0, tail
    assert not [line for line in p.seen + rest if "Traceback" in line], tail
    assert took < 10.0  # a bound for a loaded machine
    return took


def _messages(echo: Proc, until: Any, timeout: float = WAIT) -> list[dict[str, Any]]:
    """The messages ``tf_peer.py --echo`` printed, read until ``until(messages)`` holds."""
    got: list[dict[str, Any]] = []
    deadline = time.monotonic() + timeout
    while not until(got):
        assert time.monotonic() < deadline, f"the stream never satisfied the test: {got[-5:]}"
        m = echo.wait_for(r"^\{.*\}$", timeout=max(0.1, deadline - time.monotonic()))
        got.append(json.loads(m.group(0)))
    return got


def _edges(messages: list[dict[str, Any]], topic: str) -> dict[tuple[str, str], Any]:
    return {(t["parent"], t["child"]): t for m in messages if m["topic"] == topic
            for t in m["transforms"]}


def _debian(messages: list[dict[str, Any]], lookups: list[list[Any]]) -> dict[str, Any]:
    """Debian's tf2_py fed ``messages`` (authority default_authority, as ROS 2's listener
    gives): its answers to ``lookups`` and its all_frames_as_yaml."""
    r = subprocess.run(["/usr/bin/python3", str(DEBIAN_SIDE)],
                       input=json.dumps({"messages": messages, "lookups": lookups}),
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    out: dict[str, Any] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


def _lines_until_blank(p: Proc, timeout: float = WAIT) -> list[str]:
    """The lines ``p`` prints next, up to (not with) the next empty line."""
    out: list[str] = []
    deadline = time.monotonic() + timeout
    while True:
        remaining = deadline - time.monotonic()
        assert remaining > 0, f"no empty line in {timeout} s after {out[-10:]}"
        try:
            line = p.lines.get(timeout=min(remaining, 0.5))
        except queue.Empty:
            continue
        if line == "":
            return out
        out.append(line)


def test_static_broadcaster(procs: Procs) -> None:
    """examples_tf2_py static_broadcaster: five static transforms, once, on /tf_static."""
    echo = procs.peer("tf_peer.py", "--echo")
    program = procs.program("static_broadcaster")
    messages = _messages(echo, lambda ms: len(_edges(ms, "/tf_static")) == 5)
    edges = _edges(messages, "/tf_static")
    assert {e: (t["t"], t["r"]) for e, t in edges.items()} == STATIC_EXAMPLE  # the source's
    assert all(t["stamp"][0] > 1_000_000_000 for t in edges.values())  # its clock's now()
    debian = _debian(messages, [["base_link", "sonar_0", [0, 0]],
                                ["base_link", "camera", [0, 0]],
                                ["sonar_0", "sonar_2", [0, 0]]])
    sonar_0, camera, across = debian["lookups"]
    assert sonar_0["t"] == pytest.approx([S45, C45, 0.1], abs=1e-15)
    assert sonar_0["r"] == [0.0, 0.0, -0.4871745124605095, -0.8733046400935156]
    assert camera == {"t": [0.05, 0.0, pytest.approx(0.11, abs=1e-15)],
                      "r": [0.0, 0.0, 0.0, 1.0], "stamp": [0, 0]}
    # sonar_0 -> sonar_2: yaw -2·atan2(0.487, -0.873) then back, 0.1 m apart in y
    assert math.hypot(*across["t"]) == pytest.approx(2 * C45, abs=1e-12)
    print(f"static_broadcaster on tfbus, SIGINT to exit: {_ends_on_sigint(program):.3f} s")


def test_static_turtle_tf2_broadcaster(procs: Procs) -> None:
    """turtle_tf2_py static_turtle_tf2_broadcaster: world -> its argument's frame, the
    quaternion from roll/pitch/yaw by its own (transforms3d's sxyz) formula."""
    echo = procs.peer("tf_peer.py", "--echo")
    program = procs.program("static_turtle_tf2_broadcaster",
                            "mystaticturtle", "0.5", "-1.25", "1", "0.1", "0.2", "0.3")
    messages = _messages(echo, lambda ms: _edges(ms, "/tf_static"))
    (edge, t), = _edges(messages, "/tf_static").items()
    assert edge == ("world", "mystaticturtle")
    assert t["t"] == [0.5, -1.25, 1.0]
    # transforms3d.euler.euler2quat(0.1, 0.2, 0.3, 'sxyz') (w, x, y, z), in ROS's order
    want = [0.034270798550482096, 0.10602051106179562, 0.14357217502739192,
            0.9833474432563558]
    assert t["r"] == pytest.approx(want, abs=1e-15)
    debian = _debian(messages, [["world", "mystaticturtle", [0, 0]],
                                ["mystaticturtle", "world", [0, 0]]])
    forward, back = debian["lookups"]
    assert forward["t"] == [0.5, -1.25, 1.0] and forward["r"] == t["r"]
    # the inverse: -(R^T p) and the conjugate
    q = t["r"]
    assert back["r"] == pytest.approx([-q[0], -q[1], -q[2], q[3]], abs=1e-15)
    assert math.hypot(*back["t"]) == pytest.approx(math.hypot(0.5, -1.25, 1.0), abs=1e-12)
    print(f"static_turtle_tf2_broadcaster, SIGINT to exit: {_ends_on_sigint(program):.3f} s")


def _timed_edges(messages: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [t for m in messages if m["topic"] == "/tf" for t in m["transforms"]]


def test_fixed_frame_tf2_broadcaster(procs: Procs) -> None:
    """turtle_tf2_py fixed_frame_tf2_broadcaster: turtle1 -> carrot1, 2 m in y, at 10 Hz."""
    echo = procs.peer("tf_peer.py", "--echo")
    program = procs.program("fixed_frame_tf2_broadcaster")
    messages = _messages(echo, lambda ms: len(_timed_edges(ms)) >= 12)
    sent = _timed_edges(messages)
    assert {(t["parent"], t["child"]) for t in sent} == {("turtle1", "carrot1")}
    assert all((t["t"], t["r"]) == ([0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]) for t in sent)
    stamps = [s * 1_000_000_000 + n for s, n in (t["stamp"] for t in sent)]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    period = (stamps[-1] - stamps[1]) / (len(stamps) - 2) / 1e9
    assert 0.05 < period < 0.5  # its 0.1 s timer, on a loaded machine
    middle = sent[len(sent) // 2]["stamp"]
    answer = _debian(messages, [["turtle1", "carrot1", middle]])["lookups"][0]
    assert (answer["t"], answer["r"]) == ([0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    assert answer["stamp"][0] == middle[0]  # ROS 1 tf2_py: a double's nanoseconds
    assert answer["stamp"][1] == pytest.approx(middle[1], abs=1000)
    print(f"fixed_frame_tf2_broadcaster, SIGINT to exit: {_ends_on_sigint(program):.3f} s")


def test_dynamic_frame_tf2_broadcaster(procs: Procs) -> None:
    """turtle_tf2_py dynamic_frame_tf2_broadcaster: carrot1 at 10·(sin, cos)(s·π) of the
    clock's whole seconds s, at 10 Hz; Debian's tf2 interpolates between two of them."""
    echo = procs.peer("tf_peer.py", "--echo")
    program = procs.program("dynamic_frame_tf2_broadcaster")
    messages = _messages(echo, lambda ms: len(_timed_edges(ms)) >= 25)
    sent = _timed_edges(messages)
    assert {(t["parent"], t["child"]) for t in sent} == {("turtle1", "carrot1")}
    for t in sent:  # the stamp is read just after the seconds: the same second or the next
        sec = t["stamp"][0]
        assert t["t"] in ([10 * math.sin(s * math.pi), 10 * math.cos(s * math.pi), 0.0]
                          for s in (sec, sec - 1)), t
        assert t["r"] == [0.0, 0.0, 0.0, 1.0]
    a, b = sent[3], sent[4]
    mid = (a["stamp"][0] * 1_000_000_000 + a["stamp"][1]
           + b["stamp"][0] * 1_000_000_000 + b["stamp"][1]) // 2
    answer = _debian(messages, [["turtle1", "carrot1", [mid // 1_000_000_000,
                                                        mid % 1_000_000_000]]])["lookups"][0]
    # halfway (to the nanosecond) between two samples: their mean, within what Debian's
    # ROS 1 tf2_py's double-second stamps allow (an ulp of ~1.7e9 s is 2.4e-7 s: the
    # ratio of a 0.1 s gap is off by up to ~5e-6, times the step between the samples)
    for k in range(3):
        step = abs(b["t"][k] - a["t"][k])
        assert answer["t"][k] == pytest.approx((a["t"][k] + b["t"][k]) / 2,
                                               abs=1e-7 + 5e-6 * step)
    print(f"dynamic_frame_tf2_broadcaster, SIGINT to exit: {_ends_on_sigint(program):.3f} s")


def test_frame_dumper(procs: Procs) -> None:
    """examples_tf2_py frame_dumper: prints Buffer.all_frames_as_yaml() every second; fed
    static_broadcaster (on tfbus), its dump equals Debian's tf2_py fed the same stream."""
    echo = procs.peer("tf_peer.py", "--echo")
    dumper = procs.program("frame_dumper")
    dumper.wait_for(r"^\[\]$", timeout=WAIT)  # an empty buffer's dump (tf2's "[]")
    broadcaster = procs.program("static_broadcaster")
    messages = _messages(echo, lambda ms: len(_edges(ms, "/tf_static")) == 5)
    dumper.wait_for(r"^sonar_2: $", timeout=WAIT)
    _lines_until_blank(dumper)
    dump = _lines_until_blank(dumper)  # the next whole dump
    want = _debian(messages, [])["yaml"]
    assert "\n".join(dump) + "\n" == want
    assert "sonar_2: \n  parent: 'platform'\n  broadcaster: 'default_authority'\n" in want
    print(f"frame_dumper, SIGINT to exit: {_ends_on_sigint(dumper):.3f} s")
    _ends_on_sigint(broadcaster)


def _wheels(procs: Procs, tmp_path: Path) -> Proc:
    spec = tmp_path / "wheels.json"
    spec.write_text(json.dumps(WHEELS))
    return procs.peer("gated_tf_feeder.py", str(spec), "--rate", "30")


def _start_feeding(feeder: Proc, subscribers: int = 1) -> None:
    """SIGUSR1 once ``subscribers`` subscriptions (the program's listener, and the echo
    peer where a test compares with what it recorded) matched the feeder's /tf: a
    subscription matched later would miss the first samples."""
    feeder.wait_for(rf"^SUBSCRIBERS ([{subscribers}-9]|[1-9][0-9])", timeout=WAIT)
    feeder.proc.send_signal(signal.SIGUSR1)


def test_waits_for_transform(procs: Procs, tmp_path: Path) -> None:
    """examples_tf2_py waits_for_transform: wait_for_transform_async's future and its
    done callback, under rclpy's executor."""
    feeder = _wheels(procs, tmp_path)
    broadcaster = procs.program("static_broadcaster")
    program = procs.program("waits_for_transform")
    program.wait_for(r"Waiting for transform from sonar_2 to starboard_wheel", timeout=WAIT)
    program.wait_for(r"Still waiting for transform", timeout=WAIT)  # not done without data
    _start_feeding(feeder)
    program.wait_for(r"\]: Got transform$", timeout=WAIT)
    assert not [line for line in program.seen if "no longer available" in line]
    print(f"waits_for_transform, SIGINT to exit: {_ends_on_sigint(program):.3f} s")
    _ends_on_sigint(broadcaster)


def test_a_sigint_while_rclpy_takes_a_message_ends_the_program(
    procs: Procs, tmp_path: Path
) -> None:
    """examples_tf2_py frame_dumper following a 30 Hz ``/tf`` stream ends on a SIGINT
    whenever it lands, as the program's ``except KeyboardInterrupt`` expects: rclpy's
    ``take_message`` turns a ``KeyboardInterrupt`` raised in the Python code it runs to
    build a message into a ``RuntimeError`` out of ``rclpy.spin`` (status 1, a traceback),
    so the listener takes ``/tf`` serialized and no Python code runs inside a take. The
    runner sends SIGINT at the first Python call inside one, should there be any."""
    feeder = _wheels(procs, tmp_path)
    dumper = procs.program_interrupted_in_take("frame_dumper")
    dumper.wait_for(r"^\[\]$", timeout=WAIT)
    _start_feeding(feeder)
    for _ in range(2):  # two whole dumps with the wheel: dozens of messages taken
        dumper.wait_for(r"^starboard_wheel: $", timeout=WAIT)
    assert not [line for line in dumper.seen if "SIGINT INSIDE" in line]
    print(f"frame_dumper under a stream, SIGINT to exit: {_ends_on_sigint(dumper):.3f} s")


_FLOAT = r"(-?[0-9.e+-]+|nan|inf)"


def _parse_repr(text: str) -> dict[str, Any]:
    """The numbers of a geometry_msgs TransformStamped's repr (rclpy's message repr)."""
    stamp = re.search(r"Time\(sec=(\d+), nanosec=(\d+)\)", text)
    tr = re.search(rf"Vector3\(x={_FLOAT}, y={_FLOAT}, z={_FLOAT}\)", text)
    q = re.search(rf"Quaternion\(x={_FLOAT}, y={_FLOAT}, z={_FLOAT}, w={_FLOAT}\)", text)
    frames = re.search(r"frame_id='([^']*)'\), child_frame_id='([^']*)'", text)
    assert stamp and tr and q and frames, text
    return {"stamp": [int(stamp.group(1)), int(stamp.group(2))],
            "t": [float(v) for v in tr.groups()], "r": [float(v) for v in q.groups()],
            "frames": list(frames.groups())}


def test_async_waits_for_transform(procs: Procs, tmp_path: Path) -> None:
    """examples_tf2_py async_waits_for_transform: ``await lookup_transform_async`` in an
    rclpy coroutine timer callback; the transform it prints equals Debian's tf2_py's
    lookup on the same stream at the same stamp."""
    echo = procs.peer("tf_peer.py", "--echo")
    feeder = _wheels(procs, tmp_path)
    broadcaster = procs.program("static_broadcaster")
    program = procs.program("async_waits_for_transform")
    program.wait_for(r"Waiting for transform from sonar_2 to starboard_wheel", timeout=WAIT)
    # the echo peer records from the first sample, which may be the one that answers
    # (tf2_py fed a recording without it cannot look up its stamp: CI saw that)
    _start_feeding(feeder, subscribers=2)
    # the first await was answered by the data sent during it (no LookupException first)
    outcome = program.wait_for(r"\]: (Got|failed to get transform) (.*)$", timeout=WAIT)
    assert outcome.group(1) == "Got", outcome.group(0)
    got = _parse_repr(outcome.group(2))
    assert got["frames"] == ["starboard_wheel", "sonar_2"]
    ns = got["stamp"][0] * 1_000_000_000 + got["stamp"][1]
    messages = _messages(echo, lambda ms: any(  # up to a later sample (tf2_py's rounding)
        t["stamp"][0] * 1_000_000_000 + t["stamp"][1] > ns for t in _timed_edges(ms))
        and len(_edges(ms, "/tf_static")) == 5)
    want = _debian(messages, [["starboard_wheel", "sonar_2", got["stamp"]]])["lookups"][0]
    assert "stamp" in want, (want, got["stamp"], _timed_edges(messages)[:3])
    assert want["stamp"][0] == got["stamp"][0]  # ROS 1 tf2_py: a double's nanoseconds
    assert want["stamp"][1] == pytest.approx(got["stamp"][1], abs=1000)
    assert got["t"] == pytest.approx(want["t"], abs=1e-12)
    assert got["r"] == pytest.approx(want["r"], abs=1e-12)
    assert got["r"][1] != 0.0 and got["t"][1] != 0.0  # a rotation and an offset, not identity
    print(f"async_waits_for_transform, SIGINT to exit: {_ends_on_sigint(program):.3f} s")
    _ends_on_sigint(broadcaster)


def test_blocking_waits_for_transform(procs: Procs, tmp_path: Path) -> None:
    """examples_tf2_py blocking_waits_for_transform: lookup_transform with a 5 s timeout in
    a timer callback under a MultiThreadedExecutor blocks until the transform arrives
    (the listener's subscriptions must not share the timer's callback group)."""
    feeder = _wheels(procs, tmp_path)
    broadcaster = procs.program("static_broadcaster")
    program = procs.program("blocking_waits_for_transform")
    program.wait_for(r"Waiting for transform from sonar_2 to starboard_wheel", timeout=WAIT)
    _start_feeding(feeder)
    outcome = program.wait_for(r"\]: (Got transform|transform not ready)$", timeout=WAIT)
    # the first wait was answered by the data sent during it (it started before them)
    assert outcome.group(1) == "Got transform", program.seen[-20:]
    print(f"blocking_waits_for_transform, SIGINT to exit: {_ends_on_sigint(program):.3f} s")
    _ends_on_sigint(broadcaster)
