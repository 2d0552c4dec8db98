"""``BufferServer(buffer, bus)`` on a ROS 1 bus honours actionlib cancel requests and
bounds the goals it holds (127.0.0.1 only).

tf2_ros's ``BufferServer::cancelCB`` (buffer_server.cpp) ends a cancelled goal at once
(``setCanceled``: a PREEMPTED result); actionlib's ``cancelCallback`` defines which goals
a ``GoalID`` names (empty id and zero stamp: all; an id: that goal; a stamp: every goal
stamped at or before it) and recalls goals that come after a cancel naming them. The
FakeMaster tests (asyncio and trio) drive the server from another tfbus ROS 1 node
(raw goal and cancel topics on a ``Ros1Transport``); the
last one from Debian's rospy/actionlib ``SimpleActionClient`` through a real roscore.
Every wait is bounded; child processes are stopped by PID.
"""

from __future__ import annotations

import struct
import subprocess
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio
import pytest
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    master_fixture,
    ros1_fixture,
)
from ros1_hostile import FakeMaster

from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.codecs.ros1 import (
    GOAL_ID_MD5,
    GOAL_ID_TYPE,
    LOOKUP_GOAL_MD5,
    LOOKUP_GOAL_TYPE,
    LOOKUP_RESULT_MD5,
    LOOKUP_RESULT_TYPE,
    decode_lookup_result,
    encode_goal_id,
    encode_lookup_goal,
)
from tfbus.errors import LookupException, TimeoutException
from tfbus.messages import (
    Header,
    LookupTransformGoal,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.remote import BufferClient, BufferServer, ServerStatistics
from tfbus.time import Time
from tfbus.transports.ros1 import Ros1Transport
from tfbus.transports.ros1.action import LookupActionServer

PREEMPTED, SUCCEEDED, REJECTED, RECALLED = 2, 3, 5, 8
GOAL, CANCEL, RESULT = ("/tf2_buffer_server/goal", "/tf2_buffer_server/cancel",
                        "/tf2_buffer_server/result")


def _buffer(clock: ManualClock | None = None) -> Buffer:
    buffer = Buffer(clock=clock) if clock is not None else Buffer()
    buffer.set_transform_static(TransformStamped(
        Header(Time(0), "base"), "laser",
        Transform(Vector3(1.0, 2.0, 3.0), Quaternion())), "test")
    return buffer


async def _until(predicate: Callable[[], bool], timeout: float = 30.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.02)


def goal(goal_id: str, stamp_sec: int, source: str = "ghost", timeout: float = 1000.0) -> bytes:
    """A LookupTransform goal for base <- ``source`` whose GoalID is stamped
    ``stamp_sec`` s (bytes 16..24: after the 16-byte header)."""
    raw = bytearray(encode_lookup_goal(LookupTransformGoal(
        "base", source, Time(0), timeout, Time(0), "", False, goal_id)))
    raw[16:24] = struct.pack("<II", stamp_sec, 0)
    return bytes(raw)


@asynccontextmanager
async def ros1_bus(master_uri: str, node_name: str) -> AsyncIterator[Bus]:
    """An open bus over a ROS 1 node of ``master_uri`` (loopback)."""
    async with Bus(transport=Ros1Transport(master_uri, node_name, "127.0.0.1")) as bus:
        yield bus


class ActionPeer:
    """A tfbus ROS 1 node that publishes raw goals and cancel requests and records
    every result: ``results[goal id] = (status, text, TF2Error code)``."""

    def __init__(self, transport: Ros1Transport) -> None:
        self.transport = transport
        self.results: dict[str, tuple[int, str, int]] = {}

    def on_result(self, raw: bytes, _callerid: str) -> None:
        result = decode_lookup_result(raw)
        self.results[result.goal_id] = (result.status, result.status_text, result.error)

    def send_goal(self, raw: bytes) -> None:
        self.transport.send_raw_nowait(GOAL, raw)

    def cancel(self, goal_id: str, stamp_sec: int) -> None:
        self.transport.send_raw_nowait(CANCEL, encode_goal_id(Time(stamp_sec), goal_id))


@asynccontextmanager
async def action_peer(master_uri: str) -> AsyncIterator[ActionPeer]:
    async with ros1_bus(master_uri, "/action_peer") as bus:
        transport = bus.transport
        assert isinstance(transport, Ros1Transport)
        peer = ActionPeer(transport)
        transport.advertise_raw(GOAL, LOOKUP_GOAL_TYPE, LOOKUP_GOAL_MD5)
        transport.advertise_raw(CANCEL, GOAL_ID_TYPE, GOAL_ID_MD5)
        transport.subscribe_raw(RESULT, LOOKUP_RESULT_TYPE, LOOKUP_RESULT_MD5, peer.on_result)
        c = transport.connections
        await _until(lambda: bool(c(GOAL)[1] and c(CANCEL)[1] and c(RESULT)[0]))
        yield peer


def _stats(server: BufferServer) -> ServerStatistics:
    return server.statistics()


@pytest.mark.anyio
async def test_a_cancelled_client_lookup_cancels_its_goal() -> None:
    """5 BufferClient lookups of a frame that never comes (timeout 1000 s) cancelled
    by move_on_after: the client sends actionlib's cancel for each goal and the server
    ends them at once (before: they were held for 1000 s)."""
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_buffer(), served) as server, \
                ros1_bus(master.uri, "/asking") as bus:
            client = BufferClient(bus)
            t = await client.lookup_transform("base", "laser", Time(0), 20.0)
            assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)
            with anyio.move_on_after(60) as scope:
                async with anyio.create_task_group() as tg:
                    for _ in range(5):
                        tg.start_soon(client.lookup_transform, "base", "ghost", Time(0), 1000.0)
                    await _until(lambda: _stats(server).pending == 5)
                    scope.cancel()
            await _until(lambda: _stats(server).pending == 0)
            assert _stats(server).cancelled == 5
            t = await client.lookup_transform("base", "laser", Time(0), 20.0)
            assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)


