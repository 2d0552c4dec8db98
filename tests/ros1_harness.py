"""Real ROS 1 peers for the tests: pytest fixtures (a roscore per test or per module, the
tutorial's C++ nodes) on top of ``peers/ros1/ros1_peers.py`` (Debian's roscore and tools,
started and ended by PID on 127.0.0.1), which the benchmarks use too. The tutorial's nodes
are this repository's C++ sources in ``peers/ros1/`` (built by its ``build.sh``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from peer_install import peer_unavailable
from ros1_peers import (
    ROOT,
    Master,
    Proc,
    _path_env,
    free_port,
    master_env,
    ros1_missing,
    start_master,
)

__all__ = [
    "Master",
    "Proc",
    "assert_is_the_yaml_scan",
    "free_port",
    "master_env",
    "master_fixture",
    "module_master_fixture",
    "ros1_fixture",
    "ros1_missing",
    "rostopic_scan_publisher",
    "tfbus_cli",
    "tutorial_nodes_fixture",
]

PEERS = ROOT / "peers" / "ros1"


@pytest.fixture(scope="session", name="ros1")
def ros1_fixture() -> None:
    """ROS 1 is installed (installing it if possible), else the test is skipped."""
    why = ros1_missing()
    if why is not None:
        peer_unavailable("ros1", why)


@pytest.fixture(scope="session", name="tutorial_nodes")
def tutorial_nodes_fixture(ros1: None, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tutorial's C++ ``tf_broadcaster`` and ``tf_listener`` (``peers/ros1/``),
    built once. ROS 1 is there (the ``ros1`` fixture), so a failed build is a failure."""
    if shutil.which("g++") is None:
        peer_unavailable("ros1", "g++ not found: cannot build the tutorial's C++ nodes")
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
    yield from _running_master(tmp_path / "ros_home")


@pytest.fixture(scope="module", name="module_master")
def module_master_fixture(ros1: None, tmp_path_factory: pytest.TempPathFactory
                          ) -> Iterator[Master]:
    """One roscore for every test of a module (started at its first use, stopped after
    its last test), for modules whose tests each start and end their own nodes and
    need no master without them: a roscore takes seconds to start and stop at load.
    The environment points at it meanwhile. A module opts in with a ``master``
    fixture of its own that returns this one."""
    yield from _running_master(tmp_path_factory.mktemp("ros_home"))


def _running_master(home: Path) -> Iterator[Master]:
    """A roscore started in ``home`` with the environment pointing at it, until the
    generator is closed: then it is stopped and the environment restored."""
    m = start_master(home)
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


# -- sensor_msgs/LaserScan from Debian's rostopic ------------------------------------

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
