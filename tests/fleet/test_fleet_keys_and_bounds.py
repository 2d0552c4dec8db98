"""A fleet listener (namespace ``*``) against peers that announce what they like (127.0.0.1).

In-process: Zenoh's router, a fleet bus with a :class:`~tfbus.fleet.FleetBuffer`, and a
raw Zenoh session standing for the peers: it declares liveliness tokens and puts payloads
on keys of its choosing. Every wait is bounded; time is advanced on a ManualClock.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import AsyncIterator, Callable

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("msgspec")

from tfbus.bus import Bus  # noqa: E402
from tfbus.clock import ManualClock  # noqa: E402
from tfbus.codecs import native as wire  # noqa: E402
from tfbus.fleet import FleetBuffer  # noqa: E402
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh import ZenohTransport, zenoh_config  # noqa: E402
from tfbus.transports.zenoh.fleet_keys import FleetKeySpace  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def tf_payload(child: str, x: float, seq: int) -> bytes:
    t = TransformStamped(Header(Time(1), "map"), child, Transform(Vector3(x, 0, 0), Quaternion()))
    return wire.WireCodec().encode(TFMessage([t]), sender=77, seq=seq)


@contextlib.asynccontextmanager
async def raw_session(endpoint: str) -> AsyncIterator[zenoh.Session]:
    """A raw zenoh-python client session on ``endpoint`` (a peer that declares what a test
    makes up), closed on the way out."""
    cfg, _ = zenoh_config(connect=endpoint, config={"mode": "client"})
    session = await anyio.to_thread.run_sync(zenoh.open, cfg)
    try:
        yield session
    finally:
        await anyio.to_thread.run_sync(session.close)


async def wait_until(predicate: Callable[[], bool], timeout: float = 10.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.02)


def test_a_namespace_has_one_spelling() -> None:
    keys = FleetKeySpace("tfbus")
    assert keys.topic_of("tfbus/r1/tf") == "/r1/tf"
    assert keys.topic_of("tfbus/r%31/tf") is None  # alias of r1
    assert keys.topic_of("tfbus/r1/t%66") is None  # alias of /r1/tf
    assert keys.topic_of("tfbus/r1/a%20b") == "/r1/a b"  # the one spelling of "a b"
    assert keys.topic_of("tfbus/r1/a%2fb") is None  # lower-case hex: an alias
    assert keys.topic_of("tfbus/r%31/@latch/abc/tf_static", reply=True) is None
    assert keys.parse_alive("tfbus/r%31/@alive/abc/talker") is None
    assert keys.parse_alive("tfbus/r1/@alive/abc/t%61lker") is None
    assert keys.parse_alive("tfbus/r1/@alive/abc/talker") == ("abc", "r1/talker", "")


async def test_a_percent_encoded_alias_of_a_namespace_is_refused_and_counted() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace="*",
                               name="fleet")
    async with ZenohRouter(listen=endpoint), Bus(transport=transport) as fbus, \
            FleetBuffer(fbus) as fleet, raw_session(endpoint) as session:
        liveliness = session.liveliness()
        alias = liveliness.declare_token("tfbus/r%31/@alive/aa11/intruder")
        real = liveliness.declare_token("tfbus/r2/@alive/bb22/robot")
        await fleet.wait_for_robot("r2", timeout=10)
        await wait_until(lambda: transport.statistics().refused_tokens == 1)
        session.put("tfbus/r%31/tf", tf_payload("base", 9.0, 1))
        session.put("tfbus/r2/tf", tf_payload("base", 2.0, 1))
        await wait_until(lambda: fleet.statistics().messages == 1
                         and transport.statistics().refused_keys == 1)
        assert "r1" not in fleet and list(fleet) == ["r2"]
        assert fleet["r2"].lookup_transform("map", "base", Time(0)).transform \
            .translation.x == 2.0
        stats = transport.statistics()  # delivered: r2 appearing, its /tf
        assert (stats.refused_keys, stats.refused_tokens, stats.delivered) == (1, 1, 2)
        assert stats.dropped == 1
        alias.undeclare()
        real.undeclare()


async def test_announced_namespaces_are_bounded_and_gone_ones_released() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    clock = ManualClock(Time(1000))
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace="*",
                               name="fleet")
    async with ZenohRouter(listen=endpoint), Bus(transport=transport) as fbus, \
            FleetBuffer(fbus, max_robots=3, forget_after=60, clock=clock) as fleet, \
            raw_session(endpoint) as session:
        liveliness = session.liveliness()
        tokens = {f"ns{i}": liveliness.declare_token(f"tfbus/ns{i}/@alive/{i:04x}/n")
                  for i in range(5)}
        await wait_until(lambda: fleet.statistics().robots_refused == 2)
        kept = sorted(fleet)
        assert len(kept) == 3 and len(fbus.transport.alive()) == 5  # type: ignore[attr-defined]
        # a kept robot goes away: shown as gone until forget_after has passed
        tokens.pop(kept[0]).undeclare()
        await wait_until(lambda: fleet.statistics().gone == 1)
        clock.advance_nowait(59.0)
        assert fleet.robots()[kept[0]].alive is False and len(fleet) == 3
        clock.advance_nowait(1.0)  # 60 s gone: released by the fleet's clock
        await wait_until(lambda: fleet.statistics().released == 1)
        assert kept[0] not in fleet and len(fleet) == 2
        # room again: a new namespace is followed, the next one refused
        tokens["ns5"] = liveliness.declare_token("tfbus/ns5/@alive/0005/n")
        await fleet.wait_for_robot("ns5", timeout=10)
        tokens["ns6"] = liveliness.declare_token("tfbus/ns6/@alive/0006/n")
        await wait_until(lambda: fleet.statistics().robots_refused == 3)
        assert len(fleet) == 3 and "ns6" not in fleet
        with pytest.raises(RuntimeError, match="max_robots=3"):
            fleet.add_robot("manual")
        for token in tokens.values():
            token.undeclare()


def test_bounds_are_checked() -> None:
    bus = Bus()
    with pytest.raises(ValueError, match="max_robots must be at least 1, got 0"):
        FleetBuffer(bus, max_robots=0)
    with pytest.raises(ValueError, match="forget_after must be positive seconds, got -1"):
        FleetBuffer(bus, forget_after=-1)


async def test_live_nodes_are_bounded_whatever_a_peer_declares() -> None:
    """A peer declaring liveliness tokens for made-up node ids (and topics) fills at most
    ``max_peers`` places; the rest are ignored and counted, and a node that goes frees
    its place for the next."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, name="me",
                               max_peers=3)
    async with ZenohRouter(listen=endpoint), Bus(transport=transport), \
            raw_session(endpoint) as session:
        liveliness = session.liveliness()
        tokens = [liveliness.declare_token(f"tfbus/@alive/{i:04x}/fake") for i in range(6)]
        tokens.append(liveliness.declare_token(f"tfbus/@alive/{'f' * 65}/long"))
        await wait_until(lambda: transport.statistics().peers_over_limit == 4)
        assert len(transport.alive()) == 3
        # topics of a tracked node are bounded too (256 by default): one more is fine
        first = sorted(transport.alive())[0]
        topic = liveliness.declare_token(f"tfbus/@alive/{first}/fake/tf")
        await wait_until(lambda: "/tf" in transport.alive()[first].topics)
        # a tracked node goes: its place is free for a new one
        gone = tokens.pop(int(first, 16))
        topic.undeclare()
        gone.undeclare()
        await wait_until(lambda: first not in transport.alive())
        tokens.append(liveliness.declare_token("tfbus/@alive/abcd/late"))
        await wait_until(lambda: "abcd" in transport.alive())
        assert len(transport.alive()) == 3
        assert transport.statistics().peers_over_limit == 4
        for token in tokens:
            token.undeclare()


