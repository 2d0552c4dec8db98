"""Every ``do_transform_*`` and ``Buffer.transform`` path of ``tfbus.compat`` on rclpy
messages (the ROS 2 wheels of ``.venv-ros2``; no node, no DDS): run by
``tests/compat/test_compat_ros_messages.py``.

For each path the result must be an instance of the class given (an rclpy message), take
a field assignment as a ROS node makes one, and go through
``rclpy.serialization.serialize_message`` and back to the same bytes. The cloud's points
are printed for the test to check against the hand-computed transform. Prints one JSON
line: path -> {"type", "set", "serialized"}, and "cloud_points".
"""

from __future__ import annotations

import json
import struct
from typing import Any

from builtin_interfaces.msg import Time  # type: ignore[import-not-found]
from geometry_msgs.msg import (  # type: ignore[import-not-found]
    Point32,
    PointStamped,
    PolygonStamped,
    Pose,
    PoseStamped,
    PoseWithCovarianceStamped,
    TransformStamped,
    Vector3Stamped,
    WrenchStamped,
)
from rclpy.serialization import (  # type: ignore[import-not-found]
    deserialize_message,
    serialize_message,
)
from sensor_msgs.msg import PointCloud2, PointField  # type: ignore[import-not-found]

from tfbus.compat import tf2_geometry_msgs as geometry
from tfbus.compat import tf2_ros
from tfbus.compat import tf2_sensor_msgs as sensor

POINTS = [(1.0, 0.0, 0.0, 7.0), (0.0, 2.0, 0.5, 8.0), (-1.5, 0.25, 3.0, 9.0)]


def transform() -> Any:
    t = TransformStamped()
    t.header.frame_id = "map"
    t.header.stamp = Time(sec=5, nanosec=250)
    t.child_frame_id = "laser"
    t.transform.translation.x, t.transform.translation.y = 1.0, 2.0
    t.transform.translation.z = 0.5
    t.transform.rotation.z, t.transform.rotation.w = 0.6, 0.8  # a turn about z
    return t


def stamped(cls: Any) -> Any:
    m = cls()
    m.header.frame_id = "laser"
    m.header.stamp = Time(sec=5, nanosec=250)
    return m


def cloud() -> Any:
    c = stamped(PointCloud2)
    c.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                for i, n in enumerate(("x", "y", "z", "intensity"))]
    c.height, c.width, c.point_step = 1, len(POINTS), 16
    c.row_step = 16 * len(POINTS)
    c.data = b"".join(struct.pack("<4f", *p) for p in POINTS)
    c.is_dense = True
    return c


def check(out: Any, given: Any) -> dict[str, Any]:
    data = serialize_message(out)
    back = deserialize_message(data, type(out))
    report = {"type": type(out) is type(given),
              "serialized": serialize_message(back) == data and len(data) > 0}
    target = out.header if hasattr(out, "header") else out.position
    if hasattr(out, "header"):
        target.frame_id = "renamed"  # what a ROS node does with a result
        report["set"] = out.header.frame_id == "renamed"
    else:
        target.x = 9.0
        report["set"] = out.position.x == 9.0
    return report


def values(t: Any, inner: Any, with_cov: Any, polygon: Any) -> dict[str, Any]:
    """The numbers of the transform, pose-with-covariance and polygon results, for the
    test to check against the hand-computed transform."""
    tr = geometry.do_transform_transform(inner, t)
    pc = geometry.do_transform_pose_with_covariance_stamped(with_cov, t)
    pg = geometry.do_transform_polygon_stamped(polygon, t)
    v, q = tr.transform.translation, tr.transform.rotation
    p, o = pc.pose.pose.position, pc.pose.pose.orientation
    return {"transform": [tr.header.frame_id, tr.child_frame_id, v.x, v.y, v.z,
                          q.x, q.y, q.z, q.w],
            "pose_with_covariance": [p.x, p.y, p.z, o.x, o.y, o.z, o.w,
                                     [float(c) for c in pc.pose.covariance]],
            "polygon": [[pt.x, pt.y, pt.z] for pt in pg.polygon.points]}


def main() -> None:
    t = transform()
    point = stamped(PointStamped)
    point.point.x = 1.0
    vector = stamped(Vector3Stamped)
    vector.vector.y = 1.0
    pose = stamped(PoseStamped)
    pose.pose.orientation.w = 1.0
    plain = Pose()
    plain.position.x = 1.0
    wrench = stamped(WrenchStamped)
    wrench.wrench.force.x = 3.0
    inner = stamped(TransformStamped)
    inner.child_frame_id = "tool"
    inner.transform.rotation.w = 1.0
    with_cov = stamped(PoseWithCovarianceStamped)
    with_cov.pose.pose.orientation.w = 1.0
    with_cov.pose.covariance = [float(i) for i in range(36)]
    polygon = stamped(PolygonStamped)
    polygon.polygon.points = [Point32(x=1.0), Point32(y=1.0)]
    cases = {
        "point": (geometry.do_transform_point, point),
        "vector3": (geometry.do_transform_vector3, vector),
        "pose_stamped": (geometry.do_transform_pose_stamped, pose),
        "pose": (geometry.do_transform_pose, plain),
        "wrench": (geometry.do_transform_wrench, wrench),
        "transform": (geometry.do_transform_transform, inner),
        "pose_with_covariance": (geometry.do_transform_pose_with_covariance_stamped, with_cov),
        "polygon": (geometry.do_transform_polygon_stamped, polygon),
        "cloud": (sensor.do_transform_cloud, cloud()),
    }
    results: dict[str, Any] = {}
    for name, (fn, given) in cases.items():
        results[name] = check(fn(given, t), given)
    buffer = tf2_ros.Buffer()
    buffer.set_transform(t, "side")
    for name, given in (("buffer.transform point", point),
                        ("buffer.transform pose_with_covariance", with_cov),
                        ("buffer.transform polygon", polygon),
                        ("buffer.transform cloud", cloud())):
        given.header.frame_id = "laser"
        results[name] = check(buffer.transform(given, "map"), given)
    out = sensor.do_transform_cloud(cloud(), t)
    results["cloud_points"] = [list(struct.unpack_from("<4f", bytes(out.data), 16 * i))
                               for i in range(out.width)]
    results["cloud_header"] = [out.header.frame_id, out.header.stamp.sec,
                               out.header.stamp.nanosec]
    results["values"] = values(t, inner, with_cov, polygon)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
