"""``tfbus view`` in a real browser: Debian's headless Chromium opens the page served from
the turtle bag and from a live buffer; the screenshot is not blank, the frame names are in
the page's text, a frame whose broadcaster stopped is shown stale then hidden, and an id
with markup stays text.

Chromium runs as a child process in a session of its own with a fresh profile, driven
through CDP (``tests/view/cdp.py``: every wait on the page bounded); when it is done (or a
wait outlives its bound) the process group it leads is ended by its PID and the profile
removed (``headless_chromium.end_chromium``); everything is on 127.0.0.1.
"""

from __future__ import annotations

import html
import io
import json
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("viser")
Image = pytest.importorskip("PIL.Image")  # viser's own dependency (through imageio)

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.bag import read_messages  # noqa: E402
from tfbus.clock import ManualClock  # noqa: E402
from tfbus.core import BufferCore  # noqa: E402
from tfbus.monitor import TfSummary  # noqa: E402
from tfbus.view.player import BagPlayer, draw_live  # noqa: E402
from tfbus.view.server import TfPage  # noqa: E402
from tfbus.view.timeline import BagTimeline  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"


def dom(exe: str, url: str, until: str) -> str:
    """The page's DOM once ``until`` is in it: one headless Chromium opens ``url`` through
    CDP (``tests/view/cdp.py``) and the DOM is read again until the viser client has drawn
    what the server sent (at most 60 s; a page that never shows it fails with that
    text). A wait on the page itself, not on Chromium's virtual-time budget: a loaded
    machine made a cold ``--dump-dom`` run outlive its bound three times over."""
    from cdp import Chromium

    with Chromium(exe) as c:
        c.open(url)
        c.wait(f"document.documentElement.outerHTML.includes({json.dumps(until)})")
        return c.html()


SCENE = (330, 260, 930, 740)
"""A box of the 1280 x 800 page that only the 3D scene draws into (left of the side
panel, below viser's notices, above its orientation gizmo): flat until the scene is
drawn."""


def _scene_drawn(shot: Any) -> bool:
    """Whether the scene box of ``shot`` holds more than one flat colour (grid lines,
    axes, labels drawn)."""
    lo, hi = shot.convert("L").crop(SCENE).getextrema()
    return bool(hi - lo > 100)


def screenshot(exe: str, url: str, path: Path, until: str, timeout: float = 60.0) -> Any:
    """A screenshot of ``url`` (also written to ``path``) in one headless Chromium driven
    through CDP, once the page's text holds ``until`` (what the server sent is there)
    and its scene is drawn (:func:`_scene_drawn`; the viser client fades its scene in
    after loading and draws as the websocket delivers it, slower on a loaded machine):
    each waited for at most ``timeout`` seconds. The last shot either way: a page that
    never draws fails the caller's assertions on it."""
    from cdp import Chromium

    with Chromium(exe) as c:
        # the viewport of 1280 x 800 CSS pixels that ``--window-size`` gives ``--screenshot``
        c.call("Emulation.setDeviceMetricsOverride", width=1280, height=800,
               deviceScaleFactor=1, mobile=False)
        c.open(url)
        c.wait(f"document.body.innerText.includes({json.dumps(until)})", timeout)
        deadline = time.monotonic() + timeout
        while True:
            shot = Image.open(io.BytesIO(c.screenshot(path)))
            if _scene_drawn(shot) or time.monotonic() > deadline:
                return shot
            time.sleep(0.2)


def row(page_dom: str, frame_text: str) -> list[str]:
    """The cells of the frame-tree row of ``frame_text`` (as the DOM holds it, escaped)."""
    m = re.search(r"<tr><td>" + re.escape(frame_text) + r"</td>(.*?)</tr>", page_dom)
    assert m is not None, f"no row for {frame_text!r}"
    return [frame_text, *re.findall(r"<td>(.*?)</td>", m.group(1))]


