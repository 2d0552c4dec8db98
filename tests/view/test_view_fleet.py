"""The fleet selector of ``tfbus view`` (tfbus/view/fleet.py): on a ``namespace=*`` bus
(FleetBuffer, merged: frames prefixed with each robot's name) or a bag of such frames,
one robot or all side by side (offset along x so that no two overlap), each in its own
fixed frame. Live with two robots over Zenoh (a router on tcp/127.0.0.1, client sessions,
no scouting) driven in headless Chromium through the DevTools protocol; on a bag with the
slider."""

from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path

import pytest

pytest.importorskip("viser")

from proc_lines import ProcLines
from test_view_controls import _pick, until

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.view.fleet import ALL_ROBOTS, GAP, MIN_SLOT, FleetView, robot_fixed_frame, robot_of
from tfbus.view.player import BagPlayer
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

T0 = 1_700_000_000 * 10**9
MS = 1_000_000
ODD = "<img src=x onerror=alert(3)>"
"""A robot named with markup (no '/': a namespace is one segment)."""


def tf(parent: str, child: str, x: float, stamp_ns: int = T0) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def positions(page: TfPage, names: list[str]) -> dict[str, tuple[float, ...]]:
    return {n: tuple(round(float(v), 6) for v in page.frames[n].position) for n in names}


def test_robot_names_and_fixed_frames() -> None:
    assert [robot_of(n) for n in ("robot7/base_link", "base_link", "/x", "r/", "a/b/c")] \
        == ["robot7", None, None, None, "a"]
    parents = {"r1/odom": "r1/map", "r1/base": "r1/odom", "r1/tag": "r1/cam_root"}
    frames = ["r1/map", "r1/odom", "r1/base", "r1/cam_root", "r1/tag"]
    assert robot_fixed_frame("r1", frames, parents, None) == "r1/map"  # the largest tree
    assert robot_fixed_frame("r1", frames, parents, "r2/odom") == "r1/odom"
    assert robot_fixed_frame("r1", frames, parents, "odom") == "r1/odom"
    assert robot_fixed_frame("r1", frames, parents, "r2/dock") == "r1/map"
    assert robot_fixed_frame("r1", [], {}, None) is None


def fleet_bag(path: Path) -> Path:
    """4 s: robot1 ``map -> base`` (x 1, 10 Hz) and static ``base -> laser`` (x 0.5) from
    the start; robot2 ``map -> base`` (x 3) from 2 s on, static ``base -> laser`` (0.25);
    a robot named with markup, :data:`ODD`, one frame ``map -> base`` (x 2) from 3 s on."""
    from rosbags.rosbag1 import Writer

    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore, to_rosbags

    store = tf_typestore(ros1=True)
    records: list[tuple[int, str, list[TransformStamped]]] = [
        (T0, "/tf_static", [tf("robot1/base", "robot1/laser", 0.5)])]
    for k in range(40):
        t = T0 + k * 100 * MS
        records.append((t + 1000, "/tf", [tf("robot1/map", "robot1/base", 1.0, t)]))
        if k == 20:
            records.append((t + 500, "/tf_static", [tf("robot2/base", "robot2/laser", 0.25,
                                                       t)]))
        if k >= 20:
            records.append((t + 2000, "/tf", [tf("robot2/map", "robot2/base", 3.0, t)]))
        if k >= 30:
            records.append((t + 3000, "/tf", [tf(f"{ODD}/map", f"{ODD}/base", 2.0, t)]))
    with Writer(path) as writer:
        conns = {topic: writer.add_connection(topic, ROSBAGS_TF_TYPE, typestore=store,
                                              callerid="/bc")
                 for topic in ("/tf", "/tf_static")}
        for t, topic, tfs in sorted(records, key=lambda r: r[0]):
            writer.write(conns[topic], t, store.serialize_ros1(
                to_rosbags(store, tfs, ros1=True), ROSBAGS_TF_TYPE))
    return path


