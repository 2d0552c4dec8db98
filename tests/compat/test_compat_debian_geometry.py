"""``tfbus.compat.tf2_geometry_msgs`` equals Debian's ROS 1 ``tf2_geometry_msgs``
(0.7.6, through PyKDL) bit for bit, signs included, on 600 transforms (25 of them the
half-turn quaternions whose sign a quaternion product and KDL's matrix disagree on) for
``do_transform_point``, ``do_transform_vector3``, ``do_transform_pose``,
``do_transform_wrench`` and ``Buffer.transform`` of each; the results are rospy messages of
the classes given. Both run on the same rospy messages in one process
(``peers/debian/debian_geometry_side.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from peer_install import require

ROOT = Path(__file__).resolve().parents[2]
SIDE = ROOT / "peers" / "debian" / "debian_geometry_side.py"


def test_every_path_equals_debian_bit_for_bit() -> None:
    require("tf2-msgs-py", "install_tf2_msgs_py.sh")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, str(SIDE)], env=env, capture_output=True, text=True,
                       timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    report = json.loads(r.stdout.strip().splitlines()[-1])
    assert {k: v["cases"] for k, v in report.items()} == {
        "point": 600, "vector3": 600, "pose": 600, "wrench": 600, "buffer.transform": 2400}
    assert {k: v["differ"][:3] for k, v in report.items()} == {k: [] for k in report}
