#!/usr/bin/python3
"""Record what ROS 1's real robot_state_publisher publishes, for tests/robot/test_robot_state.py.

Run with the system interpreter (ROS 1's rospy lives there, not in the venv)::

    /usr/bin/python3 scripts/data/record_robot_state.py                  # every URDF in the data
    /usr/bin/python3 scripts/data/record_robot_state.py --out DIR A.urdf B.urdf

Needs Debian's ROS 1 (``scripts/install/install_ros1_rsp.sh``). Everything stays on loopback:
a private roscore on 127.0.0.1 on a free port (``ROS_IP=127.0.0.1``, private
``ROS_HOME``). For each URDF it sets ``/robot_description``, starts ``rosrun
robot_state_publisher robot_state_publisher`` (``_publish_frequency:=20``), records the
node's ``/tf_static`` message, then publishes a fixed sequence of random joint states (all
joints, a subset, mimic leaders, unknown names, duplicates, a rate-limited stamp, an older
stamp, empty/mismatched positions, NaN, out-of-limit values) one at a time and records
the ``/tf`` message each one produced (``null`` when none came within 1.5 s). The node
keeps one message in its queue, so the next state is sent only after the previous answer.

Output: ``OUT/<urdf stem>.json.gz`` (see ``tests/robot/test_robot_state.py`` for the layout).
Every wait is bounded; roscore and the node are stopped by PID (SIGINT, then wait).
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import math
import os
import queue
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "urdf"
EXTRA = ROOT / "tests" / "data" / "rsp" / "extra_joints.urdf"
BASE_SEC = 1_700_000_000
FREQUENCY = 20.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def stop(proc: subprocess.Popen, timeout: float = 15.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def joints_of(path: Path) -> list[dict]:
    """Joints as the XML says (the recorder must not depend on tfbus)."""
    out = []
    for j in ET.parse(path).getroot().findall("joint"):
        limit, mimic = j.find("limit"), j.find("mimic")
        out.append({
            "name": j.get("name"), "type": j.get("type"),
            "lower": float(limit.get("lower", 0)) if limit is not None else None,
            "upper": float(limit.get("upper", 0)) if limit is not None else None,
            "mimic": mimic.get("joint") if mimic is not None else None,
        })
    return out


def cases(joints: list[dict], rng: random.Random) -> list[dict]:
    """The joint states sent, in order; stamps are whole seconds apart unless noted."""
    moving = [j for j in joints if j["type"] in ("revolute", "continuous", "prismatic")]
    leaders = [j for j in moving if not j["mimic"]]
    fixed = [j["name"] for j in joints if j["type"] in ("fixed", "planar", "floating")]
    mimic_leaders = sorted({j["mimic"] for j in moving if j["mimic"]})

    def value(j: dict, wide: bool = False) -> float:
        if j["type"] == "prismatic":
            return rng.uniform(-2.0, 2.0) if wide else rng.uniform(-0.3, 0.3)
        return rng.uniform(-10.0, 10.0) if wide else rng.uniform(-math.pi, math.pi)

    out: list[dict] = []
    sec = 0

    def add(label: str, names: list[str], positions: list[float], dt_ns: int | None = None,
            by_name: dict | None = None) -> None:
        nonlocal sec
        if dt_ns is None:
            sec += 1
            stamp = (BASE_SEC + sec) * 10**9 + rng.randrange(10**9)
        else:
            stamp = out[-1]["stamp_ns"] + dt_ns
        out.append({"label": label, "stamp_ns": stamp, "name": names, "position": positions})

    allj = moving[:]
    rng.shuffle(allj)
    add("all joints", [j["name"] for j in allj], [value(j) for j in allj])
    add("all joints again", [j["name"] for j in allj], [value(j) for j in allj])
    subset = rng.sample(leaders, max(1, len(leaders) // 3))
    add("a subset", [j["name"] for j in subset], [value(j) for j in subset])
    add("rate-limited (10 ms later)", [j["name"] for j in subset],
        [value(j) for j in subset], dt_ns=10_000_000)
    add("one interval after the last publish", [j["name"] for j in subset],
        [value(j) for j in subset], dt_ns=round(1e9 / FREQUENCY) - 10_000_000)
    if mimic_leaders:
        add("mimic leaders only", mimic_leaders, [rng.uniform(-0.5, 0.5) for _ in mimic_leaders])
        both = [j for j in moving if j["mimic"] or j["name"] in mimic_leaders]
        add("mimic joints given explicitly", [j["name"] for j in both], [value(j) for j in both])
    some = rng.sample(leaders, max(1, len(leaders) // 4))
    extra = ["no_such_joint", *fixed[:3]]
    add("unknown, fixed, planar and floating names", [*extra, *(j["name"] for j in some)],
        [rng.uniform(-1, 1) for _ in extra] + [value(j) for j in some])
    dup = rng.choice(leaders)
    add("a repeated name (first wins)", [dup["name"], dup["name"]], [value(dup), value(dup)])
    add("older stamp than the last publish", [dup["name"]], [value(dup)], dt_ns=-5 * 10**9)
    add("out of limits", [j["name"] for j in leaders], [value(j, wide=True) for j in leaders])
    add("empty position", [j["name"] for j in leaders[:2]], [])
    add("names and positions differ", [j["name"] for j in leaders[:2]], [0.1])
    nan = leaders[:3]
    add("NaN and Inf positions", [j["name"] for j in nan],
        [math.nan, *([math.inf] if len(nan) > 1 else []), *[value(j) for j in nan[2:]]])
    add("nothing known", ["no_such_joint"], [0.5])
    add("after all of that", [j["name"] for j in allj], [value(j) for j in allj])
    return out


def tf_rows(msg) -> list:
    return [[t.header.stamp.to_nsec(), t.header.frame_id, t.child_frame_id,
             [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
             [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
              t.transform.rotation.w]] for t in msg.transforms]


def start_roscore() -> subprocess.Popen:
    """A private roscore on 127.0.0.1 (free port, private ROS_HOME), up and answering."""
    port = free_port()
    home = Path(tempfile.mkdtemp(prefix="rsp_rec_"))
    os.environ.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_IP="127.0.0.1",
                      ROS_HOME=str(home), ROS_LOG_DIR=str(home / "log"))
    os.environ.pop("ROS_HOSTNAME", None)
    os.environ["PATH"] = "/usr/bin:" + os.environ.get("PATH", "")
    core = subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    import rosgraph

    deadline = time.monotonic() + 30
    while not rosgraph.is_master_online():
        if time.monotonic() > deadline or core.poll() is not None:
            stop(core)
            raise RuntimeError("roscore did not come up within 30 s")
        time.sleep(0.2)
    return core


def refusals(texts: dict[str, str], wait: float = 4.0) -> dict[str, list]:
    """For each robot description: does the real node refuse it? [exit status or
    "running" (still up after ``wait`` s), the node's first ERROR line]."""
    core = start_roscore()
    out: dict[str, list] = {}
    try:
        import rosgraph

        master = rosgraph.Master("/rsp_refusals")
        for name, text in texts.items():
            master.setParam("/robot_description", text)
            node = subprocess.Popen(["rosrun", "robot_state_publisher",
                                     "robot_state_publisher"], stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True,
                                    start_new_session=True)
            try:
                log, _ = node.communicate(timeout=wait)
                status: object = node.returncode
            except subprocess.TimeoutExpired:
                node.send_signal(signal.SIGINT)
                log, _ = node.communicate(timeout=15)
                status = "running"
            errors = [line for line in log.splitlines() if "[ERROR]" in line]
            out[name] = [status, errors[0] if errors else ""]
    finally:
        stop(core)
    return out


def record(urdfs: list[Path], out_dir: Path, seed: int, wait: float) -> list[Path]:
    core = start_roscore()
    written: list[Path] = []
    try:
        import rospy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Header
        from tf2_msgs.msg import TFMessage

        rospy.init_node("rsp_recorder", disable_signals=True)
        tf_q: queue.Queue = queue.Queue()
        static_q: queue.Queue = queue.Queue()
        rospy.Subscriber("/tf", TFMessage,
                         lambda m: tf_q.put((m._connection_header["callerid"], m)))
        rospy.Subscriber("/tf_static", TFMessage,
                         lambda m: static_q.put((m._connection_header["callerid"], m)))
        pub = rospy.Publisher("/joint_states", JointState, queue_size=10)
        version = subprocess.run(["dpkg-query", "-W", "-f", "${Version}",
                                  "ros-robot-state-publisher"], capture_output=True,
                                 text=True).stdout.strip()
        for k, urdf in enumerate(urdfs):
            rng = random.Random(f"{seed}:{urdf.name}")
            text = urdf.read_text()
            rospy.set_param("/robot_description", text)
            name = f"rsp_{k}"
            node = subprocess.Popen(
                ["rosrun", "robot_state_publisher", "robot_state_publisher",
                 f"__name:={name}", f"_publish_frequency:={FREQUENCY}"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
            try:
                static = None
                deadline = time.monotonic() + 30
                while static is None:
                    left = deadline - time.monotonic()
                    if left <= 0 or node.poll() is not None:
                        raise RuntimeError(f"{urdf.name}: no /tf_static from the node")
                    try:
                        caller, msg = static_q.get(timeout=min(left, 0.5))
                    except queue.Empty:
                        continue
                    if caller == f"/{name}":
                        static = msg
                while pub.get_num_connections() != 1:
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"{urdf.name}: the node did not subscribe")
                    time.sleep(0.05)
                time.sleep(0.5)  # the subscriber side of the connection settles
                rows = []
                for case in cases(joints_of(urdf), rng):
                    msg = JointState(header=Header(stamp=rospy.Time(
                        nsecs=case["stamp_ns"])), name=case["name"], position=case["position"])
                    pub.publish(msg)
                    got = None
                    end = time.monotonic() + wait
                    while got is None and time.monotonic() < end:
                        try:
                            caller, m = tf_q.get(timeout=0.05)
                        except queue.Empty:
                            continue
                        if caller == f"/{name}":
                            got = tf_rows(m)
                    rows.append({**case, "tf": got})
                    print(f"{urdf.name}: {case['label']}: "
                          f"{'none' if got is None else len(got)}", file=sys.stderr)
            finally:
                stop(node)
            blob = {
                "urdf": urdf.name,
                "sha256": hashlib.sha256(urdf.read_bytes()).hexdigest(),
                "node": f"ros-robot-state-publisher {version}",
                "publish_frequency": FREQUENCY,
                "recorded_at_ns": time.time_ns(),
                "static": {"stamp_ns": static.transforms[0].header.stamp.to_nsec()
                           if static.transforms else 0, "transforms": tf_rows(static)},
                "cases": rows,
            }
            out = out_dir / f"{urdf.stem}.json.gz"
            with gzip.open(out, "wt") as f:
                json.dump(blob, f, indent=0)
            written.append(out)
        rospy.signal_shutdown("done")
    finally:
        stop(core)
    return written


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("urdf", nargs="*", type=Path,
                        help="URDF files (default: tests/data/urdf/*.urdf + the extra one)")
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "rsp")
    parser.add_argument("--seed", type=int, default=15)
    parser.add_argument("--wait", type=float, default=1.5,
                        help="seconds to wait for the node's answer to one joint state")
    parser.add_argument("--refusals", action="store_true",
                        help="read {name: URDF text} as JSON on stdin, print {name: [exit "
                             "status or 'running', first ERROR line]} of the node for each")
    args = parser.parse_args()
    if args.refusals:
        json.dump(refusals(json.load(sys.stdin)), sys.stdout)
        return 0
    urdfs = args.urdf or [*sorted(DATA.glob("*.urdf")), EXTRA]
    args.out.mkdir(parents=True, exist_ok=True)
    for path in record(urdfs, args.out, args.seed, args.wait):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
