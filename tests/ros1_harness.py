"""Real ROS 1 peers for the tests: Debian's roscore and tools, the tutorial's C++ nodes.

Everything runs on 127.0.0.1: each master gets a free port, ``ROS_IP=127.0.0.1`` and a
private ``ROS_HOME``. The tutorial's nodes are this repository's C++ sources in
``tests/peers/ros1/`` (built by its ``build.sh``). Processes are started here, read by
threads line by line, waited on with a bound, and ended by their PID (SIGINT, then SIGKILL
after a bound). Also the benchmarks' ROS 1 harness (``benchmarks/bench_ros1.py``,
``bench_check.py``, ``soak_ros1.py`` put ``tests/`` on ``sys.path``): one home.
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import xmlrpc.client
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / "tests" / "peers" / "ros1"
INSTALL = ROOT / "scripts" / "install_ros1.sh"
ROS_BIN = Path("/usr/bin")


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ros1_missing(packages: tuple[str, ...] = ("tf",)) -> str | None:
    """Why ROS 1 cannot be used here (after trying to install it with
    ``scripts/install_ros1.sh``), or None: roscore, rosrun and the pkg-config
    ``packages`` (the tests' C++ nodes need ``tf``; the benchmarks' ``roscpp`` and
    ``tf2_msgs``)."""
    need = [ROS_BIN / "roscore", ROS_BIN / "rosrun"]

    def ready() -> bool:
        return all(p.exists() for p in need) and all(_has_pkg(p) for p in packages)

    if ready():
        return None
    if not INSTALL.exists():
        return f"{INSTALL} missing"
    try:
        out = subprocess.run(
            ["bash", str(INSTALL)], capture_output=True, text=True, timeout=1900, check=False
        ).stdout.strip()
    except subprocess.TimeoutExpired:
        return "installing ROS 1 timed out"
    if ready():
        return None
    return out or "ROS 1 not installed"


def _has_pkg(name: str) -> bool:
    return (
        subprocess.run(
            ["pkg-config", "--exists", name], env=_path_env(), capture_output=True, check=False
        ).returncode
        == 0
    )


def _path_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
    return env


class Proc:
    """A child process whose stdout+stderr lines are collected by a thread."""

    def __init__(self, args: list[str], env: dict[str, str], cwd: Path | None = None) -> None:
        self.args = args
        self.proc = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            encoding="utf-8",
            errors="replace",
            env=env,
            cwd=cwd,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float = 20.0) -> re.Match[str]:
        """The first line (from now on, or already seen) matching ``pattern``.

        Raises:
            AssertionError: none within ``timeout`` s, with the output seen.
        """
        rx = re.compile(pattern)
        for line in self.seen:
            if m := rx.search(line):
                self.seen.remove(line)
                return m
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    self._reader.join(timeout=1.0)
                    if self.lines.empty():
                        break
                continue
            if m := rx.search(line):
                return m
            self.seen.append(line)
        tail = "\n".join(self.seen[-30:])
        raise AssertionError(
            f"no line matching {pattern!r} from {self.args} in {timeout} s:\n{tail}"
        )

    def drain(self) -> list[str]:
        """Every line read so far that was not consumed by :meth:`wait_for`."""
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                return list(self.seen)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """End the process by its PID and wait for it; the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._reader.join(timeout=2.0)
        return int(self.proc.returncode)


@dataclass
class Master:
    """A roscore on 127.0.0.1:port and the environment for nodes that use it."""

    port: int
    env: dict[str, str]
    proc: Proc | None = None

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        self.proc = Proc([str(ROS_BIN / "roscore"), "-p", str(self.port)], self.env)
        # roscore prints this once the master and /rosout are up: wait on it, bounded.
        self.proc.wait_for(r"started core service \[/rosout\]", timeout=60.0)
        xmlrpc.client.ServerProxy(self.uri).getPid("/tfbus_test")

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.stop(signal.SIGINT, timeout=20.0)
            self.proc = None

    def run(self, *args: str) -> Proc:
        """A ROS 1 command (``rosrun``, ``rostopic``, a built node) on this master."""
        return Proc(list(args), self.env)

    def call(self, method: str, *args: object) -> object:
        code, status, value = getattr(xmlrpc.client.ServerProxy(self.uri), method)(*args)
        assert code == 1, status
        return value