@pytest.mark.anyio
async def test_cancel_requests_name_goals_as_actionlib_defines() -> None:
    """By id (that goal, PREEMPTED), by stamp (every goal stamped at or before it; a goal
    so stamped that comes later is RECALLED with actionlib's text), an id not yet seen
    (its goal RECALLED when it comes), empty id and zero stamp (every goal)."""
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_buffer(), served) as server, action_peer(master.uri) as peer:
            for k in range(1, 6):
                peer.send_goal(goal(f"g{k}", 10 * k))
            await _until(lambda: _stats(server).pending == 5)
            peer.cancel("g2", 0)
            await _until(lambda: "g2" in peer.results)
            assert _stats(server).pending == 4 and peer.results["g2"] == (PREEMPTED, "", 0)
            peer.cancel("", 30)  # g1 (10 s) and g3 (30 s)
            await _until(lambda: _stats(server).pending == 2)
            assert peer.results["g1"] == peer.results["g3"] == (PREEMPTED, "", 0)
            peer.send_goal(goal("g6", 25))  # stamped before the last cancel: recalled
            await _until(lambda: "g6" in peer.results)
            assert peer.results["g6"] == (RECALLED, (
                "This goal handle was canceled by the action server because its timestamp "
                "is before the timestamp of the last cancel request"), 0)
            peer.cancel("g7", 0)  # before g7 comes (on another connection: wait for it)
            action = server.server
            assert isinstance(action, LookupActionServer)
            await _until(lambda: "g7" in action._recall)
            peer.send_goal(goal("g7", 70))
            await _until(lambda: "g7" in peer.results)
            assert peer.results["g7"] == (RECALLED, "", 0)
            assert _stats(server).pending == 2 and "g4" not in peer.results
            peer.cancel("", 0)  # every goal
            await _until(lambda: _stats(server).pending == 0)
            assert peer.results["g4"] == peer.results["g5"] == (PREEMPTED, "", 0)
            s = _stats(server)
            assert (s.cancelled, s.answered, s.errors) == (7, 0, 0)
            peer.send_goal(goal("g8", 80, source="laser", timeout=0.0))
            await _until(lambda: "g8" in peer.results)
            assert peer.results["g8"] == (SUCCEEDED, "", 0)


