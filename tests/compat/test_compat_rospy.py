"""``tfbus.compat.tf2_ros`` in a real rospy program (Debian's ROS 1, a roscore on
127.0.0.1 and a free port): ``TransformListener(buffer)`` and
``StaticTransformBroadcaster()`` with no node join the ROS 1 graph through tfbus's ROS 1
transport (``rosnode info`` shows the node on ``/tf`` and ``/tf_static``); a blocking
``lookup_transform(..., rospy.Duration(30))`` called right after start-up waits for
Debian's ``static_transform_publisher`` and returns a rospy message with a rospy time;
Debian's own tf2_ros (rospy) receives the program's static transform; SIGINT ends the
program promptly."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from ros1_harness import Master, Proc, master_fixture, ros1_fixture  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]
PROBE = ROOT / "peers" / "ros1" / "rospy_probe.py"

DEBIAN_LISTENER = """
import rospy, tf2_ros
rospy.init_node("debian_listener")
b = tf2_ros.Buffer()
tf2_ros.TransformListener(b)
t = b.lookup_transform("map", "probe", rospy.Time(0), rospy.Duration(30))
print("GOT", t.header.stamp.secs, t.header.stamp.nsecs, t.transform.translation.x, flush=True)
"""


def _env(master: Master) -> dict[str, str]:
    env = dict(master.env)
    env["PYTHONPATH"] = str(ROOT)
    return env


def test_rospy_program_on_the_ros1_graph(master: Master) -> None:
    publisher = master.run("rosrun", "tf2_ros", "static_transform_publisher",
                           "1", "2", "3", "0", "0", "0.3826834323650898", "0.9238795325112867",
                           "map", "laser")
    probe = Proc([sys.executable, str(PROBE)], _env(master), cwd=ROOT)
    try:
        line = probe.wait_for(r"^\{.*\}$", timeout=60.0).group(0)
        got = json.loads(line)
        assert got["type"] == "geometry_msgs.msg._TransformStamped.TransformStamped"
        assert got["stamp_type"] == "Time" and got["stamp"] == [0, 0]  # a static: stamp 0
        assert got["latest"] == [0, 0]
        assert got["translation"] == [1.0, 2.0, 3.0]
        assert got["rotation"] == [0.0, 0.0, 0.3826834323650898, 0.9238795325112867]
        assert got["can"] is True
        probe.wait_for("READY", timeout=10.0)
        info = subprocess.run(["rosnode", "info", "/compat_probe_tf2"], env=master.env,
                              capture_output=True, text=True, timeout=60, check=False).stdout
        publications = info.split("Publications:")[1].split("Subscriptions:")[0]
        subscriptions = info.split("Subscriptions:")[1].split("Services:")[0]
        assert "/tf_static" in publications, info
        assert "/tf " in subscriptions and "/tf_static" in subscriptions, info
        debian = Proc(["/usr/bin/python3", "-c", DEBIAN_LISTENER], master.env)
        m = debian.wait_for(r"^GOT (\d+) (\d+) (\S+)$", timeout=60.0)
        # a static looked up at time 0: stamp 0, as tf2 answers for statics
        assert (m.group(1), m.group(2), float(m.group(3))) == ("0", "0", 4.0)
        debian.stop()
        start = time.monotonic()
        probe.proc.send_signal(signal.SIGINT)
        code = probe.proc.wait(timeout=20.0)
        elapsed = time.monotonic() - start
        assert code == 0, probe.drain()
        print(f"SIGINT to exit: {elapsed:.3f} s")
        assert elapsed < 5.0, elapsed  # a bound for a loaded machine (1 s is the aim)
    finally:
        probe.stop()
        publisher.stop()
    assert os.environ.get("ROS_IP") == "127.0.0.1"


SIM_TIME_PROGRAM = """
import sys, time
sys.path.append("/usr/lib/python3/dist-packages")
import rospy
from tfbus.compat import tf2_ros
rospy.init_node("compat_sim_time")
buffer = tf2_ros.Buffer()
tf2_ros.TransformListener(buffer)
clock = buffer.buffer.clock
print("CLOCK", type(clock).__name__, clock.now().ns, flush=True)
deadline = time.monotonic() + 60
while time.monotonic() < deadline and (rospy.Time.now().to_nsec() == 0 or clock.now().ns == 0):
    time.sleep(0.05)
