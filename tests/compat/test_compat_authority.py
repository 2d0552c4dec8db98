"""The authority tfbus's ROS 1 listener records is each publisher's caller id (the TCPROS
connection header's ``callerid``), as tf2_ros's ROS 1 listener records
``msg_evt.getPublisherName()``: three Debian publishers under three node names (two
``static_transform_publisher``s on ``/tf_static``, a ``rostopic pub`` on ``/tf``) feed a
tfbus listener and Debian's own tf2_ros listener (rospy, Debian's python3) on one roscore;
``all_frames_as_yaml`` (what view_frames draws) names the same broadcaster for every
frame in both."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest
import yaml
from ros1_harness import Master, Proc, module_master_fixture, ros1_fixture  # noqa: F401

from tfbus import Buffer, Bus, Time, TransformListener
from tfbus.transports.ros1 import Ros1Transport

pytestmark = pytest.mark.anyio

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(name="master")
def master_fixture(module_master: Master) -> Master:
    """The module's one roscore: each test starts and ends its own nodes on it."""
    return module_master

DEBIAN_LISTENER = """
import json, rospy, tf2_ros, yaml
rospy.init_node("debian_authority_listener")
b = tf2_ros.Buffer()
tf2_ros.TransformListener(b)
b.lookup_transform("map", "tip", rospy.Time(0), rospy.Duration(60))
b.lookup_transform("map", "tool", rospy.Time(0), rospy.Duration(60))
print("YAML", json.dumps(yaml.safe_load(b.all_frames_as_yaml())), flush=True)
"""

TF_YAML = ("{transforms: [{header: {stamp: now, frame_id: tool}, child_frame_id: tip, "
           "transform: {translation: {x: 0.5}, rotation: {w: 1.0}}}]}")


def _broadcasters(frames: dict[str, dict[str, object]]) -> dict[str, object]:
    return {child: info["broadcaster"] for child, info in frames.items()}


async def test_ros1_listener_records_each_publishers_caller_id(master: Master) -> None:
    publishers = [
        master.run("rosrun", "tf2_ros", "static_transform_publisher", "1", "2", "3", "0", "0",
                   "0", "1", "map", "laser", "__name:=authority_pub_a"),
        master.run("rosrun", "tf2_ros", "static_transform_publisher", "0", "0", "1", "0", "0",
                   "0", "1", "laser", "tool", "__name:=authority_pub_b"),
        master.run("rostopic", "pub", "-r", "20", "-s", "/tf", "tf2_msgs/TFMessage", "--",
                   TF_YAML, "__name:=authority_pub_c"),
    ]
    debian = Proc(["/usr/bin/python3", "-c", DEBIAN_LISTENER], master.env, cwd=ROOT)
    try:
        buffer = Buffer(cache_time=10.0)
        async with Bus(transport=Ros1Transport(master_uri=master.uri)) as bus, \
                TransformListener(buffer, bus):
            await buffer.wait_for_transform("map", "tool", Time(0), timeout=60.0)
            await buffer.wait_for_transform("map", "tip", Time(0), timeout=60.0)
            ours = yaml.safe_load(buffer.all_frames_as_yaml())
        line = await anyio.to_thread.run_sync(lambda: debian.wait_for(r"^YAML (.*)$", 90.0))
        theirs = json.loads(line.group(1))
    finally:
        debian.stop()
        for p in publishers:
            p.stop()
    assert _broadcasters(theirs) == {"laser": "/authority_pub_a", "tool": "/authority_pub_b",
                                     "tip": "/authority_pub_c"}
    assert _broadcasters(ours) == _broadcasters(theirs)
    assert {c: info["parent"] for c, info in ours.items()} == {
        c: info["parent"] for c, info in theirs.items()}


def test_a_ros1_connections_message_crosses_tfbus_wire_as_a_tfmessage() -> None:
    """A TFMessage received over ROS 1 (its class carries the publisher's caller id) is
    encoded by tfbus's own wire codec (Zenoh) as a TFMessage, not as a raw tuple."""
    from tfbus.codecs import native
    from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
    from tfbus.transports.ros1.transport import tf_message_from

    t = TransformStamped(Header(Time.from_ns(1_500_000_000), "map"), "laser",
                         Transform(Vector3(1.0, 2.0, 3.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
    received = tf_message_from("/authority_pub_a")((t,))
    assert type(received).authority == "/authority_pub_a"  # type: ignore[attr-defined]
    assert repr(received) == repr(TFMessage((t,)))
    codec = native.WireCodec()
    out = codec.decode(codec.encode(received, sender=7, seq=1))
    assert type(out.message) is TFMessage
    assert out.message == TFMessage((t,))
