"""tfbus.fleet.FleetBuffer: robots in their namespaces through a Zenoh router (127.0.0.1).

In-process: Zenoh's router (a session in router mode), two robot buses
(``namespace=robot1`` / ``robot2``, client mode) and a fleet bus (``namespace=*``).
Every wait is bounded (anyio.fail_after); nothing sleeps to make a test pass.
"""

from __future__ import annotations

import socket
from collections.abc import Callable

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")

from tfbus.bus import Bus  # noqa: E402
from tfbus.fleet import FleetBuffer, RobotInfo, prefix_frames  # noqa: E402
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh import ZenohTransport  # noqa: E402
from tfbus.transports.zenoh.fleet_keys import FleetKeySpace  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

pytestmark = pytest.mark.anyio


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ts(parent: str, child: str, sec: float, x: float) -> TransformStamped:
    return TransformStamped(
        Header(Time(sec), parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


def bus(endpoint: str, namespace: str, name: str) -> Bus:
    return Bus(transport=ZenohTransport(
        connect=endpoint, config={"mode": "client"}, namespace=namespace, name=name))


async def wait_until(predicate: Callable[[], bool], timeout: float = 10.0,
                     seen: Callable[[], object] | None = None) -> None:
    """Poll ``predicate`` until it holds, at most ``timeout`` s; on timeout the failure
    says what ``seen()`` reports (counters of the parties involved)."""
    try:
        with anyio.fail_after(timeout):
            while not predicate():
                await anyio.sleep(0.02)
    except TimeoutError:
        if seen is None:
            raise
        raise AssertionError(f"not within {timeout} s; seen: {seen()!r}") from None


def test_fleet_key_space_maps_namespaces_to_topic_prefixes() -> None:
    keys = FleetKeySpace("tfbus")
    assert keys.all_data() == "tfbus/*/**"
    assert keys.topic_of("tfbus/robot7/tf") == "/robot7/tf"
    assert keys.topic_of("tfbus/robot7/a/b") == "/robot7/a/b"
    assert keys.topic_of("tfbus/robot7/@latch/abc/tf_static", reply=True) == "/robot7/tf_static"
    assert keys.topic_of("tfbus/robot7/@latch/abc/tf_static") is None
    assert keys.topic_of("other/robot7/tf") is None
    assert keys.data("/robot7/tf") == "tfbus/robot7/tf"
    assert keys.data("/tf") == "tfbus/tf"
    alive = keys.parse_alive("tfbus/robot7/@alive/abc/talker/tf_static")
    assert alive == ("abc", "robot7/talker", "/robot7/tf_static")
    assert keys.parse_alive("tfbus/robot7/@alive/abc/talker") == ("abc", "robot7/talker", "")
    assert keys.parse_alive("tfbus/@alive/abc/talker") is None
    assert keys.alive("abc", "fleet") == "tfbus/@alive/abc/fleet"
    assert keys.alive() == "tfbus/*/@alive/**"
    assert keys.latch("abc") == "tfbus/*/@latch/abc/**"


def test_prefix_frames_is_tf_prefix_style() -> None:
    out = prefix_frames("robot7", [ts("/odom", "base_link", 1, 2.0)])
    assert (out[0].header.frame_id, out[0].child_frame_id) == ("robot7/odom", "robot7/base_link")
    assert out[0].header.stamp == Time(1) and out[0].transform.translation.x == 2.0


async def test_one_buffer_per_robot_and_gone_robots() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    events: list[tuple[str, str]] = []
    async with ZenohRouter(listen=endpoint), bus(endpoint, "*", "fleet") as fbus, \
            FleetBuffer(fbus) as fleet:
        fleet.on_change(lambda what, info: events.append((what, info.name)))
        async with bus(endpoint, "robot1", "r1") as r1:
            async with bus(endpoint, "robot2", "r2") as r2:
                await fleet.wait_for_robot("robot1", timeout=10)
                await fleet.wait_for_robot("robot2", timeout=10)
                r1.publish_nowait("/tf_static", TFMessage([ts("base", "laser", 0, 0.5)]))
                r2.publish_nowait("/tf_static", TFMessage([ts("base", "laser", 0, 0.25)]))
                # wait until the robots' publishers reach the fleet, then send dynamics
                for r, x in ((r1, 1.0), (r2, 3.0)):
                    await wait_until(lambda r=r: r.transport.matching("/tf"))  # type: ignore[union-attr]
                    r.publish_nowait("/tf", TFMessage([ts("map", "base", 5, x)]))
                await wait_until(lambda: fleet.statistics().messages == 4, seen=lambda: (
                    fleet.statistics(), fleet.robots(),
                    [b.transport.statistics() for b in (fbus, r1, r2)]))  # type: ignore[union-attr]
                t1 = fleet["robot1"].lookup_transform("map", "laser", Time(0))
                t2 = fleet["robot2"].lookup_transform("map", "laser", Time(0))
                assert t1.transform.translation.x == pytest.approx(1.5)
                assert t2.transform.translation.x == pytest.approx(3.25)
                info = fleet.robots()["robot1"]
                assert info.alive and info.nodes == {"robot1/r1"}
                assert info.broadcasters == {"robot1/r1"}
                assert (info.messages, info.transforms) == (2, 2)
            # robot2 closed its bus: its liveliness goes, it is reported gone
            await wait_until(lambda: not fleet.robots()["robot2"].alive)
            assert fleet.robots()["robot1"].alive
            assert fleet.statistics().gone == 1
            # its buffer is kept
            assert fleet["robot2"].lookup_transform("map", "laser", Time(0)).transform \
                .translation.x == pytest.approx(3.25)
        assert sorted(fleet) == ["robot1", "robot2"]
        assert ("gone", "robot2") in events


async def test_merged_buffer_prefixes_frames_and_statics_return_after_router_restart() -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    events: list[tuple[str, str]] = []
    router = ZenohRouter(listen=endpoint)
    await router.__aenter__()
    try:
        async with bus(endpoint, "*", "fleet") as fbus, FleetBuffer(fbus, merged=True) as fleet, \
                bus(endpoint, "robot1", "r1") as r1:
            fleet.on_change(lambda what, info: events.append((what, info.name)))
            await fleet.wait_for_robot("robot1", timeout=10)
            r1.publish_nowait("/tf_static", TFMessage([ts("base", "laser", 0, 0.5)]))
            merged = fleet.merged
            assert merged is not None and fleet["robot1"] is merged
            await wait_until(lambda: merged.can_transform("robot1/base", "robot1/laser", Time(0)))
            # the router goes away: the robot is reported gone
            await router.__aexit__()
            await wait_until(lambda: not fleet.robots()["robot1"].alive)
            # a static published while nobody hears it ...
            r1.publish_nowait("/tf_static", TFMessage([ts("base", "camera", 0, 0.125)]))
            # ... arrives when the router is back (the fleet asks the robot that reappears)
            router = ZenohRouter(listen=endpoint)
            await router.__aenter__()
            await fleet.wait_for_robot("robot1", timeout=20)
            await wait_until(
                lambda: merged.can_transform("robot1/base", "robot1/camera", Time(0)), 20
            )
            t = merged.lookup_transform("robot1/laser", "robot1/camera", Time(0))
            assert t.transform.translation.x == pytest.approx(-0.375)
            assert events[-2:] == [("gone", "robot1"), ("alive", "robot1")]
    finally:
        await router.__aexit__()


async def test_add_robot_on_an_in_process_bus() -> None:
    async with Bus() as b, FleetBuffer(b) as fleet:
        buffer = fleet.add_robot("robot9")
        b.publish_nowait("/robot9/tf", TFMessage([ts("map", "base", 1, 2.0)]))
        b.publish_nowait("/robot9/tf", "not a TFMessage")
        assert buffer.lookup_transform("map", "base", Time(0)).transform.translation.x == 2.0
        assert fleet.statistics().dropped == 1
        assert fleet.robots()["robot9"] == RobotInfo("robot9", True, frozenset(), frozenset(),
                                                      1, 1)
        with pytest.raises(ValueError, match="robot name must be one non-empty chunk, got 'a/b'"):
            fleet.add_robot("a/b")
        with pytest.raises(KeyError):
            fleet["robot1"]