def test_peer_table_bounds_topics_per_node_and_checks_its_arguments() -> None:
    from tfbus.transports.zenoh.keys import KeySpace
    from tfbus.transports.zenoh.peers import PeerTable

    keys = KeySpace()
    table = PeerTable(keys, frozenset({"/tf_static"}), max_peers=2, max_topics=2)
    assert table.update(True, keys.alive("n1", "a")) is not None
    for topic in ("/tf", "/tf_static"):
        assert table.update(True, keys.alive("n1", "a", topic)) is not None
    assert table.update(True, keys.alive("n1", "a", "/extra")) is None
    assert table.update(True, keys.alive("n1", "a", "/tf")) is not None  # already tracked
    assert table.alive()["n1"].topics == frozenset({"/tf", "/tf_static"})
    assert table.over_limit == 1
    # the version counts the updates applied (4), not the one refused; then a clear
    assert table.version == 4
    table.update(False, keys.alive("n1", "a", "/tf"))
    assert table.version == 5 and table.alive()["n1"].topics == frozenset({"/tf_static"})
    table.clear()
    assert table.version == 6 and not table.alive()
    with pytest.raises(ValueError, match="max_peers must be at least 1, got 0"):
        PeerTable(keys, frozenset(), max_peers=0)
    with pytest.raises(ValueError, match="max_topics must be at least 1, got 0"):
        PeerTable(keys, frozenset(), max_topics=0)


