"""tf2_ros's LookupTransform action on ROS 1 (127.0.0.1), both directions.

A roscore on a free loopback port. (1) ``tfbus.remote.BufferClient(bus)`` on a ROS 1 bus
against Debian's real ``buffer_server`` fed by Debian's ``static_transform_publisher``: the
transform, or the server's TF2Error as the tf2 exception of the same kind. (2) Debian's
real ``tf2_ros.BufferClient`` (python3-tf2-ros, rospy + actionlib) against
``tfbus.remote.BufferServer(buffer, bus)`` on a ROS 1 bus, whose action topics are
carried by the same node as ``/tf``. Every wait is bounded; the nodes are stopped by PID.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import subprocess
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import anyio.abc
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    module_master_fixture,
    ros1_fixture,
    tfbus_cli,
)
from ros1_hostile import FakeMaster, HostilePeer, http_answer, send_raw, tcpros_answer, xmlrpc_call

from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.codecs.ros1 import (
    LOOKUP_GOAL_MD5,
    LOOKUP_GOAL_TYPE,
    LOOKUP_RESULT_MD5,
    LOOKUP_RESULT_TYPE,
    decode_lookup_goal,
    decode_lookup_result,
    encode_lookup_goal,
)
from tfbus.core.policy import Clamp, Exact, Nearest, Previous, Window
from tfbus.errors import LookupException
from tfbus.messages import (
    Header,
    LookupTransformGoal,
    Point,
    PointStamped,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.remote import BufferClient, BufferServer
from tfbus.time import Time
from tfbus.transports.ros1 import Ros1Transport
from tfbus.transports.ros1.tcpros import encode_header, frame, read_frame

BUFFER_SERVER = Path("/usr/lib/tf2_ros/buffer_server")


@pytest.fixture(name="master")
def master_fixture(module_master: Master) -> Master:
    """The module's one roscore: each test starts and ends its own nodes on it."""
    return module_master


@asynccontextmanager
async def ros1_bus(master_uri: str, node_name: str | None = None) -> AsyncIterator[Bus]:
    """An open bus over a ROS 1 node of ``master_uri`` (loopback)."""
    async with Bus(transport=Ros1Transport(master_uri, node_name, "127.0.0.1")) as bus:
        yield bus

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
    assert done.stdout.split() == [LOOKUP_GOAL_TYPE, LOOKUP_GOAL_MD5, LOOKUP_RESULT_TYPE,
                                   LOOKUP_RESULT_MD5]


