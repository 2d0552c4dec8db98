"""tf2_ros's LookupTransform action on ROS 1 (127.0.0.1), both directions.

A roscore on a free loopback port. (1) tfbus's Ros1BufferClient against Debian's real
``buffer_server`` fed by Debian's ``static_transform_publisher``: the transform, or the
server's TF2Error as the tf2 exception of the same kind. (2) Debian's real
``tf2_ros.BufferClient`` (python3-tf2-ros, rospy + actionlib) against tfbus's
Ros1BufferServer. Every wait is bounded; the nodes are stopped by PID.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import anyio
import pytest
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    master_fixture,
    ros1_fixture,
    tfbus_cli,
)

from tfbus.buffer import Buffer
from tfbus.errors import LookupException
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.remote.ros1 import (
    GOAL_MD5,
    GOAL_TYPE,
    RESULT_MD5,
    RESULT_TYPE,
    Ros1BufferClient,
    Ros1BufferServer,
    decode_goal,
    decode_result,
    encode_goal,
)
from tfbus.time import Time

BUFFER_SERVER = Path("/usr/lib/tf2_ros/buffer_server")
STATIC_PUBLISHER = Path("/usr/lib/tf2_ros/static_transform_publisher")


def test_md5sums_are_debians() -> None:
    """The action's md5sums and types are those of Debian's python3-tf2-msgs."""
    script = ("from tf2_msgs.msg import LookupTransformActionGoal as G, "
              "LookupTransformActionResult as R\nprint(G._type, G._md5sum, R._type, R._md5sum)")
    try:
        done = subprocess.run(["/usr/bin/python3", "-c", script], capture_output=True,
                              text=True, timeout=60, check=False)
    except OSError as err:
        pytest.skip(f"no Debian python3: {err}")
    if done.returncode != 0:
        pytest.skip(f"python3-tf2-msgs is not installed: {done.stderr.strip()[-200:]}")
    assert done.stdout.split() == [GOAL_TYPE, GOAL_MD5, RESULT_TYPE, RESULT_MD5]


def test_goal_round_trips_through_debians_genpy() -> None:
    raw = encode_goal("g-1", 3, "map", "laser", Time(5, 7), 1.5, Time(6), "odom", True)
    script = ("import sys\nfrom tf2_msgs.msg import LookupTransformActionGoal as G\n"
              "m = G(); m.deserialize(sys.stdin.buffer.read()); g = m.goal\n"
              "print(m.header.seq, m.goal_id.id, g.target_frame, g.source_frame, "
              "g.source_time.to_nsec(), g.timeout.to_nsec(), g.target_time.to_nsec(), "
              "g.fixed_frame, g.advanced)")
    done = subprocess.run(["/usr/bin/python3", "-c", script], input=raw, capture_output=True,
                          timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip(f"python3-tf2-msgs is not installed: {done.stderr.decode()[-200:]}")
    assert done.stdout.decode().split() == [
        "3", "g-1", "map", "laser", "5000000007", "1500000000", "6000000000", "odom", "True"]
    with pytest.raises(ValueError, match="malformed tf2_msgs/LookupTransformActionResult"):
        decode_result(b"\x01\x02")
    goal = decode_goal(raw)
    assert (goal.goal_id, goal.target_frame, goal.source_time, goal.timeout, goal.advanced) \
        == ("g-1", "map", Time(5, 7), 1.5, True)
    with pytest.raises(ValueError, match="malformed tf2_msgs/LookupTransformActionGoal"):
        decode_goal(raw[:-3])


def test_client_gets_answers_from_debians_buffer_server(master: Master) -> None:
    if not BUFFER_SERVER.exists():
        pytest.skip(f"{BUFFER_SERVER} missing (Debian's libtf2-ros1d)")
    static = master.run(str(STATIC_PUBLISHER), "1", "2", "3", "0", "0", "0", "base", "laser")
    server = master.run(str(BUFFER_SERVER))
    try:
        async def main() -> None:
            async with Ros1BufferClient(master.uri) as client:
                with anyio.fail_after(60):
                    while True:
                        try:
                            t = await client.lookup_transform("base", "laser", Time(0), 1.0)
                            break
                        except LookupException:
                            await anyio.sleep(0.2)  # the server has not heard /tf_static yet
                assert (t.header.frame_id, t.child_frame_id) == ("base", "laser")
                assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)
                with pytest.raises(LookupException) as err:
                    await client.lookup_transform("base", "ghost", Time(0), 0.0)
                assert "ghost" in str(err.value)
                full = await client.lookup_transform_full("laser", Time(0), "laser", Time(0),
                                                          "base", 1.0)
                assert tuple(full.transform.translation) == (0.0, 0.0, 0.0)

        anyio.run(main)
    finally:
        for p in (server, static):
            p.stop()


DEBIAN_CLIENT = """
import rospy, tf2_ros
rospy.init_node("debian_buffer_client", anonymous=True)
client = tf2_ros.BufferClient("/tf2_buffer_server")
print("server", client.wait_for_server(rospy.Duration(30)), flush=True)
t = client.lookup_transform("base", "laser", rospy.Time(0), rospy.Duration(1))
v = t.transform.translation
print("result", t.header.frame_id, t.child_frame_id, v.x, v.y, v.z, flush=True)
try:
    client.lookup_transform("base", "ghost", rospy.Time(0), rospy.Duration(0))
