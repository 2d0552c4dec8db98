"""A rospy node using ``tfbus.compat.tf2_ros`` in ROS 1's idiom (no node passed): run by
``tests/compat/test_compat_rospy.py`` under the project's Python with Debian's ROS 1
packages on ``sys.path`` (appended after the project's own). Prints one JSON line with
what it looked up, then ``READY``, and spins until SIGINT."""

from __future__ import annotations

import json
import sys

sys.path.append("/usr/lib/python3/dist-packages")

import geometry_msgs.msg  # type: ignore[import-not-found]
import rospy  # type: ignore[import-not-found]

from tfbus.compat import tf2_py, tf2_ros


def main() -> None:
    rospy.init_node("compat_probe")
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    static = tf2_ros.StaticTransformBroadcaster()
    ts = geometry_msgs.msg.TransformStamped()
    ts.header.stamp = rospy.Time(7, 5)
    ts.header.frame_id = "map"
    ts.child_frame_id = "probe"
    ts.transform.translation.x = 4.0
    ts.transform.rotation.w = 1.0
    static.sendTransform(ts)
    # blocking, as ROS 1 code calls it right after start-up: waits for the publisher
    t = buffer.lookup_transform("map", "laser", rospy.Time(0), rospy.Duration(30.0))
    core = tf2_py.BufferCore()
    core.set_transform(t, "probe")
    latest = core.get_latest_common_time("map", "laser")
    tr, q = t.transform.translation, t.transform.rotation
    print(json.dumps({
        "type": f"{type(t).__module__}.{type(t).__name__}",
        "stamp": [t.header.stamp.secs, t.header.stamp.nsecs],
        "stamp_type": type(t.header.stamp).__name__,
        "latest": [latest.secs, latest.nsecs],
        "translation": [tr.x, tr.y, tr.z],
        "rotation": [q.x, q.y, q.z, q.w],
        "can": buffer.can_transform("map", "laser", rospy.Time(0), rospy.Duration(1.0)),
    }), flush=True)
    print("READY", flush=True)
    rospy.spin()


if __name__ == "__main__":
    main()
