"""A real ROS 2 simulated-time peer for tests/transports/test_ros2.py (rclpy +
rmw_fastrtps_cpp).

Run it with the ROS 2 venv's python (scripts/install/install_ros2_env.sh), never import it:

    clock_peer.py --simulate START --factor F --tf D.json
        a simulator: every 10 ms of wall time, simulated time advances by F * 10 ms
        (START seconds at first); each step publishes /clock (rclcpp::ClockQoS: best
        effort, keep-last 1) and then D's transforms on /tf stamped with that simulated
        time (tf2_ros' DynamicBroadcasterQoS), as a simulator's robot does.
    clock_peer.py --follow
        a node with the ``use_sim_time`` parameter true: prints {"now": [sec, nanosec]}
        each time its ``get_clock().now()`` changes (the time rclpy's TimeSource took
        from /clock).

Prints READY once its endpoints exist; exits cleanly on SIGTERM/SIGINT.
"""

import argparse
import json
import os
import signal
import sys
import time

os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from tf2_msgs.msg import TFMessage

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
# rclcpp::ClockQoS: rmw_qos_profile_sensor_data with depth 1
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
STEP = 0.01  # wall seconds between two /clock messages
NSEC = 1_000_000_000


def to_msg(d, sec, nanosec):
    t = TransformStamped()
    t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
    t.header.frame_id, t.child_frame_id = d["parent"], d["child"]
    tr, r = t.transform.translation, t.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in d["t"])
    r.x, r.y, r.z, r.w = (float(v) for v in d["r"])
    return t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--simulate", type=float)
    ap.add_argument("--factor", type=float, default=10.0)
    ap.add_argument("--tf", dest="tf_file")
    ap.add_argument("--follow", action="store_true")
    ap.add_argument("--duration", type=float, default=120.0)
    a = ap.parse_args()
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    params = [Parameter("use_sim_time", Parameter.Type.BOOL, True)] if a.follow else []
    node = rclpy.create_node("tfbus_clock_peer", parameter_overrides=params)
    clock_pub = tf_pub = None
    dynamic = []
    if a.simulate is not None:
        clock_pub = node.create_publisher(Clock, "/clock", CLOCK_QOS)
        if a.tf_file:
            with open(a.tf_file) as f:
                dynamic = json.load(f)
            tf_pub = node.create_publisher(TFMessage, "/tf", TF_QOS)
    print("READY", flush=True)
    sim_ns = round(a.simulate * NSEC) if a.simulate is not None else 0
    step_ns = round(a.factor * STEP * NSEC)
    end, nxt, last = time.monotonic() + a.duration, 0.0, None
    while not stop and time.monotonic() < end:
        if clock_pub is not None and time.monotonic() >= nxt:
            sec, nanosec = divmod(sim_ns, NSEC)
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = sec, nanosec
            clock_pub.publish(msg)
            if tf_pub is not None:
                tf_pub.publish(TFMessage(transforms=[to_msg(d, sec, nanosec) for d in dynamic]))
            sim_ns += step_ns
            nxt = time.monotonic() + STEP
        rclpy.spin_once(node, timeout_sec=STEP if clock_pub is not None else 0.02)
        if a.follow:
            now = node.get_clock().now().seconds_nanoseconds()
            if now != last:
                print(json.dumps({"now": list(now)}), flush=True)
                last = now
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
