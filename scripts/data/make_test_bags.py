"""Write the project's own ROS 2 test recordings (``tests/data/SOURCES.md``):

* ``tests/data/nav2_like.mcap``: a bare MCAP file (profile ``ros2``, CDR, zstd chunks)
  written with the ``mcap`` package's writer, schemas from rosbags' ROS 2 typestore
  (so the file does not come from tfbus's own bag writer). A nav2-like TurtleBot-style
  tree in simulated time (stamps from 928 s, receive times ~1.78e9 s):

  - ``map -> odom`` at 8 Hz, stamped 0.1 s behind the sim clock (a localiser's output);
  - ``odom -> base_link`` at 25 Hz, the robot driving a circle (radius 2 m, 0.25 m/s);
  - ``base_link -> left_wheel`` and ``-> right_wheel`` at 20 Hz, one message, spinning;
  - one ``/tf_static`` message (transient-local QoS) holding 29 static edges;
  - ``/odom`` (nav_msgs/Odometry) at 5 Hz, a topic that is not tf.

  Every /tf message is its own broadcaster's, as in a real system; receive time = sim
  time + a fixed wall offset + 1..3 ms of seeded transport delay.
* ``tests/data/tf_example/``: a ROS 2 sqlite3 bag folder (rosbag2 metadata version 8,
  written with rosbags' Writer): ``odom -> base_footprint`` at 10 Hz for 51.6 s (517
  messages, wall-clock stamps) and one ``/tf_static`` ``base_footprint -> base_link``.

The numbers the tests assert are this file's constants (counts, rates, spans) and what
the tests recompute from the messages. Deterministic (seeded ``random.Random``).

    .venv/bin/python scripts/data/make_test_bags.py [--out tests/data]
"""

from __future__ import annotations

import argparse
import math
import random
import shutil
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

# -- nav2_like.mcap --------------------------------------------------------------------------
SIM_START_NS = 928 * 10**9
WALL_OFFSET_NS = 1_780_000_000 * 10**9 - SIM_START_NS  # receive time = sim + this + delay
DURATION_NS = 60 * 10**9
MAP_ODOM_PERIOD_NS = 125_000_000  # 8 Hz
MAP_ODOM_LAG_NS = 100_000_000  # stamped 0.1 s behind the sim clock
ODOM_BASE_PERIOD_NS = 40_000_000  # 25 Hz
WHEELS_PERIOD_NS = 50_000_000  # 20 Hz, both wheels in one message
ODOM_TOPIC_PERIOD_NS = 200_000_000  # /odom at 5 Hz
RADIUS, SPEED, WHEEL_RADIUS, WHEEL_SEP = 2.0, 0.25, 0.0358, 0.233
#: Counts (the tests assert them): one sample per period over [0, DURATION).
N_MAP_ODOM = DURATION_NS // MAP_ODOM_PERIOD_NS  # 480
N_ODOM_BASE = DURATION_NS // ODOM_BASE_PERIOD_NS  # 1500
N_WHEELS = DURATION_NS // WHEELS_PERIOD_NS  # 1200 messages, 2400 transforms
N_ODOM_TOPIC = DURATION_NS // ODOM_TOPIC_PERIOD_NS  # 300