def test_bag_page_in_chromium(chromium: str, page: TfPage, tmp_path: Path) -> None:
    timeline = BagTimeline.read(TURTLE)
    player = BagPlayer(page, timeline, paused=True)
    player.seek(10.0)
    player.render()
    url = f"http://127.0.0.1:{page.port}/"
    shot = screenshot(chromium, url, tmp_path / "turtle.png", "bag time 10.00 / 21.50 s")
    grey = shot.convert("L")
    assert grey.size == (1280, 800)
    assert _scene_drawn(shot)  # the scene itself, not only the panel
    lo, hi = grey.getextrema()
    assert hi - lo > 100  # not a blank canvas: grid lines, axes, labels, the panel
    colours = len(shot.convert("RGB").getcolors(maxcolors=1 << 24) or [])
    assert colours > 50
    text = dom(chromium, url, "bag time 10.00 / 21.50 s")
    names = {t.child_frame_id for rec in read_messages(TURTLE) for t in rec.message.transforms}
    names |= {t.header.frame_id for rec in read_messages(TURTLE) for t in rec.message.transforms}
    assert names == {"world", "turtle1", "turtle2", "carrot"}
    for name in names:
        assert f"<td>{name}</td>" in text
    assert row(text, "turtle1")[1] == "world" and row(text, "turtle1")[4] == "ok"
    assert row(text, "carrot")[4] == "static"
    # a static link reads "static" in the Hz column (was "0.0"), a root frame nothing
    assert row(text, "carrot")[2] == "static" and row(text, "turtle1")[2] == "0.0"
    assert row(text, "world")[2] == ""
    assert "white-space:nowrap" in text  # one line per frame: columns never wrap
    assert "bag time 10.00 / 21.50 s" in text


