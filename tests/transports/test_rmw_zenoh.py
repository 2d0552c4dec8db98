"""RmwZenohTransport through a Zenoh router on 127.0.0.1 (asyncio and trio).

The other side is tfbus itself or a bare eclipse-zenoh session configured as rmw_zenoh
configures its endpoints (``rmw_zenoh_cpp/src/detail/rmw_publisher_data.cpp``,
``PublisherData::make``: for a TRANSIENT_LOCAL + RELIABLE publisher an AdvancedPublisher
with ``publisher_detection``, a cache of ``depth`` samples and sporadic heartbeats of 500 ms;
``rmw_subscription_data.cpp``, ``SubscriptionData::init``: an AdvancedSubscriber with
``subscriber_detection``, history with ``detect_late_publishers`` and ``max_samples =
depth``, and heartbeat recovery). The router is Zenoh's own (``tfbus router``'s
:class:`~tfbus.transports.zenoh.router.ZenohRouter`) on a free port; multicast scouting is
off everywhere. Every wait is bounded.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")
zenoh_ext = pytest.importorskip("zenoh.ext")

from tfbus.bus import Bus  # noqa: E402
from tfbus.codecs.cdr import decode_tf, encode_tf  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time  # noqa: E402
from tfbus.transports._base import PeerAware, PeerEvent  # noqa: E402
from tfbus.transports.rmw_zenoh import RmwZenohTransport  # noqa: E402
from tfbus.transports.rmw_zenoh.wire import (  # noqa: E402
    Attachment,
    decode_attachment,
    encode_attachment,
)
from tfbus.transports.spec import open_transport  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio

HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
TYPE = "tf2_msgs::msg::dds_::TFMessage_"
TF_KEY = f"0/tf/{TYPE}/{HASH}"
STATIC_KEY = f"0/tf_static/{TYPE}/{HASH}"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ts(parent: str, child: str, sec: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time(sec, 250), parent), child,
                            Transform(Vector3(x, -2.5, 0.125), Quaternion(0.0, 0.0, 0.6, 0.8)))


async def wait_until(predicate: Callable[[], bool], timeout: float = 15.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.02)


async def exchange(src: Bus, dst: Any, message: TFMessage) -> None:
    """Publish ``message`` on ``src``'s /tf until ``dst`` (a subscription elsewhere)
    receives a message for its child frame, which must equal it exactly."""
    child = message.transforms[0].child_frame_id
    with anyio.fail_after(15):
        while True:
            src.publish_nowait("/tf", message)
            with anyio.move_on_after(0.2):
                while True:
                    got = await dst.receive()
                    if got.transforms[0].child_frame_id == child:
                        assert got == message
                        return


def transport(endpoint: str, name: str, **kwargs: Any) -> RmwZenohTransport:
    return RmwZenohTransport(connect=endpoint, name=name, connect_timeout=20.0, **kwargs)


@contextmanager
def raw_session(endpoint: str) -> Iterator[Any]:
    """A bare Zenoh client of the router, as rmw_zenoh's session (timestamping on)."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", '"client"')
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("timestamping/enabled", "true")
    session = zenoh.open(cfg)
    try:
        yield session
    finally:
        session.close()


