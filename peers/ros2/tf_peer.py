"""A real ROS 2 tf peer for tests/transports/test_ros2.py (rclpy + rmw_fastrtps_cpp).

Run it with the ROS 2 venv's python (scripts/install/install_ros2_env.sh), never import it:

    tf_peer.py --echo                          print every /tf and /tf_static message
    tf_peer.py --publish F.json [--static] [--rate HZ]   publish F's transforms
    tf_peer.py [--tf-static S.json] [--tf D.json] [--rate HZ]   a robot's broadcasters

--echo prints one JSON line per received TFMessage, at once (flushed):
    {"topic": "/tf", "transforms": [{"parent", "child", "stamp": [sec, nanosec],
                                     "t": [x, y, z], "r": [x, y, z, w]}, ...]}
--publish publishes ONE TFMessage holding all of F's entries (same JSON form, "stamp"
given explicitly, so edge stamps can be sent): on /tf at --rate Hz until stopped, or with
--static once on /tf_static (tf2_ros' StaticTransformBroadcaster QoS).
--tf-static / --tf behave as tf2_ros' broadcasters in a node: S's entries once on
/tf_static in one message, D's on /tf at --rate Hz, each stamped with the node's clock
at the time it is sent (entries need no "stamp"). Both may be given, with --echo too.
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
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

# tf2_ros/qos.hpp: DynamicBroadcasterQoS / DynamicListenerQoS, Static*QoS
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
STATIC_PUB_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL,
                            history=HistoryPolicy.KEEP_LAST)
STATIC_SUB_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL,
                            history=HistoryPolicy.KEEP_LAST)


def to_msg(d, now=None):
    t = TransformStamped()
    if now is not None:
        t.header.stamp = now
    else:
        t.header.stamp.sec, t.header.stamp.nanosec = int(d["stamp"][0]), int(d["stamp"][1])
    t.header.frame_id, t.child_frame_id = d["parent"], d["child"]
    # float(): this rclpy build stores a Python int in a float64 field as raw bits
    tr, r = t.transform.translation, t.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in d["t"])
    r.x, r.y, r.z, r.w = (float(v) for v in d["r"])
    return t


def to_dict(t):
    tr, r = t.transform.translation, t.transform.rotation
    return {"parent": t.header.frame_id, "child": t.child_frame_id,
            "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
            "t": [tr.x, tr.y, tr.z], "r": [r.x, r.y, r.z, r.w]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--echo", action="store_true")
    ap.add_argument("--publish")
    ap.add_argument("--static", action="store_true")
    ap.add_argument("--tf-static", dest="tf_static")
    ap.add_argument("--tf", dest="tf_file")
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--duration", type=float, default=120.0)
    a = ap.parse_args()
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    node = rclpy.create_node("tfbus_test_peer")

    def echo(topic):
        def cb(m):
            line = json.dumps({"topic": topic, "transforms": [to_dict(t) for t in m.transforms]})
            print(line, flush=True)
        return cb

    if a.echo:
        node.create_subscription(TFMessage, "/tf", echo("/tf"), TF_QOS)
        node.create_subscription(TFMessage, "/tf_static", echo("/tf_static"), STATIC_SUB_QOS)
    pub = msg = None
    if a.publish:
        with open(a.publish) as f:
            msg = TFMessage(transforms=[to_msg(d) for d in json.load(f)])
        pub = node.create_publisher(TFMessage, "/tf_static" if a.static else "/tf",
                                    STATIC_PUB_QOS if a.static else TF_QOS)
        if a.static:
            pub.publish(msg)
    if a.tf_static:
        with open(a.tf_static) as f:
            statics = json.load(f)
        static_pub = node.create_publisher(TFMessage, "/tf_static", STATIC_PUB_QOS)
        now = node.get_clock().now().to_msg()
        static_pub.publish(TFMessage(transforms=[to_msg(d, now) for d in statics]))
    dynamic, dynamic_pub = [], None
    if a.tf_file:
        with open(a.tf_file) as f:
            dynamic = json.load(f)
        dynamic_pub = node.create_publisher(TFMessage, "/tf", TF_QOS)
    print("READY", flush=True)
    end, period, nxt = time.monotonic() + a.duration, 1.0 / a.rate, 0.0
    while not stop and time.monotonic() < end:
        if time.monotonic() >= nxt:
            if pub is not None and not a.static:
                pub.publish(msg)
            if dynamic_pub is not None:
                now = node.get_clock().now().to_msg()
                dynamic_pub.publish(TFMessage(transforms=[to_msg(d, now) for d in dynamic]))
            nxt = time.monotonic() + period
        rclpy.spin_once(node, timeout_sec=min(period, 0.02))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
