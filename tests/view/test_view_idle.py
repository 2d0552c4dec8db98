"""``tfbus view`` draws nothing for nobody: with no browser connected the live view's draw
loop sleeps (no scene update while transforms arrive), a headless Chromium connecting
wakes it at once (the page shows the newest frames with no clock tick in between), and
once the browser has gone the loop sleeps again."""

from __future__ import annotations

import anyio
import pytest

pytest.importorskip("viser")

from test_view_browser import dom, row

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.view.live import LiveView
from tfbus.view.server import TfPage

pytestmark = pytest.mark.anyio


async def test_no_browser_no_drawing_a_browser_wakes_it_at_once(chromium: str,
                                                                page: TfPage) -> None:
    clock = ManualClock(Time.from_sec(10.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    url = f"http://127.0.0.1:{page.port}/"

    def arm(x: float) -> TransformStamped:
        return TransformStamped(Header(clock.now(), "odom"), "arm",
                                Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))

    async with Bus() as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:
        view = LiveView(page, buffer, stats, clock)
        tg.start_soon(view.run, bus)
        with anyio.fail_after(60):
            while view.idle == 0:  # the loop went to sleep: nobody looks
                await clock.advance(1 / 30)
        for k in range(30):  # a second of transforms and ticks: nothing drawn
            bus.publish_nowait("/tf", TFMessage([arm(1.0 + 0.1 * k)]))
            await clock.advance(1 / 30)
        assert "arm" not in page.frames and "arm" not in page.panel_html
        # a browser connects: drawn at once, with no tick of the view's clock
        shown = await anyio.to_thread.run_sync(dom, chromium, url, "<td>arm</td>")
        assert row(shown, "arm")[1:2] == ["odom"]
        assert tuple(page.frames["arm"].position) == pytest.approx((3.9, 0.0, 0.0))
        # the browser has gone: the loop sleeps again and draws nothing more
        with anyio.fail_after(60):
            while page.watched():
                await anyio.sleep(0.05)
        idle = view.idle
        with anyio.fail_after(60):
            while view.idle == idle:
                bus.publish_nowait("/tf", TFMessage([arm(7.0)]))
                await clock.advance(1 / 30)
        await clock.advance(1.0)
        assert tuple(page.frames["arm"].position) != pytest.approx((7.0, 0.0, 0.0))
        tg.cancel_scope.cancel()
    buffer.close()


def test_bag_player_plays_undrawn_with_no_browser(page: TfPage) -> None:
    """A playing bag with nobody looking: its time goes on, nothing is drawn; the same
    loop with a browser counted as present draws every tick."""
    import threading
    from pathlib import Path

    from tfbus.view.player import BagPlayer
    from tfbus.view.timeline import BagTimeline

    bag = Path(__file__).resolve().parents[1] / "data" / "webviz_turtle_tf_example.bag"
    player = BagPlayer(page, BagTimeline.read(bag))
    drawn: list[float] = []
    real = player.render
    player.render = lambda: drawn.append(player.position) or real()  # type: ignore[method-assign]

    def ticks(watched: bool) -> None:
        stop = threading.Event()
        t = [0.0]

        def clock() -> float:  # 0.1 s of bag time per tick; stops itself after 20 ticks
            t[0] += 0.1
            if t[0] > 2.0:
                stop.set()
            return t[0]

        page.watched = lambda: watched  # type: ignore[method-assign]
        player.run(stop, clock=clock)

    ticks(False)
    assert drawn == [] and player.position == pytest.approx(1.9)
    ticks(True)
    assert len(drawn) == 19 and drawn[-1] == pytest.approx(3.8)