@pytest.mark.anyio
async def test_goals_beyond_max_pending_are_rejected_and_every_wait_is_bounded() -> None:
    """max_pending=3: a fourth waiting goal is REJECTED at once with a status text saying
    why (before: every goal was held); a goal asking 2**31 s waits max_wait (5 s) of the
    buffer's clock, then is answered with the lookup's own error."""
    clock = ManualClock(Time(100))
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_buffer(clock), served, max_pending=3, max_wait=5.0) as server, \
                action_peer(master.uri) as peer, ros1_bus(master.uri, "/asking") as bus:
            client = BufferClient(bus)
            for k in range(1, 4):
                peer.send_goal(goal(f"g{k}", k, timeout=2.0**31 - 1))
            await _until(lambda: _stats(server).pending == 3)
            peer.send_goal(goal("g4", 4))
            await _until(lambda: "g4" in peer.results)
            status, text, _code = peer.results["g4"]
            assert (status, text) == (REJECTED, "buffer server busy: 3 goals waiting "
                                      f"({3 * len(goal('g1', 1))} bytes; max_pending 3)")
            with pytest.raises(TimeoutException,
                               match="Status was REJECTED: buffer server busy"):
                await client.lookup_transform("base", "laser", Time(0), 0.0)
            assert _stats(server).busy == 2
            await clock.advance(4.9)
            await anyio.sleep(0.1)
            assert _stats(server).pending == 3
            await clock.advance(0.2)
            await _until(lambda: all(f"g{k}" in peer.results for k in range(1, 4)))
            assert _stats(server).pending == 0
            assert {peer.results[f"g{k}"][::2] for k in range(1, 4)} == {(SUCCEEDED, 1)}
            t = await client.lookup_transform("base", "laser", Time(0), 0.0)
            assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)
            with pytest.raises(LookupException):
                await client.lookup_transform("base", "ghost", Time(0), 0.0)


DEBIAN_CANCEL = """
import time, rospy, actionlib
from actionlib_msgs.msg import GoalStatus
from tf2_msgs.msg import LookupTransformAction, LookupTransformGoal
rospy.init_node("debian_cancel_client", anonymous=True)
client = actionlib.SimpleActionClient("/tf2_buffer_server", LookupTransformAction)
print("server", client.wait_for_server(rospy.Duration(30)), flush=True)
client.send_goal(LookupTransformGoal(target_frame="base", source_frame="ghost",
                                     source_time=rospy.Time(0), timeout=rospy.Duration(1000)))
deadline = time.monotonic() + 30
while client.get_state() != GoalStatus.ACTIVE and time.monotonic() < deadline:
    time.sleep(0.02)
print("state", client.get_state(), flush=True)
client.cancel_goal()
print("done", client.wait_for_result(rospy.Duration(30)), client.get_state(), flush=True)
"""


def test_debians_action_client_cancels_a_goal(master: Master) -> None:
    """Debian's actionlib SimpleActionClient sees its goal ACTIVE in the status array,
    cancels it, and gets its PREEMPTED result at once (before: the goal was never listed,
    the cancel ignored, and the client waited out its 30 s)."""
    done = subprocess.run(["/usr/bin/python3", "-c", "import tf2_msgs.msg, actionlib"],
                          capture_output=True, timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip("python3-tf2-msgs / python3-actionlib not installed")

    async def main() -> None:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_buffer(), served) as server:
            client = master.run("/usr/bin/python3", "-c", DEBIAN_CANCEL)
            try:
                def wait(pattern: str) -> str:
                    return client.wait_for(pattern, timeout=60.0).group(0)

                assert await anyio.to_thread.run_sync(wait, r"server \S+") == "server True"
                assert await anyio.to_thread.run_sync(wait, r"state \S+") == "state 1"
                assert await anyio.to_thread.run_sync(wait, r"done .*") == \
                    f"done True {PREEMPTED}"
                s = _stats(server)
                assert (s.cancelled, s.pending, s.answered) == (1, 0, 0)
            finally:
                client.stop()

    anyio.run(main)