def test_live_frame_goes_stale_then_hidden(chromium: str, page: TfPage) -> None:
    clock = ManualClock(Time.from_sec(100.0))
    core, stats = BufferCore(), TfSummary()
    odd = "<b>bold</b>&amp;"

    def send(child: str, parent: str = "world") -> None:
        t = TransformStamped(Header(clock.now(), parent), child,
                             Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
        core.set_transform(t, "bc_" + child)
        stats.add(clock.now(), [t], "bc_" + child, static=False)

    send("base_link")
    send(odd)
    url = f"http://127.0.0.1:{page.port}/"
    draw_live(page, core, stats, clock.now(), frame_timeout=3.0)
    first = dom(chromium, url, "<td>base_link</td>")
    assert row(first, "base_link")[4] == "ok"
    # the id with markup is text in the page: escaped in the DOM, never an element
    escaped = html.escape(odd)
    assert row(first, escaped)[4] == "ok"
    assert "<b>bold</b>" not in first
    # base_link's broadcaster stops; odd's keeps sending
    for _ in range(4):
        clock.advance_nowait(0.5)
        send(odd)
    draw_live(page, core, stats, clock.now(), frame_timeout=3.0)  # base_link silent 2 s
    second = dom(chromium, url, "<td>stale</td>")
    assert row(second, "base_link")[4] == "stale" and row(second, "base_link")[3] == "2.0 s"
    assert row(second, escaped)[4] == "ok"
    assert page.frames["base_link"].visible
    clock.advance_nowait(1.5)  # silent 3.5 s > 3 s timeout: hidden
    draw_live(page, core, stats, clock.now(), frame_timeout=3.0)
    third = dom(chromium, url, "hidden (timed out)")
    assert row(third, "base_link")[4] == "hidden (timed out)"
    assert not page.frames["base_link"].visible


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.mark.anyio
async def test_live_bus_page_in_chromium(chromium: str, page: TfPage) -> None:
    """The live path as ``tfbus view --bus`` runs it: broadcasters on a bus ->
    TransformListener -> MonitoredSink (Buffer + TfSummary, receive time from a
    ManualClock) -> draw_live; one broadcaster stops and its frame turns stale."""
    import anyio

    from tfbus.broadcaster import TransformBroadcaster
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink

    clock = ManualClock(Time.from_sec(50.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "peer")
    url = f"http://127.0.0.1:{page.port}/"

    def tf(child: str, x: float) -> TransformStamped:
        return TransformStamped(Header(clock.now(), "odom"), child,
                                Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))

    async with Bus() as bus, TransformListener(sink, bus, clock=clock):
        arm, cam = TransformBroadcaster(bus), TransformBroadcaster(bus)

        async def send(*which: tuple[TransformBroadcaster, str, float]) -> None:
            before = stats.messages.get("/tf", 0)
            for b, child, x in which:
                await b.send_transform(tf(child, x))
            with anyio.fail_after(5):
                while stats.messages.get("/tf", 0) < before + len(which):
                    await anyio.sleep(0)

        await send((arm, "arm", 1.0), (cam, "camera", 2.0))
        draw_live(page, buffer, stats, clock.now(), frame_timeout=6.0)
        first = await anyio.to_thread.run_sync(dom, chromium, url, "<td>camera</td>")
        assert row(first, "arm")[1:2] == ["odom"] and row(first, "arm")[4] == "ok"
        assert row(first, "camera")[4] == "ok"
        assert tuple(page.frames["camera"].position) == (2.0, 0.0, 0.0)
        for k in range(6):  # the camera's broadcaster stopped; the arm keeps going
            await clock.advance(0.5)
            await send((arm, "arm", 1.0 + 0.1 * (k + 1)))
        draw_live(page, buffer, stats, clock.now(), frame_timeout=6.0)
        second = await anyio.to_thread.run_sync(dom, chromium, url, "<td>stale</td>")
        assert row(second, "camera")[4] == "stale" and row(second, "camera")[3] == "3.0 s"
        assert row(second, "arm")[4] == "ok"
        assert tuple(page.frames["arm"].position) == pytest.approx((1.6, 0.0, 0.0))
    buffer.close()


def _reds(shot: Any) -> int:
    """Pixels of the x axes' red (230, 30, 30; viser's thin lines blend it lighter):
    red well above green and blue, never a grey or the links' orange; in the scene only
    (viser's orientation gizmo, bottom left, and the panel are left out)."""
    rgb = shot.convert("RGB").crop((150, 150, 940, 700))
    return sum(n for n, (r, g, b) in (rgb.getcolors(maxcolors=1 << 24) or [])
               if r - max(g, b) > 80)


def _reds_until(c: Any, path: Path, ok: Callable[[int], bool], timeout: float = 60.0) -> int:
    """:func:`_reds` of screenshots of the open page, taken until ``ok`` holds for one
    (the viser client fades its scene in after loading and redraws as messages arrive; a
    loaded machine is slower at both) or ``timeout`` seconds have passed: the last count."""
    deadline = time.monotonic() + timeout
    while True:
        n = _reds(Image.open(io.BytesIO(c.screenshot(path))))
        if ok(n) or time.monotonic() > deadline:
            return n
        time.sleep(0.2)


def test_axes_fade_to_grey_in_chromium(chromium: str, page: TfPage, tmp_path: Path) -> None:
    """rviz's fade as the browser draws it: fresh frames have red x axes on screen; at the
    timeout the same frames, redrawn in the same open page, are grey (no red pixel left in
    the scene)."""
    from cdp import Chromium

    from tfbus.view import build_scene

    clock = ManualClock(Time.from_sec(100.0))
    core = BufferCore()
    for k, child in enumerate(("a", "b", "c")):
        core.set_transform(TransformStamped(
            Header(clock.now(), "world"), child,
            Transform(Vector3(0.4 * k, 0.3, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0))), "bc")
    # every frame updated now (the root too, as when a broadcaster sends it)
    last = dict.fromkeys(("world", "a", "b", "c"), clock.now())
    page.draw(build_scene(core, now=clock.now(), last_update=last, frame_timeout=3.0))
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        fresh = _reds_until(c, tmp_path / "fresh.png", lambda n: n > 300)
        clock.advance_nowait(3.0)  # silent for the whole timeout: grey, still drawn
        page.draw(build_scene(core, now=clock.now(), last_update=last, frame_timeout=3.0))
        assert [page.axes_colours(f) for f in ("world", "a", "b", "c")] == \
            [((128, 128, 128),) * 3] * 4
        grey = _reds_until(c, tmp_path / "grey.png", lambda n: n < 10)
    assert fresh > 300    # four red x axes
    assert grey < 10      # none left
