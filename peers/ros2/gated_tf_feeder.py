"""A real rclpy ``/tf`` publisher that starts publishing only when told (SIGUSR1): run by
``tests/compat/test_compat_programs_rclpy.py`` with the ROS 2 venv's python, never imported.

    gated_tf_feeder.py F.json [--rate HZ]

F holds transforms as ``tf_peer.py`` takes them (``parent``, ``child``, ``t``, ``r``; no
stamp). Prints ``READY`` once its publisher exists and ``SUBSCRIBERS n`` whenever the number
of ``/tf`` subscriptions it matched changes; after SIGUSR1 it publishes them in one
``TFMessage`` at HZ (30 by default), each stamped with the node's clock when sent, as
examples_tf2_py's ``dynamic_broadcaster`` does from joint states. Ends on SIGINT/SIGTERM.
"""

import argparse
import json
import signal
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("transforms")
    ap.add_argument("--rate", type=float, default=30.0)
    args = ap.parse_args()
    with open(args.transforms) as f:
        entries = json.load(f)
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    state = {"stop": False, "go": False}
    signal.signal(signal.SIGTERM, lambda *_: state.update(stop=True))
    signal.signal(signal.SIGINT, lambda *_: state.update(stop=True))
    signal.signal(signal.SIGUSR1, lambda *_: state.update(go=True))
    node = rclpy.create_node("gated_tf_feeder")
    pub = node.create_publisher(TFMessage, "/tf", TF_QOS)
    print("READY", flush=True)
    seen = -1
    period = 1.0 / args.rate
    deadline = time.monotonic() + 600.0  # a test never needs longer
    while not state["stop"] and time.monotonic() < deadline:
        n = pub.get_subscription_count()
        if n != seen:
            seen = n
            print(f"SUBSCRIBERS {n}", flush=True)
        if state["go"]:
            now = node.get_clock().now().to_msg()
            msg = TFMessage()
            for d in entries:
                t = TransformStamped()
                t.header.stamp = now
                t.header.frame_id, t.child_frame_id = d["parent"], d["child"]
                tr, r = t.transform.translation, t.transform.rotation
                tr.x, tr.y, tr.z = (float(v) for v in d["t"])
                r.x, r.y, r.z, r.w = (float(v) for v in d["r"])
                msg.transforms.append(t)
            pub.publish(msg)
        time.sleep(period)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
