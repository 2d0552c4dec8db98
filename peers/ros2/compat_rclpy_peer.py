"""An rclpy process using ``tfbus.compat.tf2_ros`` as ROS 2 code uses ``tf2_ros``.

Also: ``wait_for_transform_async`` and ``lookup_transform_async`` as rclpy Futures (one
awaited in a timer's coroutine callback) and a working ``timeout``. Run by
``tests/compat/test_compat_rclpy.py`` under the ROS 2 venv's python (real rclpy wheels).
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
from rclpy.duration import Duration
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
    buffer = tf2_ros.Buffer(node=listener)
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
    if answer is None:
        return 3
    out = {
        "frame_id": answer.header.frame_id,
        "child_frame_id": answer.child_frame_id,
        "stamp_ns": answer.header.stamp.sec * 1_000_000_000 + answer.header.stamp.nanosec,
        "translation": [answer.transform.translation.x, answer.transform.translation.y,
                        answer.transform.translation.z],
        "type": type(answer).__module__ + "." + type(answer).__name__,
    }
    # ROS 2's non-blocking waits: an rclpy Future completed when the data arrive
    k = 100
    future = buffer.wait_for_transform_async("map", "laser", Time(seconds=k + 1))
    out["future_type"] = type(future).__module__ + "." + type(future).__name__
    out["done_before"] = future.done()
    caster.sendTransform([msg("map", "base", Time(seconds=k + 1), 7.0)])
    executor.spin_until_future_complete(future, timeout_sec=WAIT)
    out["wait_result"] = future.result() if future.done() else None
    # awaited inside an rclpy coroutine callback (a timer's)
    got: list[object] = []

    async def in_callback() -> None:
        if got:
            return
        got.append(None)
        try:
            t = await buffer.lookup_transform_async("map", "laser", Time(seconds=k + 2))
        except Exception as exc:  # reported in the JSON line
            got[0] = repr(exc)
        else:
            got[0] = t.transform.translation.x

    # on the talker node (the listener's node works too: its subscriptions have their own
    # ReentrantCallbackGroup, as tf2_ros's; examples_tf2_py's async waiter does that)
    timer = talker.create_timer(0.05, in_callback)
    deadline = time.monotonic() + WAIT
    while not got and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    caster.sendTransform([msg("map", "base", Time(seconds=k + 2), 8.0)])
    while got[0] is None and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    timer.cancel()
    out["awaited_x"] = got[0]
    # a timeout that works
    late = buffer.lookup_transform_async("map", "nowhere", Time(seconds=0),
                                         timeout=Duration(seconds=0.3))
    executor.spin_until_future_complete(late, timeout_sec=WAIT)
    out["timeout_error"] = type(late.exception()).__name__ if late.done() else None
    for node in (talker, listener):
        node.destroy_node()
    rclpy.shutdown()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
