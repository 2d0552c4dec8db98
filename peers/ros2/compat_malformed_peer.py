"""An rclpy process whose ``tfbus.compat.tf2_ros`` listener is sent, among valid
``/tf`` messages, some it cannot decode and one transform the buffer must refuse.

Node ``compat_sender`` publishes on ``/tf``, with tf2's QoS, serialized ``TFMessage``s
(rclpy's ``publish`` of bytes), in this order:

1. ``map -> base`` at 1 s, x = 1;
2. ``map -> base`` at sec = -5 (valid CDR; a time before 1970);
3. ``map -> base`` whose child frame id is ``b"base\\xff"`` (not UTF-8);
4. message 1 cut 9 bytes short (truncated);
5. ``map -> ghost`` at 1 s with x = NaN, and ``base -> laser`` at 1 s, x = 0.5;
6. ``map -> base`` and ``base -> laser`` at 2 s, x = 2 and 0.5.

Node ``compat_receiver`` holds a compat ``Buffer`` and ``TransformListener(buffer,
node)``. Both are spun (at most ``WAIT`` seconds) until ``map <- laser`` at 2 s can be
looked up (message 6 came, so every earlier one was taken: one reliable writer, one
reader). One JSON line is printed. Run by ``tests/compat/test_compat_rclpy.py`` under the
ROS 2 venv's python (real rclpy wheels). Exit status 3 when message 6 never came.
"""

from __future__ import annotations

import json
import math
import sys
import time

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import TransformStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from rclpy.time import Time
from tf2_msgs.msg import TFMessage

from tfbus.compat import tf2_ros

WAIT = 20.0


def tf(parent: str, child: str, sec: int, x: float) -> TransformStamped:
    m = TransformStamped()
    m.header.frame_id = parent
    m.header.stamp = TimeMsg(sec=sec, nanosec=0)
    m.child_frame_id = child
    m.transform.translation.x = x
    m.transform.rotation.w = 1.0
    return m


def wire(*transforms: TransformStamped) -> bytes:
    data: bytes = serialize_message(TFMessage(transforms=list(transforms)))
    return data


def main() -> int:
    rclpy.init()
    sender = rclpy.create_node("compat_sender")
    receiver = rclpy.create_node("compat_receiver")
    buffer = tf2_ros.Buffer(node=receiver)
    listener = tf2_ros.TransformListener(buffer, receiver)
    publisher = sender.create_publisher(TFMessage, "/tf", QoSProfile(depth=100))
    executor = SingleThreadedExecutor()
    executor.add_node(sender)
    executor.add_node(receiver)
    deadline = time.monotonic() + WAIT
    while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    first = wire(tf("map", "base", 1, 1.0))
    not_utf8 = wire(tf("map", "baseX", 1, 1.0)).replace(b"baseX\x00", b"base\xff\x00")
    for data in (
        first,
        wire(tf("map", "base", -5, 1.0)),
        not_utf8,
        first[:-9],
        wire(tf("map", "ghost", 1, math.nan), tf("base", "laser", 1, 0.5)),
        wire(tf("map", "base", 2, 2.0), tf("base", "laser", 2, 0.5)),
    ):
        publisher.publish(data)
    answer = None
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if buffer.can_transform("map", "laser", Time(seconds=2)):
            answer = buffer.lookup_transform("map", "laser", Time(seconds=1.5))
            break
    if answer is None:
        return 3
    out = {
        "malformed": listener.malformed,
        "map_laser_x_at_1.5": answer.transform.translation.x,
        "ghost": buffer.can_transform("map", "ghost", Time(seconds=1)),
        "yaml": buffer.all_frames_as_yaml(),
    }
    for node in (sender, receiver):
        node.destroy_node()
    rclpy.shutdown()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