print("NOW", rospy.Time.now().to_nsec(), clock.now().ns, flush=True)
t = buffer.lookup_transform("map", "laser", rospy.Time(0), rospy.Duration(30))
print("GOT", t.transform.translation.x, flush=True)
"""
"""A rospy program on /use_sim_time: its compat Buffer's clock, before and after /clock."""


def test_rospy_use_sim_time_makes_the_compat_buffer_follow_clock(master: Master) -> None:
    master.call("setParam", "/tfbus_test", "/use_sim_time", True)
    program = Proc([sys.executable, "-c", SIM_TIME_PROGRAM], _env(master), cwd=ROOT)
    clock = publisher = None
    try:
        # time is zero until the first /clock, as rospy's with /use_sim_time
        m = program.wait_for(r"^CLOCK (\w+) (\d+)$", timeout=60.0)
        assert (m.group(1), m.group(2)) == ("SimClock", "0")
        clock = master.run("rostopic", "pub", "-r", "5", "/clock", "rosgraph_msgs/Clock", "--",
                           "{clock: {secs: 42, nsecs: 500000000}}")
        m = program.wait_for(r"^NOW (\d+) (\d+)$", timeout=60.0)
        assert (m.group(1), m.group(2)) == ("42500000000", "42500000000")
        publisher = master.run("rosrun", "tf2_ros", "static_transform_publisher",
                               "1.5", "0", "0", "0", "0", "0", "1", "map", "laser")
        m = program.wait_for(r"^GOT (\S+)$", timeout=60.0)
        assert float(m.group(1)) == 1.5
    finally:
        program.stop()
        for proc in (clock, publisher):
            if proc is not None:
                proc.stop()


LATE_SENDER = """
import sys
sys.path.append("/usr/lib/python3/dist-packages")
import rospy
from geometry_msgs.msg import TransformStamped
from tfbus.compat import tf2_ros
from tfbus.compat._loop import background
rospy.init_node("compat_late_sender")
t = TransformStamped()
t.header.frame_id, t.child_frame_id = "map", "late"
t.transform.rotation.w = 1.0
broadcaster = tf2_ros.TransformBroadcaster()
broadcaster.sendTransform(t)
print("SENT", background.running, flush=True)
rospy.signal_shutdown("done")  # its hook stops the background loop
loop_thread = background._thread
loop_thread.join(30)
print("STOPPED", loop_thread.is_alive(), flush=True)
broadcaster.sendTransform(t)  # what a rospy callback still running may do now
tf2_ros.TransformBroadcaster().sendTransform(t)
tf2_ros.StaticTransformBroadcaster().sendTransform(t)
print("AFTER", background.running, flush=True)
"""
"""A rospy program that sends transforms after its shutdown began."""


def test_transforms_sent_after_rospy_shutdown_are_dropped_quietly(master: Master) -> None:
    """Once rospy's shutdown has begun (its hook stops the background loop), a
    ``sendTransform`` (a rospy callback still running, e.g. turtle_tf2's broadcaster on a
    last pose) sends nothing and raises nothing, as a rospy publisher does then
    (``rospy/topics.py``: a publish to a topic closed by the shutdown returns); new
    broadcasters do not start the loop again; the program ends with status 0."""
    program = Proc([sys.executable, "-c", LATE_SENDER], _env(master), cwd=ROOT)
    try:
        assert program.wait_for(r"^SENT (\w+)$", timeout=60.0).group(1) == "True"
        assert program.wait_for(r"^STOPPED (\w+)$", timeout=60.0).group(1) == "False"
        assert program.wait_for(r"^AFTER (\w+)$", timeout=60.0).group(1) == "False"
        assert program.proc.wait(timeout=30.0) == 0
        lines = program.drain()
        assert not [line for line in lines if "Traceback" in line], lines[-20:]
    finally:
        program.stop()
