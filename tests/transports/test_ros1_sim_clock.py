"""SimClock on a ROS 1 graph: Debian's ``rostopic pub /clock rosgraph_msgs/Clock`` (rospy,
genpy's serialiser) on a fresh roscore drives a tfbus SimClock through the ROS 1
transport's ``clock_topic``. ROS_IP=127.0.0.1 (the master fixture); every wait bounded.
"""

from __future__ import annotations

import anyio
import pytest
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    master_fixture,
    ros1_fixture,
)

from tfbus import Bus, SimClock, Time
from tfbus.transports.ros1 import Ros1Transport

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
