"""``tfbus.compat.tf2_ros.BufferClient`` is ROS 1 tf2_ros's action client: its lookups are
goals of the ``tf2_msgs/LookupTransform`` action, answered by Debian's real C++
``buffer_server`` (fed by Debian's ``static_transform_publisher`` and a ``rostopic pub``
on ``/tf``) exactly as Debian's own ``tf2_ros.BufferClient`` (rospy, Debian's python3) is
answered on the same server: the transform, and the ``TF2Error`` codes as tf2's
exceptions (an unknown frame, an extrapolation, a server that never answers). The
action's topics are on the process's one tfbus ROS 1 node, beside ``/tf``. Against
tfbus's own :class:`~tfbus.remote.BufferServer` on a ROS 1 bus too, whose held goal is
cancelled when the client's wait ends first."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from ros1_harness import Master, Proc, module_master_fixture, ros1_fixture  # noqa: F401

from tfbus import Buffer as TfbusBuffer
from tfbus import Bus, ManualClock, Time
from tfbus.compat import tf2_ros
from tfbus.compat._loop import background, ros1_bus, shutdown
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.remote import BufferServer

ROOT = Path(__file__).resolve().parents[2]
Q = (0.0, 0.0, 0.3826834323650898, 0.9238795325112867)


@pytest.fixture(name="master")
def master_fixture(module_master: Master) -> Master:
    """The module's one roscore: each test starts and ends its own nodes on it."""
    return module_master


# (name, method, args): the same calls on both clients (times in seconds, 0: latest)
QUERIES: list[tuple[str, str, list[Any]]] = [
    ("static", "lookup_transform", ["map", "laser", 0.0, 5.0]),
    ("static_inverse", "lookup_transform", ["laser", "map", 0.0, 0.0]),
    ("full", "lookup_transform_full", ["laser", 0.0, "map", 0.0, "map", 5.0]),
    ("unknown", "lookup_transform", ["map", "nowhere", 0.0, 0.0]),
    ("unknown_waited", "lookup_transform", ["map", "nowhere", 0.0, 1.0]),
    ("past", "lookup_transform", ["map", "tip", 1.0, 0.0]),
    ("can_yes", "can_transform", ["map", "laser", 0.0, 5.0]),
    ("can_no", "can_transform", ["map", "nowhere", 0.0, 0.0]),
]

DEBIAN_CLIENT = """
import json, sys, time, rospy, tf2_ros
rospy.init_node("debian_buffer_client")
ns, queries = sys.argv[1], json.loads(sys.argv[2])
client = tf2_ros.BufferClient(ns, timeout_padding=rospy.Duration(float(sys.argv[3])))
print("SERVER", client.wait_for_server(rospy.Duration(float(sys.argv[4]))), flush=True)
out, took = {}, {}
for name, method, args in queries:
    args = [rospy.Time.from_sec(a) if i in TIMES.get(method, ()) else a
            for i, a in enumerate(args)]
    args[-1] = rospy.Duration.from_sec(args[-1])
    start = time.monotonic()
    try:
        t = getattr(client, method)(*args)
    except Exception as exc:
        out[name] = ["error", type(exc).__name__, str(exc)]
        continue
    finally:
        took[name] = time.monotonic() - start
    if isinstance(t, bool):
        out[name] = ["bool", t]
        continue
    tr, q = t.transform.translation, t.transform.rotation
    out[name] = ["ok", t.header.frame_id, t.child_frame_id,
                 [t.header.stamp.secs, t.header.stamp.nsecs], [tr.x, tr.y, tr.z],
                 [q.x, q.y, q.z, q.w]]
print("RESULTS", json.dumps(out), flush=True)
print("TOOK", json.dumps(took), flush=True)
""".replace("TIMES", repr({"lookup_transform": (2,), "lookup_transform_full": (1, 3),
                          "can_transform": (2,)}))
PADDING = 10.0
"""Seconds a client waits for the server's answer beyond a lookup's timeout
(``timeout_padding``) where the server does answer."""
_TF2_NAMES = {"LookupException", "ConnectivityException", "ExtrapolationException",
              "InvalidArgumentException", "TimeoutException", "TransformException"}
_TIMES = {"lookup_transform": (2,), "lookup_transform_full": (1, 3), "can_transform": (2,)}


