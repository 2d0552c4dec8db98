"""The ROS 1 half of ``bench_robot_state.py``: the real robot_state_publisher's cost.

Runs under Debian's ``/usr/bin/python3`` (rospy), never imports tfbus. Reads the scenario
as JSON on stdin ({"urdf": path, "states": [[stamp_ns, names, positions], ...],
"rate": Hz}), starts a private roscore on 127.0.0.1 (free port, private ROS_HOME) and the
node (``ignore_timestamp``: every state is published), sends the states at ``rate``, and
prints one JSON object: transforms the node published, the node's CPU seconds (user +
system, ``/proc/PID/stat``) while doing it, and wall seconds. Every wait is bounded; the
node and roscore are stopped by PID.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

NODE = "/usr/lib/robot_state_publisher/robot_state_publisher"


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main() -> None:
    scenario: dict[str, Any] = json.load(sys.stdin)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    home = tempfile.mkdtemp(prefix="rsp_bench_")
    os.environ.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_IP="127.0.0.1",
                      ROS_HOME=home, ROS_LOG_DIR=f"{home}/log")
    os.environ.pop("ROS_HOSTNAME", None)
    core = subprocess.Popen(["/usr/bin/roscore", "-p", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    node = None
    try:
        import rosgraph  # type: ignore[import-not-found]
        import rospy  # type: ignore[import-not-found]
        from sensor_msgs.msg import JointState  # type: ignore[import-not-found]
        from tf2_msgs.msg import TFMessage  # type: ignore[import-not-found]

        deadline = time.monotonic() + 30
        while not rosgraph.is_master_online():
            if time.monotonic() > deadline:
                raise RuntimeError("roscore did not come up")
            time.sleep(0.2)
        rospy.init_node("rsp_bench", disable_signals=True)
        with open(scenario["urdf"]) as f:
            rospy.set_param("/robot_description", f.read())
        counts = {"messages": 0, "transforms": 0}

        def on_tf(msg: Any) -> None:
            counts["messages"] += 1
            counts["transforms"] += len(msg.transforms)

        rospy.Subscriber("/tf", TFMessage, on_tf, queue_size=10000)
        pub = rospy.Publisher("/joint_states", JointState, queue_size=10000)
        with open(f"{home}/node.err", "w") as err_file:
            node = subprocess.Popen(
                [NODE, "__name:=robot_state_publisher", "_ignore_timestamp:=true"],
                stdout=subprocess.DEVNULL, stderr=err_file, start_new_session=True)
        while pub.get_num_connections() < 1:
            if time.monotonic() > deadline + 30:
                with open(f"{home}/node.err") as err:
                    raise RuntimeError(f"the node did not subscribe: {err.read()[-500:]}")
            time.sleep(0.05)
        time.sleep(1.0)
        msgs = []
        for stamp, names, positions in scenario["states"]:
            m = JointState(name=names, position=positions)
            m.header.stamp = rospy.Time(stamp // 10**9, stamp % 10**9)
            msgs.append(m)
        period = 1.0 / scenario["rate"]
        cpu0, wall0 = cpu_seconds(node.pid), time.monotonic()
        for k, m in enumerate(msgs):
            pub.publish(m)
            pause = wall0 + (k + 1) * period - time.monotonic()
            if pause > 0:
                time.sleep(pause)
        end = time.monotonic() + 5
        while counts["messages"] < len(msgs) and time.monotonic() < end:
            time.sleep(0.05)
        cpu1, wall1 = cpu_seconds(node.pid), time.monotonic()
        json.dump({"sent": len(msgs), **counts, "cpu_s": cpu1 - cpu0,
                   "wall_s": wall1 - wall0}, sys.stdout)
        rospy.signal_shutdown("done")
    finally:
        if node is not None:
            stop(node)
        stop(core)


if __name__ == "__main__":
    main()