def test_goal_round_trips_through_debians_genpy() -> None:
    raw = encode_lookup_goal(LookupTransformGoal("map", "laser", Time(5, 7), 1.5, Time(6),
                                                 "odom", True, "g-1", Time(9, 4)))
    script = ("import sys\nfrom tf2_msgs.msg import LookupTransformActionGoal as G\n"
              "m = G(); m.deserialize(sys.stdin.buffer.read()); g = m.goal\n"
              "print(m.header.seq, m.header.stamp.to_nsec(), m.goal_id.stamp.to_nsec(), "
              "m.goal_id.id, g.target_frame, g.source_frame, "
              "g.source_time.to_nsec(), g.timeout.to_nsec(), g.target_time.to_nsec(), "
              "g.fixed_frame, g.advanced)")
    done = subprocess.run(["/usr/bin/python3", "-c", script], input=raw, capture_output=True,
                          timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip(f"python3-tf2-msgs is not installed: {done.stderr.decode()[-200:]}")
    assert done.stdout.decode().split() == [
        "0", "9000000004", "9000000004", "g-1", "map", "laser", "5000000007", "1500000000",
        "6000000000", "odom", "True"]
    with pytest.raises(ValueError, match="malformed tf2_msgs/LookupTransformActionResult"):
        decode_lookup_result(b"\x01\x02")
    goal = decode_lookup_goal(raw)
    assert (goal.goal_id, goal.target_frame, goal.source_time, goal.timeout, goal.advanced) \
        == ("g-1", "map", Time(5, 7), 1.5, True)
    assert goal == LookupTransformGoal("map", "laser", Time(5, 7), 1.5, Time(6), "odom", True,
                                       "g-1", Time(9, 4))
    with pytest.raises(ValueError, match="malformed tf2_msgs/LookupTransformActionGoal"):
        decode_lookup_goal(raw[:-3])


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_client_gets_answers_from_debians_buffer_server(master: Master, backend: str) -> None:
    if not BUFFER_SERVER.exists():
        pytest.skip(f"{BUFFER_SERVER} missing (Debian's libtf2-ros1d)")
    static = master.run(str(STATIC_PUBLISHER), "1", "2", "3", "0", "0", "0", "base", "laser")
    server = master.run(str(BUFFER_SERVER))
    try:
        async def main() -> None:
            async with ros1_bus(master.uri) as bus:
                client = BufferClient(bus)
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

        anyio.run(main, backend=backend)
    finally:
        for p in (server, static):
            p.stop()


DEBIAN_CLIENT = """
import rospy, tf2_ros
rospy.init_node("debian_buffer_client", anonymous=True)
client = tf2_ros.BufferClient("/tf2_buffer_server")
print("server", client.wait_for_server(rospy.Duration(30)), flush=True)

def asked(lookup, *args):
    # rospy's SimpleActionClient drops a result that arrives before send_goal has
    # returned ("Got a transition callback on a goal handle that we're not tracking",
    # ros/actionlib#206, never fixed) and then times out: a fast server on a loaded
    # machine. The goal is asked again, at most twice, and each loss is printed.
    for attempt in range(3):
        try:
            return lookup(*args)
        except tf2_ros.TimeoutException:
            if attempt == 2:
                raise
            print("lost_result", args[1], flush=True)  # the source frame asked for

t = asked(client.lookup_transform, "base", "laser", rospy.Time(0), rospy.Duration(1))
v = t.transform.translation
print("result", t.header.frame_id, t.child_frame_id, v.x, v.y, v.z, flush=True)
try:
    asked(client.lookup_transform, "base", "ghost", rospy.Time(0), rospy.Duration(0))
except tf2_ros.LookupException as e:
    print("lookup_error", str(e), flush=True)
t = asked(client.lookup_transform_full, "laser", rospy.Time(0), "laser", rospy.Time(0),
          "base", rospy.Duration(1))
print("full", t.transform.translation.x, flush=True)
print("done", flush=True)
"""


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_debians_buffer_client_gets_answers_from_tfbus(master: Master, backend: str) -> None:
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
        async with ros1_bus(master.uri, "/tfbus_served") as bus, \
                BufferServer(buffer, bus) as server:
            client = master.run("/usr/bin/python3", "-c", DEBIAN_CLIENT)
            try:
                def wait(pattern: str) -> str:
                    return client.wait_for(pattern, timeout=60.0).group(0)

                assert await anyio.to_thread.run_sync(wait, r"server \S+") == "server True"
                # "^": the result line, not a "lost_result laser" line before it
                assert await anyio.to_thread.run_sync(wait, r"^result .*") == \
                    "result base laser 1.0 2.0 3.0"
                assert await anyio.to_thread.run_sync(wait, r"lookup_error .*") == \
                    f"lookup_error {expected_error}"
                assert await anyio.to_thread.run_sync(wait, r"full .*") == "full 0.0"
                await anyio.to_thread.run_sync(wait, r"^done$")
                lost = [line.split()[1] for line in client.seen
                        if line.startswith("lost_result ")]
                errors = lost.count("ghost")  # the lookup the server answers with an error
                s = server.statistics()
                # every goal answered, those whose result the client lost included
                assert (s.requests, s.answered, s.errors, s.malformed) == \
                    (3 + len(lost), 2 + len(lost) - errors, 1 + errors, 0), (s, lost)
            finally:
                client.stop()

    anyio.run(main, backend=backend)


def test_serve_buffer_command_answers_debians_buffer_client(master: Master) -> None:
    """``tfbus serve-buffer --bus ros1:master=...`` fed by Debian's
    static_transform_publisher, asked by Debian's tf2_ros.BufferClient; ``rosnode info``
    shows the action's topics on the node that subscribes to ``/tf`` (one node)."""
    done = subprocess.run(["/usr/bin/python3", "-c", "import tf2_ros, actionlib"],
                          capture_output=True, timeout=60, check=False)
    if done.returncode != 0:
        pytest.skip("python3-tf2-ros / python3-actionlib not installed")
    static = master.run(str(STATIC_PUBLISHER), "1", "2", "3", "0", "0", "0", "base", "laser")
    server = tfbus_cli(master, "serve-buffer", "--bus", f"ros1:master={master.uri}")
    client = None
    try:
        node = server.wait_for(r"buffer server on the ROS 1 action /tf2_buffer_server "
                               r"\(tf2_msgs/LookupTransform\) of node (/\w+)", timeout=60).group(1)
        assert node.startswith("/tf2_buffer_server")
        # the client's first lookup only (the script up to its top-level ``try:``)
        script = DEBIAN_CLIENT.split("\ntry:")[0].replace(
            'rospy.Duration(1))', 'rospy.Duration(20))')
        client = master.run("/usr/bin/python3", "-c", script)
        assert client.wait_for(r"server \S+", timeout=60).group(0) == "server True"
        assert client.wait_for(r"^result .*", timeout=60).group(0) == \
            "result base laser 1.0 2.0 3.0"
        # one node: /tf, /tf_static and the action's five topics
        info = subprocess.run(["rosnode", "info", node], env=master.env,
                              capture_output=True, text=True, timeout=60, check=False).stdout
        pubs = info.split("Publications:")[1].split("Subscriptions:")[0]
        subs = info.split("Subscriptions:")[1].split("Services:")[0]
        for topic in ("result", "feedback", "status"):
            assert f" * /tf2_buffer_server/{topic} [" in pubs, info
        for topic in ("/tf ", "/tf_static ", "/tf2_buffer_server/goal ",
                      "/tf2_buffer_server/cancel "):
            assert f" * {topic}[" in subs, info
        assert server.stop() == 0
        # every goal answered, one more for each result rospy's client lost (asked again)
        lost = sum(line.startswith("lost_result ") for line in client.seen)
        assert server.wait_for(r"summary: \d+ requests, \d+ answered", timeout=20).group(0) \
            == f"summary: {1 + lost} requests, {1 + lost} answered"
    finally:
        for p in (client, server, static):
            if p is not None:
                p.stop()


# ------------------------------------------------------------------ hostile local peers
# A FakeMaster (peers/ros1/ros1_hostile.py) on 127.0.0.1 instead of a roscore: each test runs
# without ROS installed, on asyncio and on trio. In each, the node under attack keeps
# answering a good client and leaves its context cleanly (an error escaping into the
# node's task group would be raised there).


def _static_buffer() -> Buffer:
    buffer = Buffer()
    buffer.set_transform_static(TransformStamped(
        Header(Time(0), "base"), "laser",
        Transform(Vector3(1.0, 2.0, 3.0), Quaternion())), "test")
    return buffer


async def _answered(client: BufferClient) -> None:
    """The server answers a lookup (bounded: the connections may still be opening)."""
    t = await client.lookup_transform("base", "laser", Time(0), 20.0)
    assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)


