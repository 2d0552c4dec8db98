"""Every ``do_transform_*`` and ``Buffer.transform`` path of ``tfbus.compat`` on rospy
messages (Debian's ROS 1 message packages appended to ``sys.path``, in the project's
Python), beside Debian's own ``tf2_sensor_msgs.do_transform_cloud``: run by
``tests/compat/test_compat_ros_messages.py``.

For each path the result must be an instance of the class given (a rospy message), take
a field assignment as a ROS node makes one (``out.header.frame_id = ...``), serialize
(genpy ``serialize``) and read back to the same bytes; the cloud's bytes must equal Debian's
``do_transform_cloud``'s. Prints one JSON line: path -> {"type", "set", "serialized",
"equal"}.
"""

from __future__ import annotations

import io
import json
import sys
from typing import Any

sys.path.append("/usr/lib/python3/dist-packages")

import rospy  # type: ignore[import-not-found]
import tf2_sensor_msgs as debian_sensor  # type: ignore[import-not-found]
from geometry_msgs.msg import (  # type: ignore[import-not-found]
    Point32,
    PointStamped,
    PolygonStamped,
    PoseStamped,
    PoseWithCovarianceStamped,
    TransformStamped,
    Vector3Stamped,
    WrenchStamped,
)
from sensor_msgs import point_cloud2  # type: ignore[import-not-found]
from sensor_msgs.msg import PointField  # type: ignore[import-not-found]
from std_msgs.msg import Header  # type: ignore[import-not-found]

from tfbus.compat import tf2_geometry_msgs as geometry
from tfbus.compat import tf2_ros
from tfbus.compat import tf2_sensor_msgs as sensor


def transform() -> Any:
    t = TransformStamped()
    t.header.frame_id = "map"
    t.header.stamp = rospy.Time(5, 250)
    t.child_frame_id = "laser"
    t.transform.translation.x, t.transform.translation.y = 1.0, 2.0
    t.transform.translation.z = 0.5
    t.transform.rotation.z, t.transform.rotation.w = 0.6, 0.8  # a turn about z
    return t


def stamped(cls: Any) -> Any:
    m = cls()
    m.header.frame_id = "laser"
    m.header.stamp = rospy.Time(5, 250)
    return m


def cloud() -> Any:
    header = Header(frame_id="laser", stamp=rospy.Time(5, 250))
    fields = [PointField("x", 0, PointField.FLOAT32, 1),
              PointField("y", 4, PointField.FLOAT32, 1),
              PointField("z", 8, PointField.FLOAT32, 1),
              PointField("intensity", 12, PointField.FLOAT32, 1)]
    points = [(1.0, 0.0, 0.0, 7.0), (0.0, 2.0, 0.5, 8.0), (-1.5, 0.25, 3.0, 9.0)]
    return point_cloud2.create_cloud(header, fields, points)


def check(out: Any, given: Any) -> dict[str, Any]:
    buf = io.BytesIO()
    out.serialize(buf)
    back = type(out)()
    back.deserialize(buf.getvalue())
    again = io.BytesIO()
    back.serialize(again)  # float32 fields round on the wire: compare the bytes
    report = {"type": type(out) is type(given),
              "serialized": again.getvalue() == buf.getvalue() and len(buf.getvalue()) > 0}
    out.header.frame_id = "renamed"  # what a ROS node does with a result
    report["set"] = out.header.frame_id == "renamed"
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
    results: dict[str, Any] = {}
    point = stamped(PointStamped)
    point.point.x = 1.0
    vector = stamped(Vector3Stamped)
    vector.vector.y = 1.0
    pose = stamped(PoseStamped)
    pose.pose.orientation.w = 1.0
    wrench = stamped(WrenchStamped)
    wrench.wrench.force.x = 3.0
    inner = stamped(TransformStamped)
    inner.child_frame_id = "tool"
    inner.transform.rotation.w = 1.0
    with_cov = stamped(PoseWithCovarianceStamped)
    with_cov.pose.pose.orientation.w = 1.0
    with_cov.pose.covariance = [float(i) for i in range(36)]
    polygon = stamped(PolygonStamped)
    polygon.polygon.points = [Point32(1.0, 0.0, 0.0), Point32(0.0, 1.0, 0.0)]
    given_cloud = cloud()
    cases = {
        "point": (geometry.do_transform_point, point),
        "vector3": (geometry.do_transform_vector3, vector),
        "pose": (geometry.do_transform_pose, pose),
        "wrench": (geometry.do_transform_wrench, wrench),
        "transform": (geometry.do_transform_transform, inner),
        "pose_with_covariance": (geometry.do_transform_pose_with_covariance_stamped, with_cov),
        "polygon": (geometry.do_transform_polygon_stamped, polygon),
        "cloud": (sensor.do_transform_cloud, given_cloud),
    }
    for name, (fn, given) in cases.items():
        results[name] = check(fn(given, t), given)
    # The same through Buffer.transform (the registered functions), point and cloud.
    buffer = tf2_ros.Buffer()
    buffer.set_transform(t, "side")
    for name, given in (("buffer.transform point", point),
                        ("buffer.transform pose_with_covariance", with_cov),
                        ("buffer.transform polygon", polygon),
                        ("buffer.transform cloud", cloud())):
        given.header.frame_id = "laser"
        results[name] = check(buffer.transform(given, "map"), given)
    # The cloud's bytes equal Debian's tf2_sensor_msgs (Eigen, float32 stores).
    ours = sensor.do_transform_cloud(cloud(), t)
    theirs = debian_sensor.do_transform_cloud(cloud(), t)
    results["cloud"]["equal"] = (
        ours.data == theirs.data and ours.fields == theirs.fields
        and ours.header == theirs.header and ours.point_step == theirs.point_step
        and ours.row_step == theirs.row_step and ours.width == theirs.width)
    results["cloud"]["points"] = [list(p) for p in point_cloud2.read_points(ours)]
    results["values"] = values(t, inner, with_cov, polygon)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
