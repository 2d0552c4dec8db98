"""tf_monitor's statistics (tfbus.monitor), hand-computed: rates (one definition), delays,
broadcasters, the chain and its net delay, simulated time; and the live path, a
TransformListener feeding a Buffer and the statistics through MonitoredSink (asyncio and
trio, time driven by ManualClock)."""

from __future__ import annotations

import anyio
import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.monitor import MonitoredSink, TfStatistics, frame_chain, link_rate

T0 = 1_700_000_000 * 10**9
MS = 1_000_000


def tf(parent: str, child: str, ns: int) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_link_rate_is_intervals_over_span() -> None:
    assert link_rate(5, 0, 400 * MS) == 10.0
    assert link_rate(1, 0, 0) == 0.0
    assert link_rate(3, 5, 5) == 0.0


def test_frame_and_broadcaster_statistics_by_hand() -> None:
    """odom -> base at stamps 0, 100, 100 (repeated), 300 ms, each received 20 ms later,
    by 'a'; map -> odom static by 'b'."""
    s = TfStatistics()
    s.add(Time.from_ns(T0), [tf("map", "odom", 0)], "b", static=True)
    for stamp in (0, 100, 100, 300):
        s.add(Time.from_ns(T0 + (stamp + 20) * MS), [tf("odom", "base", T0 + stamp * MS)], "a",
              static=False)
    base = s.frames["base"]
    assert (base.parent, base.count, len(base.stamps)) == ("odom", 4, 3)
    assert base.rate == pytest.approx(2 / 0.3)  # 3 distinct stamps over 0.3 s
    assert base.delay_avg == pytest.approx(0.02) and base.delay_max == pytest.approx(0.02)
    assert base.authority == "a"
    assert s.frames["odom"].static and s.frames["odom"].rate == 0.0
    a = s.authorities["a"]
    assert a.messages == 4 and a.rate == pytest.approx(3 / 0.3)
    assert s.messages == {"/tf_static": 1, "/tf": 4}
    assert s.sim_time is False and s.transform_count == 5


def test_chain_order_and_net_delay() -> None:
    """world -> a -> b, world -> c: the chain b..c is b, a, world, c (tf2's order, as
    tf_monitor prints it); net delay = receive - latest common stamp."""
    parents = {"a": "world", "b": "a", "c": "world"}
    assert frame_chain(parents, "b", "c") == ["b", "a", "world", "c"]
    assert frame_chain(parents, "world", "b") == ["world", "a", "b"]
    assert frame_chain({"x": "y", "p": "q"}, "x", "p") is None
    s = TfStatistics()
    chain = s.watch_chain("b", "c")
    assert chain.frames is None
    s.add(Time.from_ns(T0 + 10 * MS), [tf("world", "a", T0), tf("a", "b", T0)], "n",
          static=False)
    s.add(Time.from_ns(T0 + 50 * MS), [tf("world", "c", T0 + 40 * MS)], "n", static=False)
    assert chain.frames == ("b", "a", "world", "c")
    # Only the second message saw a connected chain: 50 ms - min(0, 0, 40) ms.
    assert chain.delay_count == 1 and chain.delay_avg == pytest.approx(0.05)


def test_simulated_time_delays_use_the_newest_stamp() -> None:
    s = TfStatistics()
    for k in range(3):
        s.add(Time.from_ns(T0 + k * 100 * MS), [tf("map", "odom", 10**10 + k * 100 * MS)], "a",
              static=False)
    s.add(Time.from_ns(T0 + 400 * MS), [tf("odom", "base", 10**10 + 150 * MS)], "a",
          static=False)
    assert s.sim_time is True
    assert s.frames["odom"].delay_max == 0.0
    assert s.frames["base"].delay_avg == pytest.approx(0.05)  # 200 ms newest - 150 ms


@pytest.mark.anyio
async def test_listener_feeds_buffer_and_statistics() -> None:
    """The live path: TransformListener -> MonitoredSink -> Buffer and TfStatistics, the
    receive time from the clock, the authority from the callback, bad transforms counted
    by the listener and kept out of the buffer."""
    clock = ManualClock(Time.from_ns(T0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfStatistics()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer-static" if static else "peer")
    async with Bus() as bus, TransformListener(sink, bus, clock=clock) as listener:
        await bus.publish("/tf_static", TFMessage([tf("map", "odom", 0)]))
        for k in range(3):
            await clock.set(Time.from_ns(T0 + k * 100 * MS + 5 * MS))
            await bus.publish("/tf", TFMessage([tf("odom", "base", T0 + k * 100 * MS)]))
            with anyio.fail_after(5):
                while stats.messages.get("/tf", 0) < k + 1:
                    await anyio.sleep(0)
        assert buffer.lookup_transform("map", "base", Time(0)).header.stamp.ns == T0 + 200 * MS
        assert listener.statistics().stored == 4
    base = stats.frames["base"]
    assert base.rate == pytest.approx(10.0) and base.delay_avg == pytest.approx(0.005)
    assert base.authority == "peer" and stats.frames["odom"].authority == "peer-static"
    buffer.close()