def test_fleet_on_a_bag_follows_the_slider(page: TfPage, tmp_path: Path) -> None:
    fleet = FleetView(page)
    player = BagPlayer(page, BagTimeline.read(fleet_bag(tmp_path / "fleet.bag")),
                       paused=True, fleet=fleet)
    player.seek(1.0)
    player.render()
    assert fleet.robots == ("robot1",)
    assert fleet.dropdown.options == (ALL_ROBOTS, "robot1")
    assert positions(page, ["robot1/map", "robot1/base", "robot1/laser"]) == {
        "robot1/map": (0.0, 0.0, 0.0), "robot1/base": (1.0, 0.0, 0.0),
        "robot1/laser": (1.5, 0.0, 0.0)}
    player.seek(3.5)
    player.render()
    assert fleet.robots == (ODD, "robot1", "robot2")
    # side by side, sorted by name: x extent 0 .. 3.25 m, + GAP
    slot = max(MIN_SLOT, 3.25 + GAP)
    assert fleet.offsets == {ODD: 0.0, "robot1": slot, "robot2": 2 * slot}
    assert positions(page, ["robot1/base", "robot2/map", "robot2/laser", f"{ODD}/base"]) == {
        "robot1/base": (slot + 1.0, 0.0, 0.0), "robot2/map": (2 * slot, 0.0, 0.0),
        "robot2/laser": (2 * slot + 3.25, 0.0, 0.0), f"{ODD}/base": (2.0, 0.0, 0.0)}
    # no two robots overlap: each robot's frames lie in its own slot
    for k, robot in enumerate(sorted(fleet.offsets)):
        xs = [page.frames[n].position[0] for n in page.frames if n.startswith(robot + "/")]
        assert k * slot <= min(xs) and max(xs) <= (k + 1) * slot - GAP + 1e-9
    odd = "&lt;img src=x onerror=alert(3)&gt;"
    assert f"{odd}: fixed frame {odd}/map, x +0.00 m" in fleet.html_value
    assert "<img" not in fleet.html_value
    # one robot: at its own origin, the others not drawn
    fleet.pick("robot2")
    player.render()
    assert positions(page, ["robot2/base"]) == {"robot2/base": (3.0, 0.0, 0.0)}
    assert not page.frames["robot1/base"].visible and not page.frames[f"{ODD}/base"].visible
    assert page.frames["robot2/base"].visible
    assert fleet.dropdown.value == "robot2"
    # back before robot2's first transform: it has no frames; the page says so
    player.seek(1.0)
    scene = player.render()
    assert scene.frames == () and scene.message == "no frames of robot robot2 received"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.anyio
