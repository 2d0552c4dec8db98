"""SimClock on a ROS 1 graph: Debian's ``rostopic pub /clock rosgraph_msgs/Clock`` (rospy,
genpy's serialiser) on a fresh roscore drives a tfbus SimClock through the ROS 1
transport's ``clock_topic``; Debian's ``rosbag play --clock`` of the repository's turtle
recording drives a tfbus listener on a SimClock whose lookups at ``clock.now()`` equal
Debian's tf2_ros (rospy) listener's at the same times; ``tfbus replay --clock`` drives a
rospy node with ``/use_sim_time`` (its ``rospy.Time.now()`` reaches the recording's last
time). ROS_IP=127.0.0.1 (the master fixture); every wait bounded.
"""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import anyio
import anyio.to_thread
import pytest
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    Proc,
    master_fixture,
    ros1_fixture,
    tfbus_cli,
)

from tfbus import Bus, SimClock, Time
from tfbus.bag import load_buffer, read_messages
from tfbus.cli._bus_source import BusSource
from tfbus.transports.ros1 import Ros1Transport

TURTLE = Path(__file__).resolve().parents[1] / "data" / "webviz_turtle_tf_example.bag"

ROSPY_SIM_NOW = """
import time, rospy
rospy.init_node("sim_time_follower")
print("USE_SIM_TIME", rospy.get_param("/use_sim_time"), flush=True)
deadline = time.monotonic() + 90
while time.monotonic() < deadline and not rospy.is_shutdown():
    now = rospy.Time.now()
    print("NOW", now.secs, now.nsecs, flush=True)
    time.sleep(0.05)
"""
"""A rospy node with /use_sim_time: prints ``rospy.Time.now()`` every 50 ms of wall time."""

ROSPY_LOOKUPS = """
import sys, rospy, tf2_ros
rospy.init_node("sim_time_tf2_listener")
buffer = tf2_ros.Buffer(rospy.Duration(60))
tf2_ros.TransformListener(buffer)
print("READY", flush=True)
for line in sys.stdin:
    secs, nsecs = (int(x) for x in line.split())
    t = buffer.lookup_transform("world", "turtle1", rospy.Time(secs, nsecs), rospy.Duration(30))
    v, q = t.transform.translation, t.transform.rotation
    print("AT", secs, nsecs, repr(v.x), repr(v.y), repr(v.z), repr(q.x), repr(q.y),
          repr(q.z), repr(q.w), flush=True)
"""
"""Debian's tf2_ros listener (rospy, on /use_sim_time): looks up world -> turtle1 at each
``secs nsecs`` line read from stdin and prints the answer with full precision."""

pytestmark = pytest.mark.anyio


async def test_rostopic_clock_drives_a_sim_clock(master: Master) -> None:
    transport = Ros1Transport(master_uri=master.uri, clock_topic="/clock")
    assert transport.subscriptions() == ("/tf", "/tf_static", "/clock")
    assert transport.topic_type("/clock") == "rosgraph_msgs/Clock"
    publisher = master.run(
        "rostopic", "pub", "-r", "5", "/clock", "rosgraph_msgs/Clock", "--",
        "{clock: {secs: 42, nsecs: 500000000}}",
    )  # fmt: skip
    try:
        async with Bus(transport=transport) as bus, SimClock(bus) as clock:
            assert clock.now() == Time(0)
            with anyio.fail_after(40):  # rostopic's start-up; woken by the message
                await clock.sleep_until(Time(42))
            assert clock.now() == Time(42, 500_000_000)
            types = dict(master.call("getTopicTypes", "/tfbus_test"))
            assert types["/clock"] == "rosgraph_msgs/Clock"
            assert clock.dropped == 0 and clock.jumps == 0 and clock.accepted >= 1
    finally:
        publisher.stop()
    stats = transport.statistics()
    assert stats.malformed == 0 and stats.delivered >= 1


def test_clock_topic_is_checked() -> None:
    with pytest.raises(ValueError, match="clock topic '/tf' is already carried"):
        Ros1Transport(clock_topic="/tf")
    with pytest.raises(ValueError, match="clock topic 'clock' is not a global ROS graph name"):
        Ros1Transport(clock_topic="clock")
    plain = Ros1Transport()
    assert plain.subscriptions() == ("/tf", "/tf_static")


