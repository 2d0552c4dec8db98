"""An rclpy process using ``tfbus.compat.tf2_ros`` under a node with ``use_sim_time``.

Node ``compat_simulator`` publishes ``/clock`` (``rosgraph_msgs/Clock``) from 100 s in
steps of 0.1 s, one ``/clock`` 2e9 s ahead among them, and ``map -> base`` on ``/tf`` stamped
with it (``x`` = the step's simulated seconds - 100). Node ``compat_sim_listener`` has the
parameter ``use_sim_time`` true and holds the ROS 2 tutorial's ``Buffer()`` and
``TransformListener(buffer, node)``; node ``compat_wall_listener`` the same without it.
Spun (at most ``WAIT`` seconds) until the simulated buffer can look ``base`` up at its
clock's ``now()`` past 101 s; then the last ``/clock`` is repeated until the rclpy node's
own clock reads it. One JSON line is printed. Run by
``tests/compat/test_compat_rclpy.py`` under the ROS 2 venv's python (real rclpy wheels).
Exit status 3 when it never came.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.time import Time
from rosgraph_msgs.msg import Clock

from tfbus.compat import tf2_ros

WAIT = 30.0
START_NS = 100_000_000_000
STEP_NS = 100_000_000


def tf(stamp_ns: int) -> TransformStamped:
    m = TransformStamped()
    m.header.frame_id = "map"
    m.header.stamp = Time(nanoseconds=stamp_ns).to_msg()
    m.child_frame_id = "base"
    m.transform.translation.x = (stamp_ns - START_NS) / 1e9
    m.transform.rotation.w = 1.0
    return m


def clock(sec: int, nanosec: int) -> Clock:
    c = Clock()
    c.clock.sec = sec
    c.clock.nanosec = nanosec
    return c


def main() -> int:
    rclpy.init()
    sim = rclpy.create_node("compat_simulator")
    listener = rclpy.create_node(
        "compat_sim_listener",
        parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, True)],
    )
    wall = rclpy.create_node("compat_wall_listener")
    buffer = tf2_ros.Buffer()  # the ROS 2 tutorial's form: no node, no clock
    tf2_ros.TransformListener(buffer, listener)
    wall_buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(wall_buffer, wall)
    node_buffer = tf2_ros.Buffer(node=listener)  # the node given to the buffer itself
    clock_pub = sim.create_publisher(Clock, "/clock", 10)
    caster = tf2_ros.TransformBroadcaster(sim)
    executor = SingleThreadedExecutor()
    for node in (sim, listener, wall):
        executor.add_node(node)
    sim_clock = buffer.buffer.clock
    deadline = time.monotonic() + WAIT
    k = 0
    now_ns = 0
    while time.monotonic() < deadline:
        k += 1
        now_ns = START_NS + k * STEP_NS
        caster.sendTransform(tf(now_ns))  # the transform of the step, then its time
        clock_pub.publish(clock(now_ns // 10**9, now_ns % 10**9))
        if k == 3:
            # absurdly far ahead (rclpy's own TimeSource follows it; a negative one would
            # raise in its callback): counted and dropped by the SimClock
            clock_pub.publish(clock(2_000_000_000, 0))
        for _ in range(8):  # one callback per spin_once: the step's, and any late ones
            executor.spin_once(timeout_sec=0.01)
        seen = sim_clock.now()
        if seen.ns > START_NS + 10 * STEP_NS and buffer.can_transform("map", "base", seen):
            break
    else:
        return 3
    # the last /clock again until the node's own clock (rclpy's TimeSource) reads it too
    while time.monotonic() < deadline:
        clock_pub.publish(clock(now_ns // 10**9, now_ns % 10**9))
        for _ in range(4):
            executor.spin_once(timeout_sec=0.01)
        if listener.get_clock().now().nanoseconds == now_ns == sim_clock.now().ns:
            break
    else:
        return 3
    found = buffer.lookup_transform("map", "base", Time(nanoseconds=now_ns))
    stats = sim_clock.statistics()
    print(json.dumps({
        "clock": type(sim_clock).__name__,
        "same_clock_for_node_buffer": node_buffer.buffer.clock is sim_clock,
        "now_ns": sim_clock.now().ns,
        "published_ns": now_ns,
        "rclpy_now_ns": listener.get_clock().now().nanoseconds,
        "x": found.transform.translation.x,
        "expected_x": (now_ns - START_NS) / 1e9,
        "dropped": stats.dropped,
        "jumps": stats.jumps,
        "wall_clock": type(wall_buffer.buffer.clock).__name__,
        "wall_now_after_2020": wall_buffer.buffer.clock.now().ns > 1_577_836_800 * 10**9,
    }), flush=True)
    for node in (sim, listener, wall):
        node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