except tf2_ros.LookupException as e:
    print("lookup_error", str(e), flush=True)
t = client.lookup_transform_full("laser", rospy.Time(0), "laser", rospy.Time(0), "base",
                                 rospy.Duration(1))
print("full", t.transform.translation.x, flush=True)
"""


def test_debians_buffer_client_gets_answers_from_tfbus(master: Master) -> None:
    done = subprocess.run(["/usr/bin/python3", "-c", "import tf2_ros, actionlib"],
                          capture_output=True, timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip("python3-tf2-ros / python3-actionlib not installed")
    buffer = Buffer()
    buffer.set_transform_static(TransformStamped(
        Header(Time(0), "base"), "laser",
        Transform(Vector3(1.0, 2.0, 3.0), Quaternion())), "test")
    expected_error = ""
    try:
        buffer.lookup_transform("base", "ghost", Time(0))
    except LookupException as exc:
        expected_error = str(exc)

    async def main() -> None:
        async with Ros1BufferServer(buffer, master.uri) as server:
            client = master.run("/usr/bin/python3", "-c", DEBIAN_CLIENT)
            try:
                def wait(pattern: str) -> str:
                    return client.wait_for(pattern, timeout=60.0).group(0)

                assert await anyio.to_thread.run_sync(wait, r"server \S+") == "server True"
                assert await anyio.to_thread.run_sync(wait, r"result .*") == \
                    "result base laser 1.0 2.0 3.0"
                assert await anyio.to_thread.run_sync(wait, r"lookup_error .*") == \
                    f"lookup_error {expected_error}"
                assert await anyio.to_thread.run_sync(wait, r"full .*") == "full 0.0"
                assert server.answered == 3 and server.malformed == 0
            finally:
                client.stop()

    anyio.run(main)


def test_serve_buffer_command_answers_debians_buffer_client(master: Master) -> None:
    """``tfbus serve-buffer --bus ros1:master=...`` fed by Debian's
    static_transform_publisher, asked by Debian's tf2_ros.BufferClient."""
    done = subprocess.run(["/usr/bin/python3", "-c", "import tf2_ros, actionlib"],
                          capture_output=True, timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip("python3-tf2-ros / python3-actionlib not installed")
    static = master.run(str(STATIC_PUBLISHER), "1", "2", "3", "0", "0", "0", "base", "laser")
    server = tfbus_cli(master, "serve-buffer", "--bus", f"ros1:master={master.uri}")
    client = None
    try:
        server.wait_for(r"buffer server on the ROS 1 action /tf2_buffer_server", timeout=60)
        script = DEBIAN_CLIENT.split("try:")[0].replace(
            'rospy.Duration(1))', 'rospy.Duration(20))')
        client = master.run("/usr/bin/python3", "-c", script)
        assert client.wait_for(r"server \S+", timeout=60).group(0) == "server True"
        assert client.wait_for(r"result .*", timeout=60).group(0) == \
            "result base laser 1.0 2.0 3.0"
        assert server.stop() == 0
        assert server.wait_for(r"summary: \d+ goals answered", timeout=20).group(0) == \
            "summary: 1 goals answered"
    finally:
        for p in (client, server, static):
            if p is not None:
                p.stop()
