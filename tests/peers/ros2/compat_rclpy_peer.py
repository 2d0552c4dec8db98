"""An rclpy process using ``tfbus.compat.tf2_ros`` as ROS 2 code uses ``tf2_ros``.

Run by ``tests/compat/test_compat_rclpy.py`` under the ROS 2 venv's python (real rclpy wheels).
Node ``talker`` sends, with the compat broadcasters, a static ``base -> laser`` and a
dynamic ``map -> base`` (real ``geometry_msgs`` messages, rclpy stamps); node
``listener`` holds a compat ``Buffer`` and ``TransformListener(buffer, node)``. Both are
spun (at most ``WAIT`` seconds) until ``map <- laser`` can be looked up; the answer is
printed as one JSON line. Exit status 3 when it never came.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.time import Time

from tfbus.compat import tf2_ros

WAIT = 20.0


def msg(parent: str, child: str, stamp: Time, x: float) -> TransformStamped:
    m = TransformStamped()
    m.header.frame_id = parent
    m.header.stamp = stamp.to_msg()
    m.child_frame_id = child
    m.transform.translation.x = x
    m.transform.rotation.w = 1.0
    return m


def main() -> int:
    rclpy.init()
    talker = rclpy.create_node("compat_talker")
    listener = rclpy.create_node("compat_listener")
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer, listener)
    tf2_ros.StaticTransformBroadcaster(talker).sendTransform(
        msg("base", "laser", Time(seconds=0), 0.5)
    )
    caster = tf2_ros.TransformBroadcaster(talker)
    executor = SingleThreadedExecutor()
    executor.add_node(talker)
    executor.add_node(listener)
    deadline = time.monotonic() + WAIT
    k = 0
    answer = None
    while time.monotonic() < deadline:
        k += 1
        caster.sendTransform([msg("map", "base", Time(seconds=k), float(k))])
        executor.spin_once(timeout_sec=0.1)
        if k > 2 and buffer.can_transform("map", "laser", Time(seconds=2)):
            answer = buffer.lookup_transform("map", "laser", Time(seconds=2))
            break
    for node in (talker, listener):
        node.destroy_node()
    rclpy.shutdown()
    if answer is None:
        return 3
    print(json.dumps({
        "frame_id": answer.header.frame_id,
        "child_frame_id": answer.child_frame_id,
        "stamp_ns": answer.header.stamp.ns,
        "translation": list(answer.transform.translation),
        "type": type(answer).__module__ + "." + type(answer).__name__,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
