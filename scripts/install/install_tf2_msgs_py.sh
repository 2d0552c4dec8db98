#!/usr/bin/env bash
# Install Debian's ROS 1 python3-tf2-geometry-msgs and python3-tf2-sensor-msgs (0.7.6),
# the reference implementations the registered transforms of tfbus.convert are checked
# against (tests/geometry/test_convert_reference.py, run under /usr/bin/python3). Exits 0
# only when both import and transform a point; otherwise 1 with the reason
# (scripts/install/_peer.sh). Idempotent and bounded in time.
set -u
PEER="tf2-msgs-py"
PKGS="python3-tf2-geometry-msgs python3-tf2-sensor-msgs"
# shellcheck source=scripts/install/_peer.sh
. "$(dirname "${BASH_SOURCE[0]}")/_peer.sh"
present() {
    # shellcheck disable=SC2086
    dpkg_have $PKGS
}
works() {
    /usr/bin/python3 - <<'PY'
import tf2_geometry_msgs, tf2_sensor_msgs  # noqa: F401
from geometry_msgs.msg import PointStamped, TransformStamped
t = TransformStamped()
t.transform.translation.x, t.transform.rotation.w = 0.1, 1.0
p = PointStamped()
p.point.x = 1.0
assert abs(tf2_geometry_msgs.do_transform_point(p, t).point.x - 1.1) < 1e-12
PY
}
peer_install