async def test_two_robots_over_zenoh_in_chromium(chromium: str, page: TfPage) -> None:
    """robot1 and robot2 on their own namespaces through a Zenoh router; the view's
    fleet bus (``namespace=*``, FleetBuffer merged into the view's buffer through a
    MonitoredSink, as ``tfbus view --bus 'zenoh:namespace=*'`` wires it): all robots side
    by side, then robot2 picked in the page, then all again re-rooted at each robot's
    base."""
    pytest.importorskip("zenoh")
    import anyio
    from cdp import Chromium

    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.fleet import FleetBuffer
    from tfbus.messages import TFMessage
    from tfbus.monitor import MonitoredSink, TfSummary
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.router import ZenohRouter
    from tfbus.view.live import LiveView

    def bus(endpoint: str, namespace: str, name: str) -> Bus:
        return Bus(transport=ZenohTransport(connect=endpoint, config={"mode": "client"},
                                            namespace=namespace, name=name))

    async def wait_until(predicate: Callable[[], bool], timeout: float = 20.0) -> None:
        with anyio.fail_after(timeout):
            while not predicate():
                await anyio.sleep(0.02)

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    clock = ManualClock(Time.from_ns(T0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    summary = TfSummary()
    async with ZenohRouter(listen=endpoint), bus(endpoint, "*", "view") as fbus, \
            FleetBuffer(fbus, merged=True, sink=MonitoredSink(buffer, summary, clock),
                        clock=clock) as fleet, \
            bus(endpoint, "robot1", "r1") as r1, bus(endpoint, "robot2", "r2") as r2:
        selector = FleetView(page, lambda: fleet.robots())
        view = LiveView(page, buffer, summary, clock, fleet=selector)
        await fleet.wait_for_robot("robot1", timeout=20)
        await fleet.wait_for_robot("robot2", timeout=20)
        for r, x, lx in ((r1, 1.0, 0.5), (r2, 3.0, 0.25)):
            r.publish_nowait("/tf_static", TFMessage([tf("base", "laser", lx)]))
            await wait_until(lambda r=r: r.transport.matching("/tf"))  # type: ignore[attr-defined]
            r.publish_nowait("/tf", TFMessage([tf("map", "base", x)]))
        await wait_until(lambda: fleet.statistics().transforms == 4)
        view.render()
        slot = max(MIN_SLOT, 3.25 + GAP)
        names = ["robot1/map", "robot1/base", "robot1/laser", "robot2/map", "robot2/base",
                 "robot2/laser"]
        assert positions(page, names) == {
            "robot1/map": (0.0, 0.0, 0.0), "robot1/base": (1.0, 0.0, 0.0),
            "robot1/laser": (1.5, 0.0, 0.0), "robot2/map": (slot, 0.0, 0.0),
            "robot2/base": (slot + 3.0, 0.0, 0.0), "robot2/laser": (slot + 3.25, 0.0, 0.0)}

        def pick_robot2() -> str:
            with Chromium(chromium) as c:
                c.open(f"http://127.0.0.1:{page.port}/")
                c.wait("document.body && document.body.innerText.includes("
                       "'robot2: fixed frame robot2/map')")
                _pick(c, "robot", "robot2")
                until(lambda: selector.choice == "robot2", "robot2 picked")
                return str(c.js("document.body.innerText"))

        text = await anyio.to_thread.run_sync(pick_robot2)
        assert f"robot2: fixed frame robot2/map, x +{slot:.2f} m" in text
        view.render()  # the draw loop's next tick
        assert positions(page, ["robot2/map", "robot2/laser"]) == {
            "robot2/map": (0.0, 0.0, 0.0), "robot2/laser": (3.25, 0.0, 0.0)}
        assert not any(page.frames[n].visible for n in names[:3])
        assert selector.html_value.count("fixed frame") == 1
        # all robots again, each from the frame named like the page's fixed frame
        selector.pick(None)
        page.fixed_frame_choice = "robot2/base"
        view.render()
        assert selector.fixed_frames == {"robot1": "robot1/base", "robot2": "robot2/base"}
        slot = max(slot, 3.5 + GAP)  # x from -3 (robot2/map) to 0.5 (robot1/laser)
        assert selector.slot == slot
        assert positions(page, ["robot1/map", "robot1/base", "robot2/map", "robot2/base"]) == {
            "robot1/map": (-1.0, 0.0, 0.0), "robot1/base": (0.0, 0.0, 0.0),
            "robot2/map": (slot - 3.0, 0.0, 0.0), "robot2/base": (slot, 0.0, 0.0)}
    buffer.close()


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_fleet_flag_needs_a_bag() -> None:
    from click.testing import CliRunner

    from tfbus.cli import cli

    result = CliRunner().invoke(cli, ["view", "--fleet", "--bus", "memory", "--port", "0"])
    assert result.exit_code == 2
    assert result.stderr.strip() == ("tfbus view: error: --fleet applies to --bag only (a "
                                     "namespace=* bus always has the robot selector)")


@pytest.mark.anyio
async def test_command_on_a_fleet_bus_in_chromium(chromium: str) -> None:
    """``tfbus view --bus 'zenoh:mode=client&connect=...&namespace=*'`` as a process: two
    robots publish through a Zenoh router on 127.0.0.1; the page lists both side by side
    (each from its own map). SIGINT ends it with status 0; it is killed by PID if not."""
    pytest.importorskip("zenoh")
    import signal
    import subprocess
    import sys

    import anyio
    from cdp import Chromium

    from tfbus.bus import Bus
    from tfbus.messages import TFMessage
    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.router import ZenohRouter

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    port = free_port()
    exe = Path(sys.executable).with_name("tfbus")
    async with ZenohRouter(listen=endpoint):
        proc = subprocess.Popen(
            [str(exe), "view", "--bus", f"zenoh:mode=client&connect={endpoint}&namespace=*",
             "--port", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True)
        try:
            assert ProcLines(proc).first() == f"tfbus view: http://127.0.0.1:{port}/"
            robots = [Bus(transport=ZenohTransport(connect=endpoint, config={"mode": "client"},
                                                   namespace=f"robot{k}", name=f"r{k}"))
                      for k in (1, 2)]
            async with robots[0] as r1, robots[1] as r2:
                slot = max(MIN_SLOT, 3.0 + GAP)
                want = ["robot1: fixed frame robot1/map, x +0.00 m",
                        f"robot2: fixed frame robot2/map, x +{slot:.2f} m"]

                def shown() -> str:  # until both robots are placed (each heard in its turn)
                    with Chromium(chromium) as c:
                        c.open(f"http://127.0.0.1:{port}/")
                        return str(c.wait(
                            "document.body && " + " && ".join(
                                f"document.body.innerText.includes({w!r})" for w in want)
                            + " && document.body.innerText", timeout=60))

                with anyio.fail_after(60):  # until the view hears both robots' statics
                    async with anyio.create_task_group() as tg:
                        async def publish() -> None:
                            while True:  # latched statics, re-sent until the page shows them
                                for r, x in ((r1, 1.0), (r2, 3.0)):
                                    r.publish_nowait("/tf_static",
                                                     TFMessage([tf("map", "base", x)]))
                                await anyio.sleep(0.2)

                        tg.start_soon(publish)
                        text = await anyio.to_thread.run_sync(shown)
                        tg.cancel_scope.cancel()
            assert all(w in text for w in want)
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=30) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