def master_env(port: int, home: Path) -> dict[str, str]:
    env = _path_env()
    env.update(
        ROS_MASTER_URI=f"http://127.0.0.1:{port}",
        ROS_IP="127.0.0.1",
        ROS_HOME=str(home),
        ROS_LOG_DIR=str(home / "log"),
        PYTHONUNBUFFERED="1",
    )
    env.pop("ROS_HOSTNAME", None)
    (home / "log").mkdir(parents=True, exist_ok=True)
    return env


@pytest.fixture(scope="session", name="ros1")
def ros1_fixture() -> None:
    """ROS 1 is installed (installing it if possible), else the test is skipped."""
    why = ros1_missing()
    if why is not None:
        pytest.skip(why)


@pytest.fixture(scope="session", name="tutorial_nodes")
def tutorial_nodes_fixture(ros1: None, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tutorial's C++ ``tf_broadcaster`` and ``tf_listener`` (``tests/peers/ros1/``),
    built once. ROS 1 is there (the ``ros1`` fixture), so a failed build is a failure."""
    if shutil.which("g++") is None:
        pytest.skip("g++ not found: cannot build the tutorial's C++ nodes")
    out = tmp_path_factory.mktemp("ros1_nodes")
    res = subprocess.run(
        ["bash", str(PEERS / "build.sh"), str(out)],
        env=_path_env(),
        capture_output=True,
        text=True,
        timeout=700,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(name="master")
def master_fixture(ros1: None, tmp_path: Path) -> Iterator[Master]:
    """A fresh roscore on a free loopback port; the test's environment points at it."""
    port = free_port()
    m = Master(port, master_env(port, tmp_path / "ros_home"))
    m.start()
    saved = {k: os.environ.get(k) for k in ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME")}
    os.environ["ROS_MASTER_URI"] = m.uri
    os.environ["ROS_IP"] = "127.0.0.1"
    os.environ.pop("ROS_HOSTNAME", None)
    try:
        yield m
    finally:
        m.stop()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def tfbus_cli(master: Master, *args: str) -> Proc:
    """``python -m tfbus.cli ARGS`` on this master."""
    env = dict(master.env)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONIOENCODING"] = "utf-8"
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env["PATH"]
    return Proc([sys.executable, "-m", "tfbus.cli", *args], env, cwd=ROOT)


# -- sensor_msgs/LaserScan from Debian's rostopic (issue 24) -------------------------

SCAN_YAML = (
    "{header: {seq: 0, stamp: {secs: 10, nsecs: 100000000}, frame_id: base_laser}, "
    "angle_min: 0.0, angle_max: 3.14159265, angle_increment: 1.57079633, "
    "time_increment: 0.01, scan_time: 0.1, range_min: 0.1, range_max: 10.0, "
    "ranges: [1.0, 2.0, 3.0, .nan, .inf], intensities: [5.0, 6.5, 7.0, 0.0, 1.0]}"
)
"""One LaserScan as ``rostopic pub`` takes it (YAML): five beams, a NaN and an inf."""


def rostopic_scan_publisher(master: Master, topic: str = "/scan") -> Proc:
    """Debian's ``rostopic pub`` (rospy, genpy's serialiser) publishing SCAN_YAML at 5 Hz."""
    return master.run("rostopic", "pub", "-r", "5", topic, "sensor_msgs/LaserScan", "--",
                      SCAN_YAML)


def assert_is_the_yaml_scan(got: object) -> None:
    """``got`` is SCAN_YAML's scan as a tfbus LaserScan, value for value (float32)."""
    import numpy as np

    from tfbus.messages import Header
    from tfbus.sensor_msgs import LaserScan
    from tfbus.time import Time

    assert type(got) is LaserScan
    assert got.header == Header(Time.from_ns(10_100_000_000), "base_laser")
    f32 = np.float32
    assert (got.angle_min, got.angle_max, got.angle_increment, got.time_increment,
            got.scan_time, got.range_min, got.range_max) == tuple(
        float(f32(v)) for v in (0.0, 3.14159265, 1.57079633, 0.01, 0.1, 0.1, 10.0))
    # PyYAML's .nan is -inf/inf: x86's default NaN, sign bit set; compared as a NaN
    assert np.isnan(got.ranges[3]) and got.ranges.dtype == f32 and len(got.ranges) == 5
    want = np.array([1.0, 2.0, 3.0, np.inf], dtype=f32)
    assert got.ranges[[0, 1, 2, 4]].tobytes() == want.tobytes()
    assert got.intensities.tobytes() == np.array([5.0, 6.5, 7.0, 0.0, 1.0], f32).tobytes()