#: (parent, child, xyz, rpy): a TurtleBot-4-like set of 29 fixed joints.
STATICS: list[tuple[str, str, tuple[float, float, float], tuple[float, float, float]]] = [
    ("base_link", "base_footprint", (0.0, 0.0, -0.0102), (0.0, 0.0, 0.0)),
    ("base_link", "shell_link", (0.0, 0.0, 0.0942), (0.0, 0.0, 0.0)),
    ("base_link", "imu_link", (-0.032, 0.0, 0.068), (0.0, 0.0, 0.0)),
    ("base_link", "bumper", (0.0, 0.0, 0.024), (0.0, 0.0, 0.0)),
    ("bumper", "bump_front_left", (0.1425, 0.0817, 0.0), (0.0, 0.0, 0.52)),
    ("bumper", "bump_front_center", (0.1642, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ("bumper", "bump_front_right", (0.1425, -0.0817, 0.0), (0.0, 0.0, -0.52)),
    ("bumper", "bump_left", (0.0, 0.1642, 0.0), (0.0, 0.0, 1.5708)),
    ("bumper", "bump_right", (0.0, -0.1642, 0.0), (0.0, 0.0, -1.5708)),
    ("base_link", "cliff_front_left", (0.155, 0.0523, 0.0), (0.0, 0.0, 0.3)),
    ("base_link", "cliff_front_right", (0.155, -0.0523, 0.0), (0.0, 0.0, -0.3)),
    ("base_link", "cliff_side_left", (0.0656, 0.1472, 0.0), (0.0, 0.0, 1.15)),
    ("base_link", "cliff_side_right", (0.0656, -0.1472, 0.0), (0.0, 0.0, -1.15)),
    ("base_link", "ir_intensity_front_center_left", (0.1634, 0.0195, 0.05), (0.0, 0.0, 0.1)),
    ("base_link", "ir_intensity_front_center_right", (0.1634, -0.0195, 0.05), (0.0, 0.0, -0.1)),
    ("base_link", "ir_intensity_left", (0.1087, 0.1239, 0.05), (0.0, 0.0, 0.85)),
    ("base_link", "ir_intensity_right", (0.1087, -0.1239, 0.05), (0.0, 0.0, -0.85)),
    ("base_link", "ir_intensity_side_left", (0.0306, 0.1618, 0.05), (0.0, 0.0, 1.38)),
    ("base_link", "ir_omni", (0.1533, 0.0, 0.0627), (0.0, 0.0, 0.0)),
    ("base_link", "button_1", (0.0, 0.05, 0.11), (0.0, 0.0, 0.0)),
    ("base_link", "button_2", (0.0, -0.05, 0.11), (0.0, 0.0, 0.0)),
    ("base_link", "button_power", (-0.05, 0.0, 0.11), (0.0, 0.0, 0.0)),
    ("shell_link", "rplidar_link", (-0.04, 0.0, 0.0985), (0.0, 0.0, 1.5708)),
    ("shell_link", "oakd_link", (0.0585, 0.0, 0.1199), (0.0, 0.0, 0.0)),
    ("oakd_link", "oakd_rgb_camera_frame", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ("oakd_rgb_camera_frame", "oakd_rgb_camera_optical_frame", (0.0, 0.0, 0.0),
     (-1.5708, 0.0, -1.5708)),
    ("oakd_link", "oakd_left_camera_frame", (0.0, 0.0375, 0.0), (0.0, 0.0, 0.0)),
    ("oakd_link", "oakd_right_camera_frame", (0.0, -0.0375, 0.0), (0.0, 0.0, 0.0)),
    ("base_link", "wheel_drop_left", (0.0, 0.1165, 0.0402), (0.0, 0.0, 0.0)),
]  # fmt: skip
assert len(STATICS) == 29

# -- tf_example (sqlite3) ---------------------------------------------------------------------
EX_START_NS = 1_700_000_000 * 10**9 + 250_000_000
EX_PERIOD_NS = 100_000_000  # 10 Hz
EX_COUNT = 517  # 51.6 s from first to last stamp


def quat_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of fixed-axis roll, pitch, yaw (tf2's Quaternion::setRPY)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)  # fmt: skip


class Msgs:
    """ROS 2 message constructors and CDR serialisation from rosbags' typestore."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.t = self.store.types

    def tf(self, parent: str, child: str, stamp_ns: int, xyz: tuple[float, float, float],
           q: tuple[float, float, float, float]) -> Any:  # fmt: skip
        t = self.t
        return t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp_ns, parent),
            child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](*xyz),
                rotation=t["geometry_msgs/msg/Quaternion"](*q),
            ),
        )

    def header(self, stamp_ns: int, frame: str) -> Any:
        sec, nsec = divmod(stamp_ns, 10**9)
        stamp = self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def tf_message(self, transforms: list[Any]) -> Any:
        return self.t["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def cdr(self, msg: Any) -> bytes:
        return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))

    def msgdef(self, typename: str) -> bytes:
        return self.store.generate_msgdef(typename, ros_version=2)[0].encode()


def robot_pose(sim_ns: int) -> tuple[float, float, float]:
    """x, y, yaw of base_link in odom at a sim time: a circle from the origin."""
    s = SPEED * (sim_ns - SIM_START_NS) / 1e9
    a = s / RADIUS
    return RADIUS * math.sin(a), RADIUS * (1 - math.cos(a)), a


def map_odom(sim_ns: int) -> tuple[tuple[float, float, float], float]:
    """The localiser's slowly drifting correction: translation and yaw."""
    u = (sim_ns - SIM_START_NS) / 1e9
    return (0.5 + 0.002 * u, -0.3 + 0.05 * math.sin(u / 10), 0.0), 0.1 + 0.001 * u


def nav2_records(m: Msgs) -> list[tuple[int, str, Any]]:
    """(receive time ns, topic, message) of nav2_like.mcap, in receive-time order."""
    rng = random.Random(20)
    recs: list[tuple[int, str, Any]] = []

    def recv(sim_ns: int) -> int:
        return sim_ns + WALL_OFFSET_NS + 1_000_000 + rng.randrange(0, 2_000_001)

    statics = [m.tf(p, c, SIM_START_NS, xyz, quat_rpy(*rpy)) for p, c, xyz, rpy in STATICS]
    recs.append((SIM_START_NS + WALL_OFFSET_NS, "/tf_static", m.tf_message(statics)))
    for i in range(N_ODOM_BASE):
        t = SIM_START_NS + i * ODOM_BASE_PERIOD_NS
        x, y, yaw = robot_pose(t)
        msg = m.tf_message([m.tf("odom", "base_link", t, (x, y, 0.0), quat_rpy(0, 0, yaw))])
        recs.append((recv(t), "/tf", msg))
    for i in range(N_WHEELS):
        t = SIM_START_NS + i * WHEELS_PERIOD_NS + 3_000_000  # its own phase
        s = SPEED * (t - SIM_START_NS) / 1e9
        left = s * (1 - WHEEL_SEP / 2 / RADIUS) / WHEEL_RADIUS
        right = s * (1 + WHEEL_SEP / 2 / RADIUS) / WHEEL_RADIUS
        msg = m.tf_message([
            m.tf("base_link", "left_wheel", t, (0.0, WHEEL_SEP / 2, 0.0), quat_rpy(0, left, 0)),
            m.tf("base_link", "right_wheel", t, (0.0, -WHEEL_SEP / 2, 0.0),
                 quat_rpy(0, right, 0)),
        ])  # fmt: skip
        recs.append((recv(t), "/tf", msg))
    for i in range(N_MAP_ODOM):
        now = SIM_START_NS + i * MAP_ODOM_PERIOD_NS + 7_000_000
        t = now - MAP_ODOM_LAG_NS
        xyz, yaw = map_odom(t)
        recs.append((recv(now), "/tf", m.tf_message([m.tf("map", "odom", t, xyz,
                                                           quat_rpy(0, 0, yaw))])))  # fmt: skip
    odom_type = m.t["nav_msgs/msg/Odometry"]
    pwc = m.t["geometry_msgs/msg/PoseWithCovariance"]
    twc = m.t["geometry_msgs/msg/TwistWithCovariance"]

    for i in range(N_ODOM_TOPIC):
        t = SIM_START_NS + i * ODOM_TOPIC_PERIOD_NS
        x, y, yaw = robot_pose(t)
        qx, qy, qz, qw = quat_rpy(0, 0, yaw)
        pose = m.t["geometry_msgs/msg/Pose"](
            position=m.t["geometry_msgs/msg/Point"](x, y, 0.0),
            orientation=m.t["geometry_msgs/msg/Quaternion"](qx, qy, qz, qw),
        )
        twist = m.t["geometry_msgs/msg/Twist"](
            linear=m.t["geometry_msgs/msg/Vector3"](SPEED, 0.0, 0.0),
            angular=m.t["geometry_msgs/msg/Vector3"](0.0, 0.0, SPEED / RADIUS),
        )
        msg = odom_type(
            header=m.header(t, "odom"), child_frame_id="base_link",
            pose=pwc(pose=pose, covariance=np.zeros(36)),
            twist=twc(twist=twist, covariance=np.zeros(36)),
        )  # fmt: skip
        recs.append((recv(t), "/odom", msg))
    recs.sort(key=lambda r: r[0])
    return recs


def qos(durability: Any) -> list[Any]:
    """tf2_ros' publisher QoS as rosbag2 records it: reliable, keep-last (100 for /tf,
    1 for the transient-local /tf_static)."""
    from rosbags.rosbag2.metadata import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    never = QosTime(sec=9223372036, nsec=854775807)
    return [Qos(history=QosHistory.KEEP_LAST, depth=100 if durability is
                QosDurability.VOLATILE else 1, reliability=QosReliability.RELIABLE,
                durability=durability, deadline=never, lifespan=never,
                liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
                avoid_ros_namespace_conventions=False)]  # fmt: skip


def write_nav2_mcap(path: Path) -> int:
    """Write nav2_like.mcap with the mcap package; returns the number of messages."""
    from mcap.writer import CompressionType, Writer

    m = Msgs()
    recs = nav2_records(m)
    path.unlink(missing_ok=True)
    with path.open("wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="tfbus scripts/data/make_test_bags.py")
        channels: dict[str, int] = {}
        from rosbags.rosbag2.metadata import QosDurability, dump_qos_v8

        qos_static = dump_qos_v8(qos(QosDurability.TRANSIENT_LOCAL))
        qos_tf = dump_qos_v8(qos(QosDurability.VOLATILE))
        for topic, typ in (("/tf_static", "tf2_msgs/msg/TFMessage"),
                           ("/tf", "tf2_msgs/msg/TFMessage"),
                           ("/odom", "nav_msgs/msg/Odometry")):  # fmt: skip
            sid = w.register_schema(typ, "ros2msg", m.msgdef(typ))
            meta = {"offered_qos_profiles": qos_static if topic == "/tf_static" else qos_tf}
            channels[topic] = w.register_channel(topic, "cdr", sid, meta)
        seq: dict[str, int] = dict.fromkeys(channels, 0)
        for recv_ns, topic, msg in recs:
            seq[topic] += 1
            w.add_message(channels[topic], recv_ns, m.cdr(msg), recv_ns, seq[topic])
        w.finish()
    return len(recs)


def write_tf_example(folder: Path) -> int:
    """Write the sqlite3 bag folder with rosbags' Writer; returns the number of messages."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.metadata import QosDurability

    m = Msgs()

    if folder.exists():
        shutil.rmtree(folder)
    with Writer(folder, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        typ = "tf2_msgs/msg/TFMessage"
        st = w.add_connection("/tf_static", typ, typestore=m.store,
                              offered_qos_profiles=qos(QosDurability.TRANSIENT_LOCAL))
        dy = w.add_connection("/tf", typ, typestore=m.store,
                              offered_qos_profiles=qos(QosDurability.VOLATILE))
        static = m.tf("base_footprint", "base_link", EX_START_NS, (0.0, 0.0, 0.01),
                      (0.0, 0.0, 0.0, 1.0))  # fmt: skip
        w.write(st, EX_START_NS, m.cdr(m.tf_message([static])))
        for i in range(EX_COUNT):
            t = EX_START_NS + i * EX_PERIOD_NS
            u = i * EX_PERIOD_NS / 1e9
            xyz = (0.2 * u, 0.5 * math.sin(u / 8), 0.0)
            msg = m.tf_message([m.tf("odom", "base_footprint", t, xyz,
                                     quat_rpy(0, 0, 0.0625 * math.cos(u / 8)))])  # fmt: skip
            w.write(dy, t + 2_000_000, m.cdr(msg))
    return EX_COUNT + 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "tests" / "data")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    n = write_nav2_mcap(a.out / "nav2_like.mcap")
    print(f"wrote {a.out / 'nav2_like.mcap'}: {n} messages")
    n = write_tf_example(a.out / "tf_example")
    print(f"wrote {a.out / 'tf_example'}: {n} messages")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