async def _until(predicate: Callable[[], bool], timeout: float = 30.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.02)


@asynccontextmanager
async def _goal_publisher(goals: list[bytes], topic: str = "/tf2_buffer_server/goal"
                          ) -> AsyncIterator[tuple[str, anyio.Event]]:
    """A publisher of raw ``goals`` on ``topic``: its slave API URI (a HostilePeer whose
    every requestTopic answer names a TCPROS port of this task group, which sends each
    subscriber the header and then the goals) and an event set once they are sent."""
    sent = anyio.Event()

    async def serve(stream: anyio.abc.SocketStream) -> None:
        async with stream:
            with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                await read_frame(BufferedByteReceiveStream(stream), 65536, "header")
                await stream.send(encode_header({
                    "callerid": "/hostile", "md5sum": LOOKUP_GOAL_MD5, "type": LOOKUP_GOAL_TYPE,
                    "topic": topic}))
                for raw in goals:
                    await stream.send(frame(raw))
                sent.set()
                while await stream.receive():
                    pass

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.listeners[0].extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, serve)
        with HostilePeer(send_raw(http_answer(tcpros_answer(f"<int>{port}</int>")))) as peer:
            yield peer.uri, sent
        tg.cancel_scope.cancel()


@pytest.mark.anyio
async def test_buffer_client_and_server_on_ros1_buses_answer_as_a_buffer() -> None:
    """``BufferClient(bus)`` on one ROS 1 node asks ``BufferServer(buffer, bus)`` on
    another (the LookupTransform action through the master): the transform (1, 2, 3),
    the full lookup's (0, 0, 0), can_transform True / False, the server's LookupException
    with its own message, and the counters in the one ``ServerStatistics`` shape."""
    buffer = _static_buffer()
    expected = ""
    try:
        buffer.lookup_transform("base", "ghost", Time(0))
    except LookupException as exc:
        expected = str(exc)
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(buffer, served) as server, ros1_bus(master.uri, "/asking") as bus:
            client = BufferClient(bus)
            await _answered(client)
            full = await client.lookup_transform_full("laser", Time(0), "laser", Time(0),
                                                      "base", 5.0)
            assert tuple(full.transform.translation) == (0.0, 0.0, 0.0)
            assert await client.can_transform("base", "laser", Time(0), 5.0) is True
            assert await client.can_transform("base", "ghost", Time(0), 0.0) is False
            with pytest.raises(LookupException) as err:
                await client.lookup_transform("base", "ghost", Time(0), 0.0)
            assert str(err.value) == expected
            s = server.statistics()
            assert (s.requests, s.answered, s.errors, s.malformed, s.busy, s.pending) == \
                (5, 3, 2, 0, 0, 0)
            assert server.where == ("the ROS 1 action /tf2_buffer_server "
                                    "(tf2_msgs/LookupTransform) of node /served")