def _ours(client: tf2_ros.BufferClient, queries: list[tuple[str, str, list[Any]]]
          ) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    for name, method, raw in queries:
        args = [Time.from_sec(a) if i in _TIMES[method] else a for i, a in enumerate(raw)]
        try:
            t = getattr(client, method)(*args)
        except tf2_ros.TransformException as exc:  # named by tf2's class it is one of
            tf2 = next(c for c in type(exc).__mro__ if c.__name__ in _TF2_NAMES)
            out[name] = ["error", tf2.__name__, str(exc)]
            continue
        if isinstance(t, bool):
            out[name] = ["bool", t]
            continue
        stamp = divmod(t.header.stamp.ns, 1_000_000_000)
        out[name] = ["ok", t.header.frame_id, t.child_frame_id, list(stamp),
                     list(t.transform.translation), list(t.transform.rotation)]
    return out


def _debian(master: Master, ns: str, queries: list[tuple[str, str, list[Any]]],
            padding: float = 2.0, wait: float = 30.0, runs: int = 1) -> dict[str, list[Any]]:
    """Debian's rospy ``tf2_ros.BufferClient`` asked ``queries``: its answers by name.

    With ``runs`` > 1, where the server answers every query: a query whose client gave up
    waiting for the server's answer (it took ``timeout + padding`` or more: the answer was
    lost between the server and Debian's client, which CI saw twice on a loaded machine,
    a ``TimeoutException`` or a ``can_transform`` False that the server never sent) is
    asked again, all of them in a new client, up to ``runs`` clients."""
    for run in range(1, runs + 1):
        proc = Proc(["/usr/bin/python3", "-c", DEBIAN_CLIENT, ns, json.dumps(queries),
                     str(padding), str(wait)], master.env, cwd=ROOT)
        try:
            out: dict[str, list[Any]] = json.loads(proc.wait_for(r"^RESULTS (.*)$", 240.0).group(1))
            took: dict[str, float] = json.loads(proc.wait_for(r"^TOOK (.*)$", 30.0).group(1))
        finally:
            proc.stop()
        lost = [name for name, _, args in queries if took[name] >= args[-1] + padding]
        if not lost or run == runs:
            break
        print(f"Debian's client lost the answers to {lost}: asked again")
    return out


@pytest.fixture(name="loop")
def loop_fixture(master: Master) -> Iterator[None]:
    """The compat background loop for this test's master, stopped afterwards."""
    yield
    shutdown()


def _node_topics(master: Master, node: str) -> tuple[str, str]:
    info = subprocess.run(["rosnode", "info", node], env=master.env, capture_output=True,
                          text=True, timeout=60, check=False).stdout
    pubs = info.split("Publications:")[1].split("Subscriptions:")[0]
    subs = info.split("Subscriptions:")[1].split("Services:")[0]
    return pubs, subs


