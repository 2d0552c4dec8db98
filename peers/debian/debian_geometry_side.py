"""Debian's ROS 1 ``tf2_geometry_msgs`` (PyKDL) and ``tfbus.compat.tf2_geometry_msgs``
on the same rospy messages, in one process (the project's Python, Debian's ROS 1
packages appended to ``sys.path``): run by ``tests/compat/test_compat_debian_geometry.py``.
Prints one JSON line: for each path, the number of cases and the cases that differ in any
bit (sign of zero included)."""

from __future__ import annotations

import json
import math
import random
import struct
import sys
from typing import Any

sys.path.append("/usr/lib/python3/dist-packages")

import tf2_geometry_msgs as debian  # type: ignore[import-not-found]
import tf2_ros as debian_ros  # type: ignore[import-not-found]
from geometry_msgs.msg import (  # type: ignore[import-not-found]
    PointStamped,
    PoseStamped,
    TransformStamped,
    Vector3Stamped,
    WrenchStamped,
)

from tfbus.compat import tf2_geometry_msgs as ours
from tfbus.compat import tf2_ros as ours_ros


def unit(rnd: random.Random) -> list[float]:
    q = [rnd.uniform(-1, 1) for _ in range(4)]
    n = math.sqrt(sum(v * v for v in q))
    return [v / n for v in q]


def transform(rnd: random.Random, q: list[float]) -> Any:
    t = TransformStamped()
    t.header.frame_id = "map"
    t.child_frame_id = "base"
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = (
        rnd.uniform(-10, 10) for _ in range(3))
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = q
    return t


def bits(values: list[float]) -> list[str]:
    return [struct.pack("<d", v).hex() for v in values]


def flat(msg: Any) -> list[float]:
    if isinstance(msg, PointStamped):
        return [msg.point.x, msg.point.y, msg.point.z]
    if isinstance(msg, Vector3Stamped):
        return [msg.vector.x, msg.vector.y, msg.vector.z]
    if isinstance(msg, PoseStamped):
        p, o = msg.pose.position, msg.pose.orientation
        return [p.x, p.y, p.z, o.x, o.y, o.z, o.w]
    f, t = msg.wrench.force, msg.wrench.torque
    return [f.x, f.y, f.z, t.x, t.y, t.z]


def main() -> None:
    rnd = random.Random(20261123)
    special = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
               [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]]
    report: dict[str, Any] = {}
    paths = ["point", "vector3", "pose", "wrench", "buffer.transform"]
    for name in paths:
        report[name] = {"cases": 0, "differ": []}
    for i in range(600):
        qt = special[i % 5] if i < 25 else unit(rnd)
        qp = special[(i // 5) % 5] if i < 25 else unit(rnd)
        t = transform(rnd, qt)
        xyz = [rnd.uniform(-5, 5) for _ in range(3)]
        point = PointStamped()
        point.header.frame_id = "base"
        point.point.x, point.point.y, point.point.z = xyz
        vector = Vector3Stamped()
        vector.header.frame_id = "base"
        vector.vector.x, vector.vector.y, vector.vector.z = xyz
        pose = PoseStamped()
        pose.header.frame_id = "base"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = xyz
        (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
         pose.pose.orientation.w) = qp
        wrench = WrenchStamped()
        wrench.header.frame_id = "base"
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = xyz
        wrench.wrench.torque.x, wrench.wrench.torque.y, wrench.wrench.torque.z = qp[:3]
        cases = [("point", debian.do_transform_point, ours.do_transform_point, point),
                 ("vector3", debian.do_transform_vector3, ours.do_transform_vector3, vector),
                 ("pose", debian.do_transform_pose, ours.do_transform_pose, pose),
                 ("wrench", debian.do_transform_wrench, ours.do_transform_wrench, wrench)]
        for name, theirs_fn, ours_fn, msg in cases:
            want, got = theirs_fn(msg, t), ours_fn(msg, t)
            report[name]["cases"] += 1
            if type(got) is not type(want) or bits(flat(got)) != bits(flat(want)) or \
                    got.header.frame_id != want.header.frame_id:
                report[name]["differ"].append([i, flat(want), flat(got)])
        # Buffer.transform: tf2_ros's lookup then the registered function
        theirs_buf, ours_buf = debian_ros.Buffer(debug=False), ours_ros.Buffer(debug=False)
        theirs_buf.set_transform(t, "side")
        ours_buf.set_transform(t, "side")
        for msg in (point, vector, pose, wrench):
            want = theirs_buf.transform(msg, "map")
            got = ours_buf.transform(msg, "map")
            report["buffer.transform"]["cases"] += 1
            if type(got) is not type(want) or bits(flat(got)) != bits(flat(want)):
                report["buffer.transform"]["differ"].append([i, flat(want), flat(got)])
    print(json.dumps(report))


if __name__ == "__main__":
    import rospy  # type: ignore[import-not-found]

    rospy.rostime.set_rostime_initialized(True)  # genpy times without a node
    main()
