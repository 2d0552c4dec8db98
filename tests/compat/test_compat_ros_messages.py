"""A ROS program keeps using compat's results as its own messages: the point, vector3,
pose, wrench, transform, pose-with-covariance, polygon and cloud ``do_transform_*`` of
``tfbus.compat`` and ``Buffer.transform`` of
them return, for a rospy or an rclpy message, a message of the same class, which takes a
field assignment, serializes
(genpy's ``serialize``, rclpy's ``serialize_message``) and reads back to the same bytes;
the rospy cloud equals Debian's own ``tf2_sensor_msgs.do_transform_cloud`` byte for byte,
the rclpy cloud the hand-computed transform. Each library runs in its own interpreter
(``peers/debian/debian_messages_side.py``, ``peers/ros2/compat_messages_rclpy.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from peer_install import peer_unavailable, require

ROOT = Path(__file__).resolve().parents[2]
ROSPY_SIDE = ROOT / "peers" / "debian" / "debian_messages_side.py"
RCLPY_SIDE = ROOT / "peers" / "ros2" / "compat_messages_rclpy.py"
ROS2_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"

OK = {"type": True, "serialized": True, "set": True}

# The transform: translation (1, 2, 0.5), a turn about z with cos 0.28, sin 0.96
# (quaternion z 0.6, w 0.8): (x, y, z) -> (0.28 x - 0.96 y + 1, 0.96 x + 0.28 y + 2, z + 0.5),
# stored back in float32; intensity carried.
POINTS = [(1.0, 0.0, 0.0, 7.0), (0.0, 2.0, 0.5, 8.0), (-1.5, 0.25, 3.0, 9.0)]
EXPECTED = [[float(np.float32(v)) for v in (0.28 * x - 0.96 * y + 1.0, 0.96 * x + 0.28 * y + 2.0,
                                            z + 0.5, i)] for x, y, z, i in POINTS]


# The transform, pose-with-covariance and polygon results (identity inner transform and
# pose at the origin; covariance 0..35 row-major, each 3x3 block B rotated to R B Rᵀ;
# Point32 vertices (1, 0, 0) and (0, 1, 0), float32 on the wire).
R = np.array([[0.28, -0.96, 0.0], [0.96, 0.28, 0.0], [0.0, 0.0, 1.0]])
COV = np.arange(36.0).reshape(6, 6)
ROTATED = np.block([[R @ COV[i:i + 3, j:j + 3] @ R.T for j in (0, 3)] for i in (0, 3)])


def _check_values(values: object) -> None:
    assert isinstance(values, dict)
    frame, child, *numbers = values["transform"]
    assert (frame, child) == ("map", "tool")
    assert numbers == pytest.approx([1.0, 2.0, 0.5, 0.0, 0.0, 0.6, 0.8], abs=1e-12)
    *pose, covariance = values["pose_with_covariance"]
    assert pose == pytest.approx([1.0, 2.0, 0.5, 0.0, 0.0, 0.6, 0.8], abs=1e-12)
    assert np.allclose(np.array(covariance).reshape(6, 6), ROTATED, atol=1e-9)
    assert np.allclose(values["polygon"], [[1.28, 2.96, 0.5], [0.04, 2.28, 0.5]], atol=1e-6)


def _run(python: Path | str, side: Path, env: dict[str, str]) -> dict[str, object]:
    r = subprocess.run([str(python), str(side)], env=env, capture_output=True, text=True,
                       timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def test_rospy_messages_in_rospy_messages_out() -> None:
    require("tf2-msgs-py", "install_tf2_msgs_py.sh")
    report = _run(sys.executable, ROSPY_SIDE, dict(os.environ, PYTHONPATH=str(ROOT)))
    cloud = report.pop("cloud")
    assert isinstance(cloud, dict)
    assert cloud.pop("equal") is True  # Debian's tf2_sensor_msgs, byte for byte
    assert cloud.pop("points") == EXPECTED
    assert cloud == OK
    _check_values(report.pop("values"))
    assert report == {name: OK for name in (
        "point", "vector3", "pose", "wrench", "transform", "pose_with_covariance", "polygon",
        "buffer.transform point", "buffer.transform pose_with_covariance",
        "buffer.transform polygon", "buffer.transform cloud")}


def test_rclpy_messages_in_rclpy_messages_out() -> None:
    if sys.platform != "linux":
        peer_unavailable("ros2-env", "the ROS 2 wheels are manylinux only")
    require("ros2-env", "install_ros2_env.sh", timeout=1200)
    if sys.version_info[:2] != (3, 11):
        pytest.skip("the ROS 2 venv is Python 3.11: this environment's packages cannot be shared")
    paths = sysconfig.get_paths()  # the test runner's own environment (anyio, numpy, ...)
    site = os.pathsep.join(dict.fromkeys([paths["purelib"], paths["platlib"]]))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), site]))
    report = _run(ROS2_PYTHON, RCLPY_SIDE, env)
    assert report.pop("cloud_points") == EXPECTED
    assert report.pop("cloud_header") == ["map", 5, 250]  # the transform's header
    _check_values(report.pop("values"))
    assert report == {name: OK for name in (
        "point", "vector3", "pose_stamped", "pose", "wrench", "transform",
        "pose_with_covariance", "polygon", "cloud", "buffer.transform point",
        "buffer.transform pose_with_covariance", "buffer.transform polygon",
        "buffer.transform cloud")}
