"""``tfbus web``'s server over real sockets (tfbus.web.server), on asyncio and trio: the
Host/Origin check of ``tfbus view``, hostile input answered with ``status`` messages on a
connection that goes on working, the message size cap, the client cap, a goal driven by a
ManualClock (thresholds and rate exact), ``/tf_static``'s latched transforms and a
client's transforms put on the bus."""

from __future__ import annotations

import json

import anyio
import pytest
from web_support import RawClient, served, ts

from tfbus.clock import ManualClock
from tfbus.messages import TFMessage
from tfbus.time import Time
from tfbus.web.rosbridge import MAX_MESSAGE_BYTES, transform_to_json

pytestmark = pytest.mark.anyio
S = 1_000_000_000


@pytest.mark.parametrize(("host", "origin", "status"), [
    (None, None, 101),  # a non-browser client: no Origin
    (None, "http://127.0.0.1:{port}", 101),  # a page served from this machine
    (None, "http://localhost:{port}", 101),
    (None, "https://evil.example", 403),  # another site's page
    ("evil.example:{port}", None, 403),  # DNS rebinding: a foreign Host
])
async def test_host_and_origin_checked_as_tfbus_view(host: str | None, origin: str | None,
                                                     status: int) -> None:
    async with served() as w:
        port = w.server.port
        async with RawClient.connect(port, host=host and host.format(port=port),
                                     origin=origin and origin.format(port=port)) as c:
            assert c.status == status
        assert w.server.guard.refused == (status == 403)


async def test_token_lets_a_client_in_from_any_name() -> None:
    async with served(host="127.0.0.1", token="s3cret") as w:
        port = w.server.port
        async with RawClient.connect(port, host="robot.lan:1", path="/?token=s3cret") as c:
            assert c.status == 101
        async with RawClient.connect(port, host="robot.lan:1", path="/?token=wrong") as c:
            assert c.status == 403


async def test_hostile_input_answered_counted_and_the_connection_goes_on() -> None:
    async with served() as w:
        async with RawClient.connect(w.server.port) as c:
            await c.send("{not json")
            m = await c.receive()
            assert m["op"] == "status" and m["level"] == "error" and "not JSON" in m["msg"]
            await c.send({"op": "frobnicate", "id": "q1"})
            m = await c.receive()
            assert m["id"] == "q1" and "unknown or unsupported op" in m["msg"]
            # one message over the size cap, sent in one frame: read no further, answered
            await c.send(json.dumps({"op": "publish", "topic": "/tf",
                                     "msg": {"pad": "x" * (MAX_MESSAGE_BYTES + 10)}}))
            m = await c.receive()
            assert "over the limit" in m["msg"]
            # thousands of subscriptions: to /tf again and again (one kept), to topics
            # not served (each refused)
            for i in range(2000):
                await c.send({"op": "subscribe", "topic": "/tf"})
                await c.send({"op": "subscribe", "topic": f"/t{i}", "id": f"s{i}"})
                m = await c.receive()
                assert m["id"] == f"s{i}" and "is not served" in m["msg"]
            # still served: a /tf message reaches it
            w.move(7.5)
            m = await c.receive()
            assert m["op"] == "publish" and m["topic"] == "/tf"
            assert m["msg"]["transforms"][0]["transform"]["translation"]["x"] == 7.5
            (client,) = w.server.clients
            assert client.session.refused == 3 + 2000
            assert list(client.session.subscriptions) == ["/tf"]
        assert w.server.errors == 0


async def test_a_bad_frame_closes_only_that_connection() -> None:
    async with served() as w, RawClient.connect(w.server.port) as good, \
                RawClient.connect(w.server.port) as bad:
        await good.send({"op": "subscribe", "topic": "/tf"})
        await bad.stream.send(b"\x81\xff" + b"\xff" * 20)  # a frame no WebSocket sends
        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
            while True:
                await bad.receive(30)
        await w.until(lambda: len(w.server.clients) == 1)
        w.move(1.5)
        m = await good.receive()
        assert m["msg"]["transforms"][0]["transform"]["translation"]["x"] == 1.5


async def test_client_cap_answers_503() -> None:
    async with served(max_clients=2) as w:
        async with RawClient.connect(w.server.port) as a, \
                RawClient.connect(w.server.port) as b, \
                RawClient.connect(w.server.port) as c:
            assert (a.status, b.status, c.status) == (101, 101, 503)
        assert w.server.busy == 1


async def test_handshake_bounded_in_time() -> None:
    async with served(handshake_timeout=0.5) as w:
        stream = await anyio.connect_tcp("127.0.0.1", w.server.port)
        async with stream:
            await stream.send(b"GET / HTTP/1.1\r\n")  # and never the rest
            with anyio.fail_after(30), pytest.raises((anyio.EndOfStream,
                                                      anyio.BrokenResourceError)):
                await stream.receive()
        assert w.server.errors == 1


async def test_ros1_goal_on_a_manual_clock_thresholds_and_rate() -> None:
    clock = ManualClock(Time(100))
    async with served(clock=clock) as w:
        w.move(0.0)
        async with RawClient.connect(w.server.port) as c:
            await c.send({"op": "subscribe", "topic": "/tf2_web_republisher/feedback"})
            await c.send({"op": "publish", "topic": "/tf2_web_republisher/goal", "msg": {
                "goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": "g"},
                "goal": {"source_frames": ["base_link"], "target_frame": "world",
                         "angular_thres": 0.1, "trans_thres": 0.01, "rate": 5.0}}})
            (rep,) = await w.until(w.republishers)
            got = []
            for i in range(8):  # 4 mm per 0.2 s tick
                w.move(0.004 * i)
                await clock.advance(0.2)
                await w.until(lambda i=i: rep.ticks == i + 1)
            w.move(2.0)
            await clock.advance(0.2)
            while not got or got[-1][1] != 2.0:
                m = await c.receive()
                (t,) = m["msg"]["feedback"]["transforms"]
                stamp = t["header"]["stamp"]
                got.append((stamp["secs"] * S + stamp["nsecs"],
                            round(t["transform"]["translation"]["x"], 6)))
            # sent at 0, 12 mm, 24 mm, then 2 m; stamped with the clock at each tick
            assert got == [(100 * S + k * S // 5, x) for k, x in
                           ((1, 0.0), (4, 0.012), (7, 0.024), (9, 2.0))]


async def test_tf_static_latched_on_subscribe_and_published_transforms_reach_the_bus() -> None:
    async with served() as w:
        w.bus.publish_nowait("/tf_static", TFMessage([ts(0.5, 1, child="laser",
                                                         parent="base_link")]))
        async with RawClient.connect(w.server.port) as c, \
                w.bus.subscribe("/tf") as sub:
            await c.send({"op": "subscribe", "topic": "/tf_static",
                          "type": "tf2_msgs/msg/TFMessage"})
            m = await c.receive()
            (t,) = m["msg"]["transforms"]
            assert (t["child_frame_id"], t["header"]["stamp"]) == ("laser",
                                                                 {"sec": 0, "nanosec": 1})
            await c.send({"op": "advertise", "topic": "/tf", "type": "tf2_msgs/TFMessage"})
            await c.send({"op": "publish", "topic": "/tf", "msg": {"transforms": [
                transform_to_json(ts(3.25, 5 * S, child="hand"))]}})
            with anyio.fail_after(60):
                got = await sub.receive()
            assert got == TFMessage([ts(3.25, 5 * S, child="hand")])
            assert w.buffer.lookup_transform("world", "hand", Time(0)).transform == \
                ts(3.25, 5 * S).transform