def test_tfbus_replay_clock_drives_a_rospy_node_with_use_sim_time(master: Master) -> None:
    master.call("setParam", "/tfbus_test", "/use_sim_time", True)
    times = [rec.time for rec in read_messages(TURTLE)]
    first, last = min(times), max(times)
    node = Proc(["/usr/bin/python3", "-c", ROSPY_SIM_NOW], master.env)
    replay = None
    try:
        node.wait_for(r"^USE_SIM_TIME True$", timeout=60.0)
        node.wait_for(r"^NOW 0 0$", timeout=30.0)  # no /clock yet: time zero, as ROS
        replay = tfbus_cli(master, "replay", str(TURTLE), "--clock", "--rate", "4", "-q",
                           "--bus", f"ros1:{master.uri}")
        # While the replay runs the node's time is the recording's ...
        m = node.wait_for(r"^NOW (1396\d+) (\d+)$", timeout=60.0)
        during = Time(int(m.group(1)), int(m.group(2)))
        assert first <= during <= last
        # ... and it ends at the recording's last message time: /clock never passes it.
        node.wait_for(rf"^NOW {last.sec} {last.nanosec}$", timeout=60.0)
        assert replay.wait_for(r"^replayed 2689 messages from ", timeout=60.0)
        assert replay.proc.wait(60) == 0  # it ends by itself (a stop now could interrupt it)
    finally:
        if replay is not None:
            replay.stop()
        node.stop()