class Samples:
    """What a raw subscriber got (Zenoh threads append; the test reads)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.items: list[tuple[str, bytes, bytes | None]] = []

    def __call__(self, sample: Any) -> None:
        att = sample.attachment
        with self.lock:
            self.items.append((str(sample.key_expr), sample.payload.to_bytes(),
                               None if att is None else att.to_bytes()))

    def copy(self) -> list[tuple[str, bytes, bytes | None]]:
        with self.lock:
            return list(self.items)


async def test_tf_both_ways_and_static_late_join_between_two_tfbus_nodes() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    static = TFMessage((ts("base_link", "laser", 3, 0.5),))
    async with ZenohRouter(listen=endpoint):
        a_t = transport(endpoint, "robot_a")
        async with Bus(transport=a_t) as a:
            a.publish_nowait("/tf_static", static)  # before the listener exists
            b_t = transport(endpoint, "viewer")
            before = b_t.peers_version
            async with Bus(transport=b_t) as b, b.subscribe("/tf_static") as b_static, \
                    b.subscribe("/tf") as b_tf, a.subscribe("/tf") as a_tf:
                with anyio.fail_after(15):
                    got = await b_static.receive()
                assert got == static
                # /tf each way, values exact (the first puts may go out while the
                # routes come up: put until one arrives)
                await exchange(a, b_tf, TFMessage((ts("map", "odom_a", 7, 1.25),)))
                await exchange(b, a_tf, TFMessage((ts("map", "odom_b", 8, -1.25),)))
                # robot_a's publisher tokens (the /tf one declared with its first put)
                await wait_until(lambda: [
                    (p.name, p.topics) for p in b_t.broadcasters().values()
                ] == [("robot_a", {"/tf", "/tf_static"})])
                assert isinstance(b_t, PeerAware)
                # the graph changed since the start: what was derived from it is stale
                assert b_t.peers_version > before
            stats = b_t.statistics()
            assert stats.delivered >= 2 and stats.malformed == stats.no_attachment == 0
            assert a_t.statistics().sent >= 2


async def test_static_to_an_advanced_subscriber_configured_as_rmw_zenohs() -> None:
    """tfbus's static broadcaster first; then an AdvancedSubscriber as rmw_zenoh's
    /tf_static subscription gets the whole latched set, with a 33-byte attachment
    whose sequence number is that of the last put."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    first = TFMessage((ts("base_link", "laser", 3, 0.5),))
    second = TFMessage((ts("base_link", "camera", 4, -1.0),))
    async with ZenohRouter(listen=endpoint):
        t = transport(endpoint, "statics")
        async with Bus(transport=t) as bus:
            bus.publish_nowait("/tf_static", first)
            bus.publish_nowait("/tf_static", second)
            assert t.statistics().sent == 2
            got = Samples()
            with raw_session(endpoint) as session:
                sub = zenoh_ext.declare_advanced_subscriber(
                    session, STATIC_KEY, got,
                    history=zenoh_ext.HistoryConfig(detect_late_publishers=True,
                                                    max_samples=100),
                    recovery=zenoh_ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                    subscriber_detection=True)
                await wait_until(lambda: len(got.copy()) >= 1)
                key, payload, att = got.copy()[0]
                sub.undeclare()
    assert key == STATIC_KEY
    assert decode_tf(payload).transforms == first.transforms + second.transforms
    assert att is not None and len(att) == 33
    attachment = decode_attachment(att)
    assert attachment.sequence_number == 2  # counted from 1 (rmw_publisher_data.cpp)
    assert len(attachment.gid) == 16


