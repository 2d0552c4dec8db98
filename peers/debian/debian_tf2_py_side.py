"""Debian's ROS 1 ``tf2_py`` (the C++ ``tf2::BufferCore``) fed a recorded ``/tf`` and
``/tf_static`` stream: run by ``tests/compat/test_compat_programs_rclpy.py`` under Debian's
``/usr/bin/python3``, never imported.

Reads one JSON object on stdin::

    {"messages": [{"topic": "/tf" | "/tf_static", "transforms": [{"parent", "child",
                   "stamp": [sec, nanosec], "t": [x, y, z], "r": [x, y, z, w]}, ...]}, ...],
     "authority": "default_authority",
     "lookups": [[target_frame, source_frame, [sec, nanosec]], ...]}

(the messages as ``peers/ros2/tf_peer.py --echo`` prints them), gives every transform
to ``BufferCore.set_transform`` / ``set_transform_static`` under ``authority`` as ROS 2's
``tf2_ros.TransformListener`` does, and prints one JSON line: ``{"yaml":
all_frames_as_yaml(), "lookups": [{"t": [...], "r": [...], "stamp": [sec, nanosec]} or
{"error": exception class name}, ...]}``.
"""

import json
import sys

sys.path.append("/usr/lib/python3/dist-packages")

import rospy
import tf2_py
from geometry_msgs.msg import TransformStamped


def main() -> None:
    job = json.load(sys.stdin)
    core = tf2_py.BufferCore(rospy.Duration(10.0))
    authority = job.get("authority", "default_authority")
    for message in job["messages"]:
        for d in message["transforms"]:
            t = TransformStamped()
            t.header.frame_id, t.child_frame_id = d["parent"], d["child"]
            t.header.stamp = rospy.Time(int(d["stamp"][0]), int(d["stamp"][1]))
            tr, r = t.transform.translation, t.transform.rotation
            tr.x, tr.y, tr.z = (float(v) for v in d["t"])
            r.x, r.y, r.z, r.w = (float(v) for v in d["r"])
            if message["topic"] == "/tf_static":
                core.set_transform_static(t, authority)
            else:
                core.set_transform(t, authority)
    answers = []
    for target, source, (sec, nanosec) in job.get("lookups", []):
        try:
            t = core.lookup_transform_core(target, source, rospy.Time(sec, nanosec))
        except tf2_py.TransformException as exc:
            answers.append({"error": type(exc).__name__})
            continue
        tr, r = t.transform.translation, t.transform.rotation
        answers.append({"t": [tr.x, tr.y, tr.z], "r": [r.x, r.y, r.z, r.w],
                        "stamp": [t.header.stamp.secs, t.header.stamp.nsecs]})
    print(json.dumps({"yaml": core.all_frames_as_yaml(), "lookups": answers}), flush=True)


if __name__ == "__main__":
    main()
