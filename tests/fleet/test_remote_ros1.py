"""Ros1BufferClient against Debian's real tf2_ros ``buffer_server`` (ROS 1, 127.0.0.1).

A roscore on a free loopback port, Debian's ``static_transform_publisher`` (tf2_ros) and
``buffer_server`` nodes; the tfbus client sends ``tf2_msgs/LookupTransform`` goals and
gets the transform, or the server's TF2Error as the tf2 exception of the same kind.
Every wait is bounded; the nodes are stopped by PID.
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
)

from tfbus.errors import LookupException
from tfbus.remote_ros1 import (
    GOAL_MD5,
    GOAL_TYPE,
    RESULT_MD5,
    RESULT_TYPE,
    Ros1BufferClient,
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