async def test_static_from_an_advanced_publisher_configured_as_rmw_zenohs() -> None:
    """An AdvancedPublisher as rmw_zenoh's /tf_static publisher puts first (labelled
    attachment, the older Jazzy form); a tfbus listener started afterwards gets it."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    static = TFMessage((ts("odom", "base_footprint", 9, 2.0),))
    async with ZenohRouter(listen=endpoint):
        with raw_session(endpoint) as session:
            pub = zenoh_ext.declare_advanced_publisher(
                session, STATIC_KEY,
                congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE,
                cache=zenoh_ext.CacheConfig(1),
                sample_miss_detection=zenoh_ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=0.5),
                publisher_detection=True)
            pub.put(encode_tf(static), attachment=encode_attachment(
                Attachment(1, 1_763_942_400_000_000_000, bytes(range(16))), "labelled"))
            t = transport(endpoint, "late_listener")
            async with Bus(transport=t) as bus, bus.subscribe("/tf_static") as sub:
                with anyio.fail_after(15):
                    assert await sub.receive() == static
            pub.undeclare()
    assert t.statistics().bad_attachment == 0


async def test_hostile_samples_and_tokens_are_counted_and_dropped() -> None:
    """No attachment, a bad attachment, truncated CDR and a hostile liveliness token:
    each counted and dropped; the valid samples around them are delivered, in order."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    good = [TFMessage((ts("map", f"frame{i}", 10 + i, float(i)),)) for i in range(3)]
    att = encode_attachment(Attachment(1, 5, bytes(16)))
    async with ZenohRouter(listen=endpoint):
        t = transport(endpoint, "victim")
        async with Bus(transport=t) as bus, bus.subscribe("/tf") as sub, \
                bus.subscribe("/tfbus/peers") as peers:
            with raw_session(endpoint) as session:
                token = session.liveliness().declare_token(
                    "@ros2_lv/0/abcdef/1/1/XX/%/%/evil")
                node = session.liveliness().declare_token(
                    f"@ros2_lv/0/{session.zid()}/4/4/NN/%/%robot9/talker")
                pub = session.declare_publisher(TF_KEY)
                await wait_until(lambda: bool(pub.matching_status.matching))
                received: list[object] = []
                with anyio.fail_after(15):
                    while not received:  # the route is up once a valid sample arrives
                        pub.put(encode_tf(good[0]), attachment=att)
                        with anyio.move_on_after(0.2):
                            received.append(await sub.receive())
                before = t.statistics()
                pub.put(encode_tf(good[1]))                                # no attachment
                pub.put(encode_tf(good[1]), attachment=b"\x01\x02\x03")   # bad attachment
                pub.put(encode_tf(good[1])[:-7], attachment=att)          # truncated CDR
                pub.put(encode_tf(good[2]), attachment=att)
                with anyio.fail_after(15):
                    last = await sub.receive()
                while last == good[0]:  # a retry of the first put still in flight
                    with anyio.fail_after(15):
                        last = await sub.receive()
                assert last == good[2]
                await wait_until(lambda: t.statistics().refused_tokens >= 1)
                with anyio.fail_after(15):
                    event = await peers.receive()
                token.undeclare()
                node.undeclare()
                pub.undeclare()
    after = t.statistics()
    assert after.no_attachment - before.no_attachment == 1
    assert after.bad_attachment - before.bad_attachment == 1
    assert after.malformed - before.malformed == 1
    # every sample received is delivered or counted in exactly one drop counter
    assert after.received == (after.delivered + after.no_attachment + after.bad_attachment
                              + after.malformed)
    assert after.refused_tokens == 1
    assert received == [good[0]]
    assert event == PeerEvent(True, f"{event.node_id.split('/')[0]}/4", "robot9/talker")


async def test_tfbus_tokens_are_rmw_zenohs() -> None:
    """The node, its two subscriptions and (once it publishes) its publisher, as
    ``ros2 node list`` / ``ros2 topic info`` on rmw_zenoh read them."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with ZenohRouter(listen=endpoint):
        t = transport(endpoint, "tfbus-echo", domain_id=7, namespace="robot1")
        async with Bus(transport=t) as bus:
            bus.publish_nowait("/tf", TFMessage((ts("map", "a", 1, 1.0),)))
            zid = t.node_id.split("/")[0]
            with raw_session(endpoint) as session:
                keys: set[str] = set()
                with anyio.fail_after(15):
                    while len(keys) < 4:
                        replies = await anyio.to_thread.run_sync(
                            lambda: list(session.liveliness().get("@ros2_lv/7/**",
                                                                  timeout=2.0)))
                        keys = {str(r.ok.key_expr) for r in replies if r.ok is not None}
    base = f"@ros2_lv/7/{zid}/0"
    node = "%/%robot1/tfbus_echo"
    assert keys == {
        f"{base}/0/NN/{node}",
        f"{base}/1/MS/{node}/%robot1%tf/{TYPE}/{HASH}/::,100:,:,:,,",
        f"{base}/2/MS/{node}/%robot1%tf_static/{TYPE}/{HASH}/:1:,100:,:,:,,",
        f"{base}/3/MP/{node}/%robot1%tf/{TYPE}/{HASH}/::,100:,:,:,,",
    }
    assert t.data_key("/tf") == f"7/robot1/tf/{TYPE}/{HASH}"


async def test_fleet_listener_hears_each_robots_namespace() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with ZenohRouter(listen=endpoint):
        fleet_t = transport(endpoint, "fleet", namespace="*")
        r1_t = transport(endpoint, "driver", namespace="robot1")
        async with Bus(transport=fleet_t) as fleet, Bus(transport=r1_t) as r1, \
                fleet.subscribe("/robot1/tf") as sub:
            await exchange(r1, sub, TFMessage((ts("odom", "base_link", 2, 3.0),)))
            await wait_until(lambda: any(
                p.name == "robot1/driver" and "/robot1/tf" in p.topics
                for p in fleet_t.broadcasters().values()))


async def test_fleet_buffer_over_rmw_zenoh() -> None:
    """:class:`tfbus.fleet.FleetBuffer` on a fleet listener: robot1's static transform,
    sent before the fleet starts, in robot1's own buffer."""
    from tfbus.fleet import FleetBuffer

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    laser = ts("base_link", "base_laser", 1, 0.1)
    async with ZenohRouter(listen=endpoint):
        r1 = Bus(transport=transport(endpoint, "driver", namespace="robot1"))
        async with r1:
            r1.publish_nowait("/tf_static", TFMessage((laser,)))
            fleet_bus = Bus(transport=transport(endpoint, "fleet", namespace="*"))
            async with fleet_bus, FleetBuffer(fleet_bus) as fleet:
                buffer = await fleet.wait_for_robot("robot1", timeout=20)
                got = await buffer.lookup_transform_async("base_link", "base_laser",
                                                          Time(0), 20.0)
                assert got.transform == laser.transform
                assert fleet.robots()["robot1"].alive