async def test_rosbag_play_clock_drives_lookups_equal_to_tf2_ros(master: Master) -> None:
    """Debian's ``rosbag play --clock`` publishes the turtle recording and its /clock;
    tfbus looks up world -> turtle1 at ``clock.now()`` every 1.5 simulated seconds, and
    Debian's tf2_ros listener on the same graph answers the same at those times."""
    master.call("setParam", "/tfbus_test", "/use_sim_time", True)
    rospy_listener = subprocess.Popen(
        ["/usr/bin/python3", "-c", ROSPY_LOOKUPS], env=master.env, stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    # The CLI's live source with --use-sim-time (echo, monitor, view): its buffer and
    # clock exist before the bus; the ROS 1 node subscribes to /clock once attached.
    src = BusSource(f"ros1:{master.uri}", cache_time=60.0, use_sim_time=True)
    clock, buffer = src.clock, src.buffer()
    assert isinstance(clock, SimClock)
    play = None
    ours: list[tuple[Time, tuple[float, ...]]] = []
    try:
        assert rospy_listener.stdin is not None and rospy_listener.stdout is not None
        ready = await anyio.to_thread.run_sync(rospy_listener.stdout.readline)
        assert ready == "READY\n"
        async with src.attach():
            assert isinstance(src.transport, Ros1Transport)
            assert src.transport.topic_type("/clock") == "rosgraph_msgs/Clock"
            play = master.run("rosbag", "play", "--clock", "-r", "2", str(TURTLE))
            with anyio.fail_after(120):
                await clock.sleep_until(Time(1396293890))  # the clock is on bag time
                for _ in range(5):
                    await clock.sleep(1.5)
                    now = clock.now()
                    t = await buffer.lookup_transform_async("world", "turtle1", now,
                                                            timeout=5.0)
                    v, q = t.transform.translation, t.transform.rotation
                    ours.append((now, (v.x, v.y, v.z, q.x, q.y, q.z, q.w)))
            assert clock.jumps == 0 and clock.dropped == 0
        assert play.wait_for(r"Done\.", timeout=60.0)
        theirs: list[tuple[Time, tuple[float, ...]]] = []
        for now, _ in ours:
            rospy_listener.stdin.write(f"{now.sec} {now.nanosec}\n")
            rospy_listener.stdin.flush()
            with anyio.fail_after(60):
                line = await anyio.to_thread.run_sync(rospy_listener.stdout.readline)
            fields = line.split()
            assert fields[:3] == ["AT", str(now.sec), str(now.nanosec)], line
            theirs.append((now, tuple(float(x) for x in fields[3:])))
    finally:
        if play is not None:
            play.stop()
        if rospy_listener.poll() is None:
            rospy_listener.send_signal(signal.SIGINT)
            try:
                rospy_listener.wait(timeout=15)
            except subprocess.TimeoutExpired:
                rospy_listener.kill()
                rospy_listener.wait(timeout=5)
    # Five lookups 1.5 s of simulated time apart, inside the recording, answered as tf2_ros.
    assert [now for now, _ in ours] == [now for now, _ in theirs]
    assert all(Time(1396293891) < now < Time(1396293909, 544779879) for now, _ in ours)
    # The live lookups equal tfbus's own answer from the whole recording (nothing lost
    # on the way) ...
    whole = load_buffer(TURTLE)
    for now, got in ours:
        t = whole.lookup_transform("world", "turtle1", now)
        v, q = t.transform.translation, t.transform.rotation
        assert got == (v.x, v.y, v.z, q.x, q.y, q.z, q.w)
    # ... and tf2_ros's within 1e-6: tf2's C++ interpolation (tf2_py) and tfbus's differ
    # by up to ~1e-7 between these 16 ms-apart samples (the same offline, from the bag).
    for (_, a), (_, b) in zip(ours, theirs, strict=True):
        assert a == pytest.approx(b, abs=1e-6)


MS = 1_000_000


async def test_sim_clock_follows_ros1_clock_newest_only(master: Master) -> None:
    """A SimClock on a ROS 1 bus follows /clock newest-only: the clock connection is read
    by a thread of its own that keeps the newest message, so with no deadline filed the
    event loop is given only the first /clock while ``now()`` reads each newer one; a
    sleep's deadline brings its /clock to the loop; a jump back is delivered at once
    and the stamps kept before it are no longer the time; every message read is
    delivered, coalesced or kept (the transport's counters). A plain subscriber of
    /clock on a bus with no SimClock gets every message."""
    from tfbus.codecs.ros1 import CLOCK_MD5SUM, CLOCK_TYPE, encode_clock
    from tfbus.messages import Clock

    sim = Ros1Transport(master_uri=master.uri, node_name="/clock_source")
    app = Ros1Transport(master_uri=master.uri, node_name="/clock_follower",
                        clock_topic="/clock")
    sim.advertise_raw("/clock", CLOCK_TYPE, CLOCK_MD5SUM)
    async with Bus(transport=sim), Bus(transport=app) as b, SimClock(b) as clock:

        async def publish_until_now(ns: int) -> None:
            with anyio.fail_after(40):  # the master and the connection at first
                while clock.now_ns() != ns:
                    sim.send_raw_nowait("/clock", encode_clock(Clock(Time.from_ns(ns))))
                    await anyio.sleep(0.02)  # polling a bounded condition

        await publish_until_now(1000 * MS)
        seen = clock.received
        for k in range(1, 21):
            await publish_until_now((1000 + 100 * k) * MS)
        assert clock.now() == Time.from_ns(3000 * MS)
        assert clock.received - seen <= 2  # not one per /clock
        async with anyio.create_task_group() as tg:
            woke: list[int] = []
            filed = anyio.Event()

            async def sleeper() -> None:
                filed.set()  # the sleep below is filed before this task first waits
                await clock.sleep(0.5)  # filed from the newest time: until 3.5 s
                woke.append(clock.now_ns())

            tg.start_soon(sleeper)
            await filed.wait()
            await publish_until_now(3200 * MS)
            assert woke == []
            await publish_until_now(3500 * MS)
        assert woke and woke[0] >= 3500 * MS
        await publish_until_now(2000 * MS)  # a jump back
        assert clock.jumps == 1
        await publish_until_now(2500 * MS)  # before the 3.5 s kept earlier: the time
        assert clock.now() == Time.from_ns(2500 * MS) and clock.jumps == 1
        assert clock.dropped == 0
    stats = app.statistics()
    assert stats.malformed == 0 and stats.coalesced >= 1
    assert stats.delivered + stats.coalesced + stats.kept == stats.received

    plain = Ros1Transport(master_uri=master.uri, node_name="/clock_listener",
                          clock_topic="/clock")
    heard: list[object] = []
    async with Bus(transport=sim) as a, Bus(transport=plain) as b:
        b.subscribe_callback("/clock", heard.append)
        with anyio.fail_after(40):
            while len(heard) < 3:  # the connection, then each message sent
                sim.send_raw_nowait("/clock", encode_clock(Clock(Time(7))))
                await anyio.sleep(0.05)  # polling a bounded condition
        n = len(heard)
        for sec in range(8, 18):
            sim.send_raw_nowait("/clock", encode_clock(Clock(Time(sec))))
        with anyio.fail_after(40):
            while len(heard) < n + 10:  # each of the 10, none coalesced
                await anyio.sleep(0.02)  # polling a bounded condition
        assert heard[-10:] == [Clock(Time(sec)) for sec in range(8, 18)]
        assert plain.statistics().coalesced == 0
        del a