def test_a_fleet_latches_each_robots_static_topic_by_its_robot_name() -> None:
    from tfbus.transports.zenoh.peers import PeerTable

    keys = FleetKeySpace("tfbus")
    assert keys.robot_topic("/r1/tf_static") == "/tf_static"
    assert keys.robot_topic("/r1/a/b") == "/a/b"
    assert keys.robot_topic("/tf") == "/tf"  # the root namespace
    table = PeerTable(keys, frozenset({"/tf_static"}))
    node = table.update(True, "tfbus/r1/@alive/aa11/robot")
    static = table.update(True, "tfbus/r1/@alive/aa11/robot/tf_static")
    dynamic = table.update(True, "tfbus/r1/@alive/aa11/robot/tf")
    assert node is not None and static is not None and dynamic is not None
    # asked when it appears, and again when it starts publishing a latched topic
    assert (node[1], static[1], dynamic[1]) == (True, True, False)
    assert static[0].topic == "/r1/tf_static"


async def test_a_fleet_asks_a_robot_for_its_static_when_the_robot_starts_publishing_it() -> None:
    """A robot's node token comes before its static (a bus starts, then publishes): the
    fleet's queries on the node find nothing latched, and when the robot's ``/tf_static``
    token appears the fleet asks again and gets the static (its live put may precede the
    route to the fleet and be lost: the latch is what a late joiner can count on)."""
    from tfbus.transports.zenoh.transport import LATCH_QUERY_RETRIES

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace="*",
                               name="fleet")
    queries: list[str] = []  # appended in Zenoh's thread
    latched: list[bytes] = []

    def on_query(query: zenoh.Query) -> None:
        with query:
            queries.append(str(query.key_expr))
            if latched:
                query.reply("tfbus/r1/@latch/aa11/tf_static", latched[0])

    async with ZenohRouter(listen=endpoint), Bus(transport=transport) as fbus, \
            FleetBuffer(fbus) as fleet, raw_session(endpoint) as session:
        queryable = session.declare_queryable("tfbus/r1/@latch/aa11/**", on_query)
        liveliness = session.liveliness()
        node = liveliness.declare_token("tfbus/r1/@alive/aa11/robot")
        await fleet.wait_for_robot("r1", timeout=10)
        # asked when it appeared, and again while nothing answered
        await wait_until(lambda: len(queries) == 1 + LATCH_QUERY_RETRIES)
        latched.append(tf_payload("laser", 0.25, 1))
        static = liveliness.declare_token("tfbus/r1/@alive/aa11/robot/tf_static")
        await wait_until(lambda: fleet["r1"].can_transform("map", "laser", Time(0)))
        assert fleet["r1"].lookup_transform("map", "laser", Time(0)).transform \
            .translation.x == 0.25
        assert len(queries) == 2 + LATCH_QUERY_RETRIES
        assert transport.statistics().latched_replies == 1
        static.undeclare()
        node.undeclare()
        queryable.undeclare()


async def test_a_static_a_fleet_publishes_for_a_robot_reaches_the_robots_late_joiner() -> None:
    from tfbus.buffer import Buffer
    from tfbus.listener import TransformListener

    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def bus(namespace: str, name: str) -> Bus:
        return Bus(transport=ZenohTransport(connect=endpoint, config={"mode": "client"},
                                            namespace=namespace, name=name))

    static = TransformStamped(Header(Time(0), "base"), "laser",
                              Transform(Vector3(0.5, 0, 0), Quaternion()))
    async with ZenohRouter(listen=endpoint), bus("*", "fleet") as fbus:
        fbus.publish_nowait("/r7/tf_static", TFMessage([static]))
        buffer = Buffer()
        async with bus("r7", "late") as r7, TransformListener(buffer, r7):
            await wait_until(lambda: buffer.can_transform("base", "laser", Time(0)))
        assert buffer.lookup_transform("base", "laser", Time(0)).transform.translation.x == 0.5