async def test_fleet_buffer_entered_after_the_robot_was_heard_gets_its_statics() -> None:
    """A :class:`tfbus.fleet.FleetBuffer` entered only after the fleet listener heard
    robot1's node and its static transform (kept: nobody subscribed to robot1's topics
    yet), with no token of robot1 coming afterwards: entering subscribes to the robots
    already alive and has the transport deliver what it kept, so the static is in
    robot1's buffer at once."""
    from tfbus.fleet import FleetBuffer

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    laser = ts("base_link", "base_laser", 1, 0.1)
    async with ZenohRouter(listen=endpoint):
        r1 = Bus(transport=transport(endpoint, "driver", namespace="robot1"))
        async with r1:
            r1.publish_nowait("/tf_static", TFMessage((laser,)))
            fleet_t = transport(endpoint, "fleet", namespace="*")
            async with Bus(transport=fleet_t) as fleet_bus:
                # robot1's node and its static heard before any FleetBuffer subscribed
                await wait_until(lambda: fleet_t.statistics().delivered >= 1 and any(
                    p.name == "robot1/driver" and "/robot1/tf_static" in p.topics
                    for p in fleet_t.alive().values()))
                async with FleetBuffer(fleet_bus) as fleet:
                    buffer = await fleet.wait_for_robot("robot1", timeout=20)
                    got = await buffer.lookup_transform_async(
                        "base_link", "base_laser", Time(0), 20.0)
                    assert got.transform == laser.transform


def test_bus_spec_options() -> None:
    t = open_transport("rmw_zenoh:domain=7&connect=tcp/127.0.0.1:7447&namespace=robot1"
                       "&attachment=labelled", default_name="tfbus-view")
    assert isinstance(t, RmwZenohTransport)
    assert (t.domain_id, t.namespace, t.name) == (7, "/robot1", "tfbus_view")
    assert t.data_key("/tf_static") == f"7/robot1/tf_static/{TYPE}/{HASH}"
    bare = open_transport("rmw_zenoh:tcp/127.0.0.1:7500")
    assert isinstance(bare, RmwZenohTransport) and bare.data_key("/tf") == (
        f"{bare.domain_id}/tf/{TYPE}/{HASH}")
    for bad, word in (("rmw_zenoh:domain=233", "domain"), ("rmw_zenoh:mode=router", "mode"),
                      ("rmw_zenoh:namespace=a b", "namespace"),
                      ("rmw_zenoh:attachment=json", "attachment"),
                      ("rmw_zenoh:connect_timeout=-1", "connect_timeout"),
                      ("rmw_zenoh:colour=red", "colour")):
        with pytest.raises(ValueError, match=word):
            open_transport(bad)


