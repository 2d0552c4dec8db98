"""A bag-analysis program on tfbus.compat: evo's ``evo_traj`` (github.com/MichaelGrupp/evo,
GPL-3.0: installed from PyPI as a test peer by ``scripts/install/install_evo.sh``, never copied).

evo's ``evo/tools/tf_cache.py`` reads a bag's ``/tf`` and ``/tf_static`` into tf2_py's
``BufferCore`` (``set_transform`` / ``set_transform_static``), asks
``get_latest_common_time`` and looks the chain up with ``lookup_transform_core`` every
0.1 s from the first /tf stamp. It is run twice on the same recording
(``tests/data/tf_example``: odom -> base_footprint at 10 Hz, static base_footprint ->
base_link):

* on real tf2: Debian's ``/usr/bin/python3`` with Debian's ``tf2_py`` (tf2's C++
  ``BufferCore``), evo's ROS 1 branch (``rospy.Time``);
* on tfbus: the ROS 2 venv's python (real ``geometry_msgs``, ``rclpy.time``: evo's ROS 2
  branch, as under rclpy's tf2) with ``sys.modules["tf2_py"] = tfbus.compat.tf2_py`` set
  before evo is imported (``peers/evo_runner.py``): its imports changed only.

The trajectories evo saves (``--save_as_tum``) are compared pose for pose.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from peer_install import peer_unavailable, require

ROOT = Path(__file__).resolve().parents[2]
RUNNER = ROOT / "peers" / "evo_runner.py"
BAG = ROOT / "tests" / "data" / "tf_example"
ROS_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
DEBIAN_PYTHON = Path("/usr/bin/python3")
TIMEOUT = 60.0  # bound on one evo run, for a loaded machine

FIRST_STAMP = 1_700_000_000.25  # the recording's first /tf stamp (s)
LAST_STAMP = 1_700_000_051.85  # its last
STATIC_Z = 0.01  # base_footprint -> base_link, the recording's static transform (m)


@pytest.fixture(scope="module", name="evo_dir")
def evo_dir_fixture() -> Path:
    """Where evo is installed (``scripts/install/install_evo.sh``); Debian's ROS 1 and the ROS 2
    venv are there too."""
    if sys.platform != "linux":
        peer_unavailable("ros2-env", "the ROS 2 wheels are manylinux only")
    require("ros1", "install_ros1.sh")
    require("ros2-env", "install_ros2_env.sh", timeout=1200)
    line = require("evo", "install_evo.sh", timeout=900)
    evo_dir = Path(line.split("(", 1)[1].split(",")[0].rstrip(")"))
    assert (evo_dir / "evo" / "tools" / "tf_cache.py").exists(), line
    return evo_dir


def _evo_traj(python: Path, side: str, evo_dir: Path, work: Path,
              pythonpath: list[str]) -> tuple[np.ndarray, str]:
    """``evo_traj bag2 tests/data/tf_example /tf:odom.base_link --save_as_tum --full_check``
    run in ``work`` (its own HOME: evo writes its settings there). Its saved trajectory
    (rows: stamp s, x y z m, qx qy qz qw) and its output are returned."""
    work.mkdir()
    env = dict(os.environ, HOME=str(work), PYTHONPATH=os.pathsep.join(pythonpath),
               MPLBACKEND="Agg", PYTHONUNBUFFERED="1")
    out = subprocess.run(
        [str(python), str(RUNNER), str(evo_dir), side, "bag2", str(BAG),
         "/tf:odom.base_link", "--save_as_tum", "--full_check"],
        cwd=work, env=env, capture_output=True, text=True, timeout=TIMEOUT, check=False)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text
    assert "Traceback" not in text and "[ERROR]" not in text, text
    return np.loadtxt(work / "tf_odom.base_link.tum", ndmin=2), text


def test_evo_traj_matches_debian_tf2_py(evo_dir: Path, tmp_path: Path) -> None:
    paths = sysconfig.get_paths()  # the test runner's own packages (numpy, anyio, ...)
    site = list(dict.fromkeys([paths["purelib"], paths["platlib"]]))
    debian, debian_text = _evo_traj(DEBIAN_PYTHON, "debian", evo_dir, tmp_path / "debian", [])
    tfbus, tfbus_text = _evo_traj(ROS_PYTHON, "tfbus", evo_dir, tmp_path / "tfbus",
                                  [str(ROOT), *site])
    for text in (debian_text, tfbus_text):
        assert "SE(3) conform\tyes" in text and "timestamps\tok" in text, text

    # A pose every 0.1 s from the first stamp. Debian's tf2_py (ROS 1) carries stamps as
    # double seconds (tf2_py.cpp rostime_converter: ros::Time().fromSec(to_sec())), so it
    # keeps the last stamp as ...051.849999905 s and evo's 0.1 s steps end one before
    # it; tfbus keeps stamps in integer nanoseconds, as rclpy's tf2 does, and evo's last
    # step lands on the last message.
    assert len(debian) == 516 and len(tfbus) == 517
    steps = FIRST_STAMP + 0.1 * np.arange(517)
    np.testing.assert_allclose(tfbus[:, 0], steps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(debian[:, 0], steps[:516], rtol=0, atol=1e-6)
    assert tfbus[-1, 0] == pytest.approx(LAST_STAMP, abs=1e-6)

    # the same poses: odom -> base_footprint interpolated, then the static 1 cm up
    np.testing.assert_allclose(tfbus[:516, 1:], debian[:, 1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tfbus[:, 3], STATIC_Z, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tfbus[:, 4:], axis=1), 1.0, rtol=0, atol=1e-12)
    assert tfbus[0, 1:4].tolist() == pytest.approx([0.0, 0.0, STATIC_Z], abs=1e-12)