def test_buffer_client_matches_debians_on_the_real_buffer_server(
        master: Master, loop: None) -> None:
    peers = [
        master.run("rosrun", "tf2_ros", "buffer_server"),
        master.run("rosrun", "tf2_ros", "static_transform_publisher", "1", "2", "3", *map(
            str, Q), "map", "laser"),
        master.run("rostopic", "pub", "-r", "20", "-s", "/tf", "tf2_msgs/TFMessage", "--",
                   "{transforms: [{header: {stamp: now, frame_id: map}, child_frame_id: tip, "
                   "transform: {translation: {x: 0.5}, rotation: {w: 1.0}}}]}"),
    ]
    try:
        # the padding bounds the wait for the server's answer beyond a lookup's own
        # timeout (tf2_ros's default: 2 s), which a loaded machine can outrun: both
        # clients get 10 s, and each answer still comes as soon as the server sends it
        client = tf2_ros.BufferClient("tf2_buffer_server", timeout_padding=PADDING)
        assert client.wait_for_server(60.0) is True
        # the server has the data before either client asks (the static and the /tf feed)
        assert client.lookup_transform("map", "laser", Time(0), 30.0) is not None
        assert client.can_transform("map", "tip", Time(0), 30.0) is True
        theirs = _debian(master, "tf2_buffer_server", QUERIES, padding=PADDING, runs=3)
        ours = _ours(client, QUERIES)
        # the action's topics are on the process's one tfbus node, beside /tf
        node = ros1_bus().transport.node_name
        pubs, subs = _node_topics(master, node)
    finally:
        for p in peers:
            p.stop()
    assert theirs["static"] == ["ok", "map", "laser", [0, 0], [1.0, 2.0, 3.0], list(Q)]
    assert ours["static"] == theirs["static"]
    assert ours["static_inverse"] == theirs["static_inverse"]
    # the inverse, by the numbers: -R(-45 deg about z) (1, 2, 3)
    assert ours["static_inverse"][4] == pytest.approx(
        [-3 / 2 ** 0.5, -1 / 2 ** 0.5, -3.0], abs=1e-12)
    assert ours["full"] == theirs["full"]
    for name in ("unknown", "unknown_waited"):
        assert theirs[name][:2] == ["error", "LookupException"]
        assert ours[name] == theirs[name]  # the server's message, as it sent it
    assert theirs["past"][:2] == ["error", "ExtrapolationException"]
    assert ours["past"][:2] == theirs["past"][:2]  # (tfbus's subclass for the past)
    assert "s into the past.  Requested time 1.000000000 but the earliest data is at time" \
        in ours["past"][2]
    assert "s into the past.  Requested time 1.000000000" in theirs["past"][2]
    assert ours["can_yes"] == theirs["can_yes"] == ["bool", True]
    assert ours["can_no"] == theirs["can_no"] == ["bool", False]
    for topic in ("/tf2_buffer_server/goal", "/tf2_buffer_server/cancel", "/tf"):
        assert topic in pubs, pubs
    for topic in ("/tf2_buffer_server/result", "/tf2_buffer_server/status", "/tf_static"):
        assert topic in subs, subs


def test_no_server_times_out_as_debians(master: Master, loop: None) -> None:
    queries = [("nobody", "lookup_transform", ["map", "laser", 0.0, 0.5])]
    client = tf2_ros.BufferClient("no_buffer_server", timeout_padding=0.5)
    assert client.wait_for_server(0.5) is False
    start = time.monotonic()
    ours = _ours(client, queries)
    took = time.monotonic() - start
    theirs = _debian(master, "no_buffer_server", queries, padding=0.5, wait=0.5)
    assert theirs["nobody"][:2] == ["error", "TimeoutException"]
    assert ours["nobody"] == theirs["nobody"]
    assert 0.9 <= took < 30.0  # timeout + timeout_padding, then the error


@asynccontextmanager
async def _served(buffer: TfbusBuffer, master_uri: str, node_name: str,
                  **options: Any) -> AsyncIterator[BufferServer]:
    """``BufferServer(buffer, bus, **options)`` on a ROS 1 node of its own."""
    from tfbus.transports.ros1 import Ros1Transport

    async with Bus(transport=Ros1Transport(master_uri, node_name, "127.0.0.1")) as bus, \
            BufferServer(buffer, bus, **options) as server:
        yield server


def test_buffer_client_on_tfbus_server_and_cancel_on_timeout(
        master: Master, loop: None) -> None:
    served = TfbusBuffer(10.0)
    served.set_transform_static(TransformStamped(
        Header(Time(0), "map"), "laser", Transform(Vector3(1.0, 2.0, 3.0), Quaternion(*Q))),
        "test")
    server = background.enter(_served(served, master.uri, "/tf2_buffer_server"))
    # a server whose clock never moves holds a waiting goal (up to max_wait wall seconds)
    frozen = TfbusBuffer(10.0, clock=ManualClock(Time.from_sec(100.0)))
    held = background.enter(_served(frozen, master.uri, "/frozen_server",
                                    name="/frozen_server", max_wait=60.0))
    client = tf2_ros.BufferClient("tf2_buffer_server", timeout_padding=PADDING)
    assert client.wait_for_server(60.0) is True
    t = client.lookup_transform("map", "laser", Time(0), 1.0)
    assert (t.header.frame_id, t.child_frame_id) == ("map", "laser")
    assert tuple(t.transform.translation) == (1.0, 2.0, 3.0)
    assert tuple(t.transform.rotation) == Q
    with pytest.raises(tf2_ros.LookupException, match="nowhere"):
        client.lookup_transform("map", "nowhere", Time(0))
    s = server.statistics()
    assert (s.answered, s.errors) == (1, 1)

    slow = tf2_ros.BufferClient("frozen_server", timeout_padding=0.3)
    assert slow.wait_for_server(60.0) is True
    with pytest.raises(tf2_ros.TimeoutException, match="did not come back"):
        slow.lookup_transform("map", "laser", Time(0), 0.3)
    assert slow.client.cancelled == 1

    async def cancelled_there() -> None:
        import anyio

        with anyio.fail_after(30):
            while held.statistics().cancelled == 0:  # the cancel arrives through TCPROS
                await anyio.sleep(0.01)

    background.call(cancelled_there)
    h = held.statistics()
    assert (h.cancelled, h.pending, h.answered, h.errors) == (1, 0, 0, 0)


