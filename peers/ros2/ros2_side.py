"""The rclpy side of benchmarks/bench_ros2.py: run with the ROS 2 venv's python.

    ros2_side.py send --batch B --lat-count N --lat-rate HZ --flood-seconds S
    ros2_side.py recv

Protocol (shared with bench_ros2.py's tfbus roles): every message's header.frame_id
names its phase ("warm", "lat", "tput", "done") and its stamp is the sender's
time.time_ns() when it was published. A sender prints READY, publishes "warm" at 20 Hz
until it reads "go" on stdin, then N "lat" messages at HZ, then "tput" messages as fast
as it can for S seconds, prints "SENT <lat> <tput>", then "done" at 20 Hz until SIGTERM.
A receiver prints READY, WARM at its first "warm" message, and at the first "done" one
JSON line {"lat_ns": [...], "tput_transforms": n, "tput_seconds": s} and exits.
"""

import json
import os
import signal
import sys
import threading
import time

os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)


def message(phase, batch):
    now = time.time_ns()
    out = []
    for i in range(batch):
        t = TransformStamped()
        t.header.stamp.sec, t.header.stamp.nanosec = divmod(now, 1_000_000_000)
        t.header.frame_id = phase
        t.child_frame_id = f"link_{i}"
        t.transform.translation.x = float(i)
        t.transform.rotation.w = 1.0
        out.append(t)
    return TFMessage(transforms=out)


def send(node, args):
    batch, n, rate, seconds = int(args[0]), int(args[1]), float(args[2]), float(args[3])
    pub = node.create_publisher(TFMessage, "/tf", TF_QOS)
    go = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
    print("READY", flush=True)
    while not go.is_set():
        pub.publish(message("warm", 1))
        go.wait(0.05)
    period = 1.0 / rate
    nxt = time.monotonic()
    for _ in range(n):
        nxt += period
        pub.publish(message("lat", batch))
        delay = nxt - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    sent, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        pub.publish(message("tput", batch))
        sent += 1
    print(f"SENT {n} {sent}", flush=True)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    while not stop:
        pub.publish(message("done", 1))
        time.sleep(0.05)


def recv(node):
    lat, state = [], {"tput": 0, "first": None, "last": None, "warm": False, "done": False}

    def cb(m):
        now = time.time_ns()
        if not m.transforms:
            return
        t = m.transforms[0]
        phase = t.header.frame_id
        if phase == "lat":
            lat.append(now - (t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec))
        elif phase == "tput":
            state["tput"] += len(m.transforms)
            state["first"] = state["first"] or now
            state["last"] = now
        elif phase == "warm" and not state["warm"]:
            state["warm"] = True
            print("WARM", flush=True)
        elif phase == "done":
            state["done"] = True

    node.create_subscription(TFMessage, "/tf", cb, TF_QOS)
    print("READY", flush=True)
    while not state["done"]:
        rclpy.spin_once(node, timeout_sec=0.1)
    seconds = (state["last"] - state["first"]) / 1e9 if state["first"] else 0.0
    print(json.dumps({"lat_ns": lat, "tput_transforms": state["tput"], "tput_seconds": seconds}),
          flush=True)


def main():
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(f"bench_{sys.argv[1]}")
    try:
        if sys.argv[1] == "send":
            send(node, sys.argv[2:])
        else:
            recv(node)
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
