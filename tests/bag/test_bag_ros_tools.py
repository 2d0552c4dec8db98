"""Bags written by tfbus are read by the real ROS 1 tool library (Debian's
``python3-rosbag``, run by the system ``/usr/bin/python3``). Skips where it is absent."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from peer_install import require

from tfbus import (
    Duration,
    Header,
    Quaternion,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.bag import BagMessage, write_bag

SYSTEM_PYTHON = Path("/usr/bin/python3")


@pytest.fixture(autouse=True, scope="module")
def _rosbag() -> None:
    """Debian's ROS 1 rosbag (python3-rosbag, installed with ROS 1 by install_ros1.sh)."""
    require("ros1", "install_ros1.sh")

READER = """
import json, sys, rosbag
out = []
with rosbag.Bag(sys.argv[1]) as bag:
    info = bag.get_type_and_topic_info()
    for topic, msg, t in bag.read_messages():
        for tr in msg.transforms:
            r, q = tr.transform.translation, tr.transform.rotation
            out.append([topic, t.to_nsec(), tr.header.stamp.to_nsec(), tr.header.frame_id,
                        tr.child_frame_id, [r.x, r.y, r.z], [q.x, q.y, q.z, q.w]])
    latching = {c.topic: (c.header.get("latching") or b"").decode()
                for c in bag._connections.values()}
    types = {k: v.msg_type for k, v in info.topics.items()}
print(json.dumps({"transforms": out, "latching": latching, "types": types}))
"""


def _ts(stamp: Time, parent: str, child: str, x: float) -> TransformStamped:
    return TransformStamped(
        Header(stamp, parent), child, Transform(Vector3(x, 0.5, -1.0), Quaternion(0, 0, 0.6, 0.8))
    )


def test_ros1_bag_written_by_tfbus_is_read_by_rosbag(tmp_path: Path) -> None:
    base = Time(1_700_000_000, 123_456_789)
    messages = [
        BagMessage(base, "/tf_static", TFMessage((_ts(base, "base_link", "base_laser", 0.1),))),
        *(
            BagMessage(t, "/tf", TFMessage((_ts(t, "odom", "base_link", k),)))
            for k, t in enumerate(base + Duration(0, k * 10_000_000) for k in range(5))
        ),
    ]
    path = tmp_path / "session.bag"
    assert write_bag(path, messages, format="ros1") == len(messages)
    proc = subprocess.run(
        [str(SYSTEM_PYTHON), "-c", READER, str(path)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    assert got["types"] == {"/tf": "tf2_msgs/TFMessage", "/tf_static": "tf2_msgs/TFMessage"}
    assert got["latching"]["/tf_static"] == "1"
    expected = [
        [
            m.topic,
            m.time.ns,
            ts.header.stamp.ns,
            ts.header.frame_id,
            ts.child_frame_id,
            list(ts.transform.translation),
            list(ts.transform.rotation),
        ]
        for m in messages
        for ts in m.message.transforms
    ]
    assert sorted(got["transforms"], key=lambda r: (r[1], r[0])) == sorted(
        expected, key=lambda r: (r[1], r[0])
    )