@pytest.mark.anyio
async def test_raw_topics_between_two_nodes_and_a_malformed_result_dropped(
        master: Master) -> None:
    """The action's topics between two tfbus ROS 1 nodes (raw topics both ways): a server
    node that answers each goal first with bytes that are no LookupTransformActionResult
    (counted in ``malformed``, dropped), then with the real result, which the client
    returns."""
    import struct

    import anyio

    from tfbus import Bus
    from tfbus.codecs import ros1 as codec
    from tfbus.messages import LookupTransformGoal, LookupTransformResult
    from tfbus.transports.ros1 import Ros1Transport
    from tfbus.transports.ros1.action import ActionClient

    status = struct.pack("<III", 1, 0, 0) + struct.pack("<I", 0) + struct.pack("<I", 0)
    goals: list[LookupTransformGoal] = []
    callers: list[str] = []
    answer = TransformStamped(Header(Time.from_sec(5.0), "map"), "laser",
                              Transform(Vector3(1.0, 2.0, 3.0), Quaternion(*Q)))
    server = Ros1Transport(master_uri=master.uri, node_name="/raw_server")
    client_side = Ros1Transport(master_uri=master.uri, node_name="/raw_client")

    def on_goal(payload: bytes, callerid: str) -> None:
        goal = codec.decode_lookup_goal(payload)
        goals.append(goal)
        callers.append(callerid)
        server.send_raw_nowait("/raw_ns/result", b"\x01\x02 not a result")
        server.send_raw_nowait("/raw_ns/result", codec.encode_lookup_result(
            LookupTransformResult(answer, 0, "", goal.goal_id, goal.goal_stamp)))

    async with Bus(transport=server), Bus(transport=client_side), \
            anyio.create_task_group() as tg:
        server.subscribe_raw("/raw_ns/goal", codec.LOOKUP_GOAL_TYPE, codec.LOOKUP_GOAL_MD5, on_goal)
        server.subscribe_raw("/raw_ns/cancel", codec.GOAL_ID_TYPE, codec.GOAL_ID_MD5,
                             lambda _p, _c: None)
        server.advertise_raw("/raw_ns/result", codec.LOOKUP_RESULT_TYPE, codec.LOOKUP_RESULT_MD5)
        server.advertise_raw("/raw_ns/status", codec.GOAL_STATUS_ARRAY_TYPE,
                             codec.GOAL_STATUS_ARRAY_MD5)
        client = ActionClient(client_side, "raw_ns")

        async def statuses() -> None:  # actionlib's status array, 5 Hz
            while True:
                server.send_raw_nowait("/raw_ns/status", status)
                await anyio.sleep(0.2)

        tg.start_soon(statuses)
        with anyio.fail_after(60):
            await client.wait_ready()
        got = await client.lookup("map", "laser", Time(0), 1.0, Time(0), "", False, 10.0)
        # the client's goal publisher is connected to the server, the server to its result
        assert server.connections("/raw_ns/goal") == (1, 0)
        assert client_side.connections("/raw_ns/result") == (1, 0)
        assert client_side.connections("/raw_ns/goal") == (0, 1)
        tg.cancel_scope.cancel()
    assert got == answer
    assert client.malformed == 1 and client.cancelled == 0
    assert [(g.target_frame, g.source_frame, g.timeout, g.advanced) for g in goals] == [
        ("map", "laser", 1.0, False)]
    assert callers == ["/raw_client"]  # the TCPROS header's callerid, per connection