@pytest.mark.anyio
async def test_a_lookup_policy_is_refused_on_the_ros1_action() -> None:
    """The LookupTransform action (tf2_msgs) has no field for a lookup policy: a
    non-exact one is a TypeError naming the client, before anything is sent; an exact
    lookup through the same client is answered."""
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_static_buffer(), served), ros1_bus(master.uri, "/asking") as bus:
            client = BufferClient(bus)
            await _answered(client)
            for policy in (Nearest(0.1), Clamp(0.1), Previous(), Window(0.1, 1.0)):
                with pytest.raises(TypeError, match="cannot carry a lookup policy"):
                    await client.lookup_transform("base", "laser", Time(0), 1.0, policy=policy)
                with pytest.raises(TypeError, match="cannot carry a lookup policy"):
                    await client.can_transform("base", "laser", Time(0), 1.0, policy=policy)
                with pytest.raises(TypeError, match="cannot carry a lookup policy"):
                    await client.lookup_transform_full(
                        "base", Time(0), "laser", Time(0), "base", 1.0, policy=policy)
                with pytest.raises(TypeError, match="cannot carry a lookup policy"):
                    await client.transform(
                        PointStamped(Header(Time(0), "laser"), Point()), "base", 1.0,
                        policy=policy)
            done = await client.lookup_transform("base", "laser", Time(0), 1.0, policy=Exact())
            assert tuple(done.transform.translation) == (1.0, 2.0, 3.0)


@pytest.mark.anyio
async def test_a_transport_without_lookups_is_refused_by_name() -> None:
    """A bus whose transport does not serve lookups (``memory``): TypeError naming it,
    from BufferServer and BufferClient alike."""
    from tfbus.transports.memory import MemoryTransport

    async with Bus(transport=MemoryTransport()) as bus:
        for make in (lambda: BufferServer(Buffer(), bus), lambda: BufferClient(bus)):
            with pytest.raises(TypeError, match="MemoryTransport does not"):
                make()


@pytest.mark.anyio
async def test_a_subscriber_resetting_before_its_header_leaves_the_node_serving() -> None:
    """Connections to the server node's TCPROS port reset (``SO_LINGER`` 0) before
    sending a header: each ends only its own connection, the client keeps its answers."""
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_static_buffer(), served):
            transport = served.transport
            assert isinstance(transport, Ros1Transport)
            endpoint = transport.tcpros_endpoint("/tf2_buffer_server/result")
            assert endpoint is not None
            for _ in range(20):
                with socket.create_connection(endpoint, timeout=10) as sock:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            async with ros1_bus(master.uri, "/asking") as bus:
                client = BufferClient(bus)
                await _answered(client)
                await _answered(client)


@pytest.mark.anyio
async def test_an_answer_whose_stamp_ros1_cannot_carry_is_refused() -> None:
    """A goal stamped 0xFFFFFFFF s + 0xFFFFFFFF ns (past 2**32 s), and one asking a time
    past 2**32 s: neither answer fits ROS 1's uint32 seconds; each is refused and counted
    (a struct.error from the result's encoder stopped the node); the good client keeps
    its answers."""
    stamped = bytearray(encode_lookup_goal(LookupTransformGoal(
        "base", "laser", Time(0), 0.0, Time(0), "", False, "bad-1")))
    stamped[16:24] = b"\xff" * 8  # goal_id.stamp (after the 16-byte header)
    late = encode_lookup_goal(LookupTransformGoal(
        "base", "laser", Time(2**32 - 1), 0.0, Time(0), "", False, "bad-2"))
    late = late.replace(struct.pack("<II", 2**32 - 1, 0), struct.pack("<II", 2**32 - 1,
                                                                     2**32 - 1))
    assert decode_lookup_goal(late).source_time.ns >= 2**32 * 10**9
    with FakeMaster() as master:
        async with ros1_bus(master.uri, "/served") as served, \
                BufferServer(_static_buffer(), served) as server, \
                ros1_bus(master.uri, "/asking") as bus:
            client = BufferClient(bus)
            await _answered(client)
            async with _goal_publisher([bytes(stamped), late]) as (uri, sent):
                transport, asking = served.transport, bus.transport
                assert isinstance(transport, Ros1Transport)
                assert isinstance(asking, Ros1Transport)
                await anyio.to_thread.run_sync(lambda: xmlrpc_call(
                    transport.uri, "publisherUpdate", "/master",
                    "/tf2_buffer_server/goal", [uri, asking.uri]))
                with anyio.fail_after(30):
                    await sent.wait()
                await _answered(client)
                await _until(lambda: server.statistics().unsendable >= 2)
        s = server.statistics()
        assert (s.unsendable, s.malformed) == (2, 0)
    with pytest.raises(ValueError, match="ROS 1 time"):
        encode_lookup_goal(LookupTransformGoal("base", "laser", Time(2**32), 0.0, Time(0), "",
                                               False, "g"))
