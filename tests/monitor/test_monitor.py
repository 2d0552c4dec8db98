"""tf_monitor's statistics (tfbus.monitor), hand-computed: rates (one definition), delays,
broadcasters, the chain and its net delay, simulated time; and the live path, a
TransformListener feeding a Buffer and the statistics through MonitoredSink (asyncio and
trio, time driven by ManualClock)."""

from __future__ import annotations

from typing import Any

import anyio
import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.monitor import MonitoredSink, TfSummary, frame_chain, link_rate

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
    s = TfSummary()
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
    s = TfSummary()
    chain = s.watch_chain("b", "c")
    assert chain.frames is None
    s.add(Time.from_ns(T0 + 10 * MS), [tf("world", "a", T0), tf("a", "b", T0)], "n",
          static=False)
    s.add(Time.from_ns(T0 + 50 * MS), [tf("world", "c", T0 + 40 * MS)], "n", static=False)
    assert chain.frames == ("b", "a", "world", "c")
    # Only the second message saw a connected chain: 50 ms - min(0, 0, 40) ms.
    assert chain.delay_count == 1 and chain.delay_avg == pytest.approx(0.05)


def test_simulated_time_delays_use_the_newest_stamp() -> None:
    s = TfSummary()
    for k in range(3):
        s.add(Time.from_ns(T0 + k * 100 * MS), [tf("map", "odom", 10**10 + k * 100 * MS)], "a",
              static=False)
    s.add(Time.from_ns(T0 + 400 * MS), [tf("odom", "base", 10**10 + 150 * MS)], "a",
          static=False)
    assert s.sim_time is True
    assert s.frames["odom"].delay_max == 0.0
    assert s.frames["base"].delay_avg == pytest.approx(0.05)  # 200 ms newest - 150 ms