def test_constructor_names_bad_values() -> None:
    for kwargs, word in (({"domain_id": 300}, "domain_id"), ({"name": ""}, "node name"),
                         ({"topics": ["/scan"]}, "topics"), ({"max_batch": 0}, "max_batch"),
                         ({"listen": "tcp/127.0.0.1:0"}, "listen"),
                         ({"connect_timeout": float("inf")}, "connect_timeout")):
        with pytest.raises(ValueError, match=word):
            RmwZenohTransport(**kwargs)


async def test_messages_off_the_wire_are_counted() -> None:
    """Not a TFMessage, a stamp past int32 seconds, a topic not carried, /tf before
    running: counted, never raised; /tf_static before running is put once running."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    t = transport(endpoint, "sender")
    t.send_nowait("/tf", TFMessage((ts("a", "b", 1, 1.0),)))
    t.send_nowait("/tf_static", TFMessage((ts("a", "c", 1, 1.0),)))
    t.send_nowait("/scan", object())
    t.send_nowait("/tf", "not a message")
    t.send_nowait("/tf", TFMessage((ts("a", "b", 2**31, 1.0),)))
    stats = t.statistics()
    assert (stats.not_connected, stats.not_mapped, stats.send_errors, stats.sent) == (1, 1, 2, 0)
    async with ZenohRouter(listen=endpoint), Bus(transport=t):
        assert t.statistics().sent == 1


async def test_cli_static_transform_over_rmw_zenoh() -> None:
    """``tfbus static-transform --bus rmw_zenoh:...`` (a child process) is heard by a
    listener that starts after it; the child is ended by its PID."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    async with ZenohRouter(listen=endpoint):
        child = subprocess.Popen(
            [sys.executable, "-m", "tfbus.cli", "static-transform", "1.5", "-2", "0.25",
             "0", "0", "0", "base_link", "laser", "--bus", f"rmw_zenoh:{endpoint}"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        try:
            assert child.stdout is not None
            line = await anyio.to_thread.run_sync(child.stdout.readline)
            assert line.startswith("publishing static transform base_link -> laser"), line
            t = transport(endpoint, "cli_listener")
            async with Bus(transport=t) as bus, bus.subscribe("/tf_static") as sub:
                with anyio.fail_after(20):
                    got = await sub.receive()
            (only,) = got.transforms
            assert (only.header.frame_id, only.child_frame_id) == ("base_link", "laser")
            assert only.transform.translation == Vector3(1.5, -2.0, 0.25)
        finally:
            child.terminate()
            try:
                await anyio.to_thread.run_sync(lambda: child.wait(20))
            except subprocess.TimeoutExpired:
                child.kill()
                await anyio.to_thread.run_sync(child.wait)


async def test_fleet_statics_that_came_before_the_robots_node_reach_its_buffer() -> None:
    """The order a fleet listener can see on start: a robot's /tf_static history (from the
    AdvancedSubscriber) before the robot's liveliness tokens. The statics are kept until
    the FleetBuffer subscribes to ``/robot1/tf_static`` (on the robot's node appearing),
    then delivered. Driven through the transport's own queue and drain, in that order."""
    from tfbus.fleet import FleetBuffer
    from tfbus.transports.rmw_zenoh import transport as module
    from tfbus.transports.rmw_zenoh.wire import TF_QOS, endpoint_token, node_token

    t = RmwZenohTransport(namespace="*", name="fleet")
    laser = ts("base_link", "base_laser", 1, 0.1)
    att = encode_attachment(Attachment(1, 5, bytes(16)))
    t._push((module._SAMPLE, f"0/robot1/tf_static/{TYPE}/{HASH}",
             encode_tf(TFMessage((laser,))), att))
    t._push((module._ALIVE_PUT, node_token(0, "ab12", 3, "/robot1", "driver"), None, None))
    t._push((module._ALIVE_PUT, endpoint_token(0, "ab12", 3, 4, "MP", "/robot1", "driver",
                                               "/robot1/tf_static", TF_QOS), None, None))
    async with Bus() as bus, FleetBuffer(bus) as fleet:
        assert t._drain(bus, True) is False
        buffer = fleet["robot1"]
        got = await buffer.lookup_transform_async("base_link", "base_laser", Time(0), 0.0)
    assert got.transform == laser.transform
    assert t.statistics().delivered == 1
