"""Run Debian's ROS 1 ``tf2_geometry_msgs.do_transform_wrench`` and
``tf2_sensor_msgs.do_transform_cloud`` (0.7.6) on cases read as JSON from stdin.

Runs under ``/usr/bin/python3`` (``scripts/install/install_tf2_msgs_py.sh``), never imports tfbus:
the reference side of ``tests/geometry/test_convert_reference.py``. Input::

    {"wrenches": [[[tx, ty, tz], [qx, qy, qz, qw], [fx, fy, fz], [tx, ty, tz]], ...],
     "clouds": [{"t": [...], "q": [...], "fields": [[name, offset, datatype, count], ...],
                 "height": h, "width": w, "point_step": n, "row_step": m,
                 "data": hex}, ...]}

Output: one JSON object, ``{"wrenches": [[force, torque], ...], "clouds": [[point tuple,
...], ...]}`` (each cloud read back with ``read_points``).
"""

from __future__ import annotations

import json
import sys
from typing import Any

import tf2_geometry_msgs  # type: ignore[import-not-found]
import tf2_sensor_msgs  # type: ignore[import-not-found]
from geometry_msgs.msg import TransformStamped, WrenchStamped  # type: ignore[import-not-found]
from sensor_msgs.msg import PointCloud2, PointField  # type: ignore[import-not-found]
from sensor_msgs.point_cloud2 import read_points  # type: ignore[import-not-found]


def transform(t: list[float], q: list[float]) -> Any:
    ts = TransformStamped()
    ts.header.frame_id = "target"
    ts.transform.translation.x, ts.transform.translation.y, ts.transform.translation.z = t
    (ts.transform.rotation.x, ts.transform.rotation.y, ts.transform.rotation.z,
     ts.transform.rotation.w) = q
    return ts


def main() -> None:
    cases = json.load(sys.stdin)
    out: dict[str, list[Any]] = {"wrenches": [], "clouds": []}
    for t, q, force, torque in cases["wrenches"]:
        w = WrenchStamped()
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = force
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = torque
        r = tf2_geometry_msgs.do_transform_wrench(w, transform(t, q))
        out["wrenches"].append([[r.wrench.force.x, r.wrench.force.y, r.wrench.force.z],
                                [r.wrench.torque.x, r.wrench.torque.y, r.wrench.torque.z]])
    for c in cases["clouds"]:
        cloud = PointCloud2()
        cloud.fields = [PointField(name=n, offset=o, datatype=d, count=k)
                        for n, o, d, k in c["fields"]]
        cloud.height, cloud.width = c["height"], c["width"]
        cloud.point_step, cloud.row_step = c["point_step"], c["row_step"]
        cloud.is_bigendian = False
        cloud.data = bytes.fromhex(c["data"])
        r = tf2_sensor_msgs.do_transform_cloud(cloud, transform(c["t"], c["q"]))
        out["clouds"].append([list(p) for p in read_points(r)])
    print(json.dumps(out))


if __name__ == "__main__":
    main()