@pytest.mark.anyio
async def test_listener_feeds_buffer_and_summary() -> None:
    """The live path: TransformListener -> MonitoredSink -> Buffer and TfSummary, the
    receive time from the clock, the authority from the callback, bad transforms counted
    by the listener and kept out of the buffer."""
    clock = ManualClock(Time.from_ns(T0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
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


# --------------------------------------------------------------------------- rendering the table


def _render(stats_src: object, frames: tuple[str, ...] = ()) -> str:
    import io

    from rich.console import Console

    from tfbus.cli._bus_source import BusSource
    from tfbus.cli.monitor import print_monitor

    assert isinstance(stats_src, BusSource)
    buf = io.StringIO()
    print_monitor(Console(file=buf, width=200), stats_src.summary(), frames,
                  live_src=stats_src)
    return buf.getvalue()


def _row(text: str, first: str) -> list[str]:
    (line,) = [ln for ln in text.splitlines() if ln.split("│")[0].strip() == first]
    return [cell.strip() for cell in line.split("│")]


def test_a_dead_broadcasters_frames_stop_showing_their_old_rate() -> None:
    """100 Hz for 5 s from 'robot', then silence: the live tables show the rate over the
    last RATE_WINDOW (10 s) of receive time, so 100 Hz while it runs; once it has been
    silent for STALE_PERIODS (5) of its periods and at least STALE_AFTER (1 s), it is
    stale: 0.000 and marked so (the whole-run rate is kept for bags)."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.monitor import RATE_WINDOW, STALE_AFTER, STALE_PERIODS

    src = BusSource("memory")
    stats = src.summary()
    for i in range(501):  # 0 .. 5 s, stamps = receive times - 1 ms
        t = T0 + i * 10 * MS
        stats.add(Time.from_ns(t), [tf("base_link", "base_laser", t - MS)], "robot",
                  static=False)
    last = Time.from_ns(T0 + 5000 * MS)
    assert (RATE_WINDOW, STALE_PERIODS, STALE_AFTER) == (10.0, 5.0, 1.0)
    frame, robot = stats.frames["base_laser"], stats.authorities["robot"]
    assert frame.recent_rate(last) == pytest.approx(100.0)
    assert robot.recent_rate(last) == pytest.approx(100.0)
    # 0.9 s of silence: less than max(1 s, 5 periods of 10 ms): still running
    assert frame.recent_rate(Time.from_ns(last.ns + 900 * MS)) == pytest.approx(100.0)
    assert not frame.stale(Time.from_ns(last.ns + 900 * MS))
    # 1.1 s of silence: stale, its rate falls to 0 (it used to stay 100 Hz for 10 s)
    later = Time.from_ns(last.ns + 1100 * MS)
    assert frame.stale(later) and robot.stale(later)
    assert frame.recent_rate(later) == 0.0 == robot.recent_rate(later)
    src.clock = ManualClock(last)  # type: ignore[assignment]
    assert _row(_render(src), "base_laser")[3] == "100.000"
    assert _row(_render(src), "robot")[1] == "100.000"
    src.clock = ManualClock(later)  # type: ignore[assignment]
    assert _row(_render(src), "base_laser")[3] == "0.000 stale"
    assert _row(_render(src), "robot")[1] == "0.000 stale"
    src.clock = ManualClock(Time.from_ns(last.ns + 10_001 * MS))  # type: ignore[assignment]
    assert frame.recent_rate(src.clock.now()) == 0.0 == robot.recent_rate(src.clock.now())
    assert len(frame.received) == 0 == len(robot.received)  # the window let go of all
    assert frame.rate == pytest.approx(100.0)  # the whole-run rate, for bags


def test_memory_per_frame_is_bounded_whatever_the_run_time() -> None:
    """5 000 transforms/s on one frame for 60 s of receive time (300 000 distinct
    stamps): the frame keeps at most RECENT_SAMPLES (1000) samples and stamps (the
    summary used to keep a set of every stamp ever received), the broadcaster as many;
    the whole-run rate still counts every distinct stamp: 299 999 / 59.9998 s."""
    from tfbus.monitor import RECENT_SAMPLES

    s = TfSummary()
    us = 1000
    for i in range(300_000):  # every 200 us
        t = T0 + i * 200 * us
        s.add(Time.from_ns(t), [tf("odom", "base", t - MS)], "a", static=False)
    f, a = s.frames["base"], s.authorities["a"]
    assert RECENT_SAMPLES == 1000
    assert len(f.received) == 1000 and len(f.stamps) == 1000 and len(a.received) == 1000
    assert f.distinct_stamps == 300_000
    assert f.rate == pytest.approx(299_999 / 59.9998)
    now = Time.from_ns(T0 + 299_999 * 200 * us)
    # the last 1000 samples span 999 x 200 us: 5000 Hz
    assert f.recent_rate(now) == pytest.approx(5000.0) == a.recent_rate(now)


def test_recent_rate_by_hand_with_repeats_and_window() -> None:
    """Stamps (ms) 0, 100, 100 (repeated: kept once), 200, 400, 700, received 10 ms
    later. At 710 ms every sample is in the 10 s window: 5 distinct stamps over 0.7 s
    = 4 / 0.7 Hz. At 10 150 ms the window starts at 150 ms: stamps 200, 400, 700 = 2 /
    0.5 Hz... but 9.44 s of silence is stale (> 5 periods of 0.25 s, > 1 s): 0.0."""
    from tfbus.monitor import RateWindow

    s = TfSummary()
    for stamp in (0, 100, 100, 200, 400, 700):
        s.add(Time.from_ns(T0 + (stamp + 10) * MS), [tf("o", "b", T0 + stamp * MS)], "a",
              static=False)
    f = s.frames["b"]
    assert f.recent_rate(Time.from_ns(T0 + 710 * MS)) == pytest.approx(4 / 0.7)
    assert f.distinct_stamps == 5 and f.count == 6
    w = RateWindow(10.0, 1000)
    for stamp in (0, 100, 200, 400, 700):
        w.add((stamp + 10) * MS, stamp * MS)
    w.age(Time.from_ns(10_150 * MS))
    assert sorted(w.values()) == [200 * MS, 400 * MS, 700 * MS]
    assert w.stale(Time.from_ns(10_150 * MS))
    assert w.rate(Time.from_ns(10_150 * MS)) == 0.0
    w2 = RateWindow(1.0, 3)  # a short window, capped at 3 samples: 1.0 / 2 s ... by hand
    for k in range(5):
        w2.add(k * 100 * MS, k * 100 * MS)
    assert sorted(w2.values()) == [200 * MS, 300 * MS, 400 * MS]
    assert w2.rate(Time.from_ns(450 * MS)) == pytest.approx(2 / 0.2)
    with pytest.raises(ValueError, match="window"):
        RateWindow(float("nan"))
    with pytest.raises(ValueError, match="maxlen"):
        RateWindow(1.0, 1)


def test_ros1_names_the_publisher_unknown_publisher_and_has_no_liveliness_table() -> None:
    """On ROS 1 the message does not name its sender: tf_monitor prints
    ``unknown_publisher``, and there is no liveliness table to print (it would be empty)."""
    from tfbus.cli._bus_source import BusSource

    src = BusSource("ros1:master=http://127.0.0.1:1")
    src.clock = ManualClock(Time.from_ns(T0 + 20 * MS))  # type: ignore[assignment]
    src.sink.set_transforms([tf("base_link", "base_laser", T0)], "x", False)
    assert set(src.summary().authorities) == {"unknown_publisher"}
    text = _render(src)
    assert _row(text, "base_laser")[2] == "unknown_publisher"
    assert "liveliness" not in text.lower()
    assert "unknown_publisher" in [c for c in _row(text, "unknown_publisher")]


@pytest.mark.anyio
async def test_messages_before_the_liveliness_go_to_the_broadcaster() -> None:
    """A message that arrives before its broadcaster's liveliness is first "unknown";
    once the one broadcaster is known it is accounted to it: no spurious row."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.transports.zenoh import PeerEvent

    src = BusSource("zenoh?connect=tcp/127.0.0.1:1")
    src.sink.set_transforms([tf("base_link", "base_laser", T0)], "x", False)
    assert set(src.summary().authorities) == {"unknown"}

    async def events():  # type: ignore[no-untyped-def]
        yield PeerEvent(True, "a1", "robot_tf_publisher", "")
        yield PeerEvent(True, "a1", "robot_tf_publisher", "/tf")

    await src._watch(events(), None)  # type: ignore[arg-type]
    stats = src.summary()
    assert set(stats.authorities) == {"robot_tf_publisher"}
    assert stats.authorities["robot_tf_publisher"].messages == 1
    assert stats.frames["base_laser"].authority == "robot_tf_publisher"
    text = _render(src)
    assert "unknown" not in text and "unattributed" not in text


@pytest.mark.parametrize("spec", ["zenoh", "ros1", "ros2:domain=7", "memory"])
def test_the_running_node_line_names_the_node(spec: str) -> None:
    """``tfbus demo broadcaster``'s "running the broadcaster node" line: a name on every
    transport (ROS 1 and ROS 2 transports have no ``name``), never an empty ``(node )``."""
    from tfbus.cli.demo import node_label
    from tfbus.demos.tutorial import BROADCASTER_NAME
    from tfbus.transports.spec import open_transport, parse_bus_spec

    transport = (None if spec == "memory"
                 else open_transport(parse_bus_spec(spec), default_name=BROADCASTER_NAME))
    name, ident = node_label(transport, BROADCASTER_NAME)
    if spec == "ros1":  # the caller id: a ROS graph name made unique by the pid
        assert name.startswith(f"/{BROADCASTER_NAME}_") and ident == name
    else:
        expected_id = {"zenoh": "", "ros2:domain=7": "ROS 2 domain 7", "memory": ""}
        assert (name, ident) == (BROADCASTER_NAME, expected_id[spec])


def test_demo_broadcaster_line_has_no_empty_node() -> None:
    from click.testing import CliRunner

    from tfbus.cli import cli

    result = CliRunner().invoke(cli, ["demo", "broadcaster", "--bus", "memory", "--duration",
                                      "0.05"], catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    first = result.stderr.splitlines()[0]
    assert first == "[ INFO] robot_tf_publisher: running the broadcaster node on memory"


@pytest.mark.anyio
async def test_a_second_broadcaster_does_not_make_the_first_unattributed() -> None:
    """Two live broadcasters on /tf: the wire does not name the sender, but a frame keeps
    the broadcaster it had while that one was alone (tf_monitor's frame -> authority
    map): no "unattributed" row for the first one's frames."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.transports.zenoh import PeerEvent, PeerInfo

    src = BusSource("zenoh?connect=tcp/127.0.0.1:1")
    alive: dict[str, PeerInfo] = {}
    src.alive_broadcasters = lambda: dict(alive)  # type: ignore[method-assign]

    async def appear(node: str, name: str) -> None:
        async def events():  # type: ignore[no-untyped-def]
            yield PeerEvent(True, node, name, "/tf")

        alive[node] = PeerInfo(node, name, frozenset({"/tf"}))
        await src._watch(events(), None)  # type: ignore[arg-type]

    await appear("a1", "robot_tf_publisher")
    src.sink.set_transforms([tf("base_link", "base_laser", T0)], "x", False)
    await appear("b2", "odom_publisher")
    src.sink.set_transforms([tf("base_link", "base_laser", T0 + 10 * MS)], "x", False)
    src.sink.set_transforms([tf("odom", "base_link", T0 + 10 * MS)], "x", False)
    stats = src.summary()
    assert stats.frames["base_laser"].authorities == {"robot_tf_publisher": 2}
    assert stats.authorities["robot_tf_publisher"].messages == 2
    # odom -> base_link appeared while both were alive: nothing says whose it is.
    assert stats.frames["base_link"].authority == "unattributed"


class _Peers:
    """A PeerAware transport's liveliness as ``BusSource`` reads it: ``broadcasters()``
    (its calls counted) and ``peers_version``."""

    peers_topic = "/tfbus/peers"
    node_id = "self"

    def __init__(self) -> None:
        self.alive: dict[str, Any] = {}
        self.peers_version = 0
        self.calls = 0

    def broadcasters(self) -> dict[str, Any]:
        self.calls += 1
        return dict(self.alive)


def test_the_attribution_reads_the_broadcasters_again_only_when_the_peers_change() -> None:
    """Every message's sender is named from the live broadcasters: read from the
    transport once per change of its ``peers_version``, not once per message, with the
    same names as before (one broadcaster: it; two: the frame's own or "unattributed";
    none: "unknown")."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.transports.zenoh import PeerInfo

    src = BusSource("zenoh?connect=tcp/127.0.0.1:1")
    peers = _Peers()
    src._peers = peers  # type: ignore[assignment]
    peers.alive["a1"] = PeerInfo("a1", "robot_tf_publisher", frozenset({"/tf"}))
    peers.peers_version = 1
    for i in range(5):
        src.sink.set_transforms([tf("base_link", "base_laser", T0 + i * MS)], "x", False)
    assert peers.calls == 1
    peers.alive["b2"] = PeerInfo("b2", "odom_publisher", frozenset({"/tf", "/tf_static"}))
    peers.peers_version = 2
    for i in range(5, 8):
        src.sink.set_transforms([tf("base_link", "base_laser", T0 + i * MS)], "x", False)
        src.sink.set_transforms([tf("odom", "base_link", T0 + i * MS)], "x", False)
    src.sink.set_transforms([tf("base_link", "laser_mount", T0)], "x", True)
    assert peers.calls == 2
    del peers.alive["a1"], peers.alive["b2"]
    peers.peers_version = 3
    src.sink.set_transforms([tf("map", "odom", T0)], "x", False)
    assert peers.calls == 3
    stats = src.summary()
    assert stats.frames["base_laser"].authorities == {"robot_tf_publisher": 8}
    assert stats.frames["base_link"].authorities == {"unattributed": 3}
    assert stats.frames["laser_mount"].authorities == {"odom_publisher": 1}  # /tf_static
    assert stats.frames["odom"].authorities == {"unknown": 1}


def test_the_command_line_asks_the_scheme_for_fleet_and_unknown_authority(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Whether a bus is a fleet bus and what an unnamed broadcaster is called are facts of
    the scheme table (``TransportScheme.fleet_option``, ``unknown_authority``), not of
    the scheme's name: a scheme registered with them gets both from the command line."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.transports import spec

    monkeypatch.setattr(spec, "_SCHEMES", spec.schemes())  # this test's rows only
    spec.register_scheme(spec.TransportScheme(
        "yard", "tfbus.transports.memory.options", keys=frozenset({"robots"}),
        fleet_option="robots", unknown_authority="nobody",
    ))
    assert BusSource("yard?robots=*").is_fleet
    assert not BusSource("yard?robots=r1").is_fleet
    assert not BusSource("yard").is_fleet
    src = BusSource("yard")
    src.clock = ManualClock(Time.from_ns(T0 + 20 * MS))  # type: ignore[assignment]
    src.sink.set_transforms([tf("base_link", "base_laser", T0)], "x", False)
    assert set(src.summary().authorities) == {"nobody"}
    rows = spec.schemes()
    assert rows["zenoh"].is_fleet(spec.parse_bus_spec("zenoh?namespace=*"))
    assert not rows["zenoh"].is_fleet(spec.parse_bus_spec("zenoh?namespace=robot1"))
    assert not rows["ros1"].is_fleet(spec.parse_bus_spec("ros1"))
    assert (rows["ros1"].unknown_authority, rows["zenoh"].unknown_authority) == (
        "unknown_publisher", None)
    src = BusSource("memory")
    src.sink.set_transforms([tf("base_link", "base_laser", T0)], "x", False)
    assert set(src.summary().authorities) == {"unknown"}


def test_a_live_monitor_with_expire_after_drops_and_counts_expired_frames() -> None:
    """``tfbus monitor --expire-after 2``: the buffer forgets 'cup' once the newest stamp
    is more than 2 s past its last one (checked once per second of stamp time); it
    leaves the Frames table and the buffer line counts it."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.core.policy import expire_after

    src = BusSource("memory", cache_policy=expire_after(2.0))
    src.sink.set_transforms([tf("map", "cup", T0), tf("map", "base", T0)], "robot")
    text = _render(src)
    assert _row(text, "cup")[1] == "map"
    assert "buffer: 3 frames, 2 links; 0 frames expired (no data for 2 s)" in text
    for k in range(1, 5):
        src.sink.set_transforms([tf("map", "base", T0 + k * 1000 * MS)], "robot")
    text = _render(src)
    assert not [ln for ln in text.splitlines() if ln.split("│")[0].strip() == "cup"]
    assert _row(text, "base")[1] == "map"
    assert "buffer: 2 frames, 1 links; 1 frames expired (no data for 2 s)" in text
    src.buffer().close()


def test_monitor_refuses_expire_after_with_a_bag() -> None:
    from click.testing import CliRunner

    from tfbus.cli import cli

    result = CliRunner().invoke(
        cli, ["monitor", "--bag", "tests/data/webviz_turtle_tf_example.bag", "--expire-after", "2"]
    )
    assert result.exit_code == 2, result.output
    assert "--expire-after applies to --bus sources only" in result.stderr
    result = CliRunner().invoke(cli, ["monitor", "--bus", "memory", "--expire-after", "1e-300"])
    assert result.exit_code == 2, result.output
    assert "--expire-after: expire_after seconds must be > 0, got 1e-300" in result.stderr


def test_frames_the_buffer_forgot_leave_the_summary() -> None:
    """``--expire-after 2``: 'cup' (map -> cup, dynamic, last stamped T0) keeps the static
    'handle' under it, so the buffer still knows the frame id 'cup' once its own link
    expired (``BufferCore.forget``: an id stays known while a link names it as a
    parent). The summary drops cup's row all the same (the buffer has no map -> cup any
    more), keeps the static 'handle' and the live 'base'; 200 frames each published once
    and forgotten leave the summary too, which holds only what the buffer holds."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.core.policy import expire_after

    src = BusSource("memory", cache_policy=expire_after(2.0))
    src.sink.set_transforms([tf("map", "cup", T0), tf("map", "base", T0)], "robot")
    src.sink.set_transforms([tf("cup", "handle", T0)], "robot", True)
    assert set(src.summary().frames) == {"cup", "base", "handle"}
    for k in range(1, 5):
        src.sink.set_transforms([tf("map", "base", T0 + k * 1000 * MS)], "robot")
    buffer = src.buffer()
    assert buffer.frame_exists("cup") and buffer.get_parent("cup") is None
    assert set(src.summary().frames) == {"base", "handle"}
    text = _render(src)
    assert not [ln for ln in text.splitlines() if ln.split("│")[0].strip() == "cup"]
    assert _row(text, "handle")[1] == "cup" and _row(text, "handle")[3] == "static"
    assert "buffer: 4 frames, 2 links; 1 frames expired (no data for 2 s)" in text
    # Churn: a new object frame every 100 ms of stamp time, each sent once.
    for k in range(200):
        stamp = T0 + 5000 * MS + k * 100 * MS
        src.sink.set_transforms([tf("map", f"obj{k}", stamp), tf("map", "base", stamp)],
                                "robot")
    frames = src.summary().frames
    assert frames.keys() == {"base", "handle"} | {f"obj{k}" for k in range(200)
                                                   if buffer.frame_exists(f"obj{k}")}
    assert len(frames) <= 2 + 31  # objects of the last 3 s of stamps at most
    assert buffer.statistics().frames_expired > 150
    buffer.close()


class _NaiveWindow:
    """The recent-rate window by its definition, with no cleverness: a list of (receive
    time, value) samples, a repeated value refused when ``distinct``, the oldest dropped
    beyond ``maxlen`` or ``window_ns`` before now, the rate over the smallest and largest
    value held."""

    def __init__(self, window_ns: int, maxlen: int, distinct: bool) -> None:
        self.window_ns, self.maxlen, self.distinct = window_ns, maxlen, distinct
        self.samples: list[tuple[int, int]] = []
        self.last: int | None = None

    def add(self, received: int, value: int) -> bool:
        self.last = received
        if self.distinct and value in [v for _, v in self.samples]:
            return False
        self.samples.append((received, value))
        del self.samples[:-self.maxlen]
        return True

    def age(self, now: int) -> None:
        while self.samples and self.samples[0][0] < now - self.window_ns:
            del self.samples[0]

    def span_rate(self, samples: list[tuple[int, int]]) -> float:
        vals = [v for _, v in samples]
        return link_rate(len(vals), min(vals), max(vals)) if len(vals) >= 2 else 0.0

    def rate(self, now: int) -> float:
        from tfbus.monitor import STALE_AFTER, STALE_PERIODS

        self.age(now)
        if self.samples and self.samples[-1][0] > now:
            return self.span_rate([s for s in self.samples if s[0] <= now])
        if self.last is None:
            return 0.0
        rate = self.span_rate(self.samples)
        period = 1.0 / rate if rate > 0 else 0.0
        stale = (now - self.last) / 1e9 > max(STALE_AFTER, STALE_PERIODS * period)
        return 0.0 if stale else rate


@pytest.mark.parametrize("distinct", [True, False])
def test_rate_window_matches_its_definition_on_any_order(distinct: bool) -> None:
    """RateWindow against :class:`_NaiveWindow` on streams in order, reversed, random,
    with repeated values and receive times that go back: the same answer to every add,
    the same samples held, values and rates (hypothesis)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from tfbus.monitor import RateWindow

    step = st.tuples(st.integers(0, 3), st.integers(0, 40), st.integers(-5, 5))

    @settings(max_examples=300, deadline=None, derandomize=True)
    @given(st.integers(2, 6), st.lists(step, max_size=60), st.sampled_from(["up", "down", "any"]))
    def check(maxlen: int, steps: list[tuple[int, int, int]], order: str) -> None:
        w = RateWindow(0.5, maxlen, distinct=distinct)
        ref = _NaiveWindow(w.window_ns, maxlen, distinct)
        received = T0
        for i, (kind, value, jump) in enumerate(steps):
            received += jump * 100 * MS
            stamp = {"up": i // 2, "down": -(i // 2), "any": value}[order] * 10 * MS + T0
            if kind == 3:  # read the rate at a time that may be before the last add
                now = Time.from_ns(received)
                assert w.rate(now) == ref.rate(received)
            else:
                assert w.add(received, stamp) == ref.add(received, stamp)
            assert w.values_by_time() == [r for r, _ in ref.samples]
            assert w.values() == {v for _, v in ref.samples}
            assert len(w) == len(ref.samples)

    check()


def test_a_frames_window_is_the_rate_window_fed_each_transform() -> None:
    """``TfSummary.add`` keeps each dynamic frame's recent samples as
    ``RateWindow.add(receive time, stamp)`` of each transform would, on streams in
    order, reversed, random, repeated and with receive times that go back, over the
    window's bound: the same window (``RateWindow.__eq__``: the samples held and their
    order) and ``distinct_stamps`` the adds that kept a sample (hypothesis)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from tfbus.monitor import RECENT_SAMPLES, RateWindow

    step = st.tuples(st.integers(0, 2), st.integers(0, 40), st.integers(-2, 5))

    @settings(max_examples=200, deadline=None, derandomize=True)
    @given(st.lists(step, max_size=80), st.sampled_from(["up", "down", "any"]))
    def check(steps: list[tuple[int, int, int]], order: str) -> None:
        summary = TfSummary()
        ref = {"a": RateWindow(), "b": RateWindow()}
        kept = {"a": 0, "b": 0}
        received = T0
        for i, (frames, value, jump) in enumerate(steps):
            received += jump * 10 * MS
            stamp = {"up": i, "down": -i, "any": value}[order] * 10 * MS + T0
            children = ("a", "b", "ab")[frames]
            summary.add(Time.from_ns(received), [tf("world", c, stamp) for c in children],
                        "default", static=False)
            for c in children:
                kept[c] += ref[c].add(received, stamp)
        for c, window in ref.items():
            if c in summary.frames:
                assert summary.frames[c].received == window
                assert summary.frames[c].distinct_stamps == kept[c]

    check()
    # past the bound, every 97th stamp late (out of order): each later sample pushes the
    # oldest out, and a late stamp held makes the rate read the smallest and largest held
    summary = TfSummary()
    window = RateWindow()
    for i in range(2 * RECENT_SAMPLES + 50):
        received = T0 + i * MS
        stamp = received - (50 * MS - 1 if i % 97 == 96 else 0)
        summary.add(Time.from_ns(received), [tf("world", "a", stamp)], "default",
                    static=False)
        window.add(received, stamp)
        if i % 10 == 0:
            now = Time.from_ns(received)
            assert summary.frames["a"].received.rate(now) == window.rate(now)
            assert summary.frames["a"].received == window
    assert summary.frames["a"].received == window
    assert len(window) == RECENT_SAMPLES
