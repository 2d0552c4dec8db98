"""The browsable frame tree of ``tfbus view``'s page (tfbus/view/tree.py and its hooks in
server.py): frames nested under their parents from the fixed frame's root, a show/hide
box per frame (a hidden frame's axes and label are not drawn, its children are), kept
across redraws and re-rooting, bounded at MAX_TREE_ROWS; on a bag (the slider) and live,
driven in headless Chromium through the DevTools protocol with real mouse events."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("viser")

from test_view_controls import _centre, _pick, until

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.monitor import TfSummary
from tfbus.view.player import BagPlayer, draw_live
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline
from tfbus.view.tree import MAX_TREE_ROWS, TreeRow, tree_rows

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
HOSTILE = "<img src=x onerror=alert(1)>"


def tf(parent: str, child: str, x: float, sec: float = 10.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(sec), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def test_rows_nest_from_the_fixed_frames_root() -> None:
    parents = {"odom": "map", "base": "odom", "laser": "base", "cam": "base",
               "b": "a", "l1": "l2", "l2": "l1"}
    frames = ["map", "odom", "base", "laser", "cam", "a", "b", "l1", "l2"]
    rows, more = tree_rows(parents, frames, fixed_frame="b")
    assert more == 0
    assert rows == [TreeRow("a", 0, 1), TreeRow("b", 1, 0),
                    TreeRow("map", 0, 1), TreeRow("odom", 1, 1), TreeRow("base", 2, 2),
                    TreeRow("cam", 3, 0), TreeRow("laser", 3, 0),
                    TreeRow("l1", 0, 0), TreeRow("l2", 0, 0)]  # a loop: no root
    # re-rooted at laser: map's tree first
    rows, _ = tree_rows(parents, frames, fixed_frame="laser")
    assert [r.frame_id for r in rows][:3] == ["map", "odom", "base"]
    # a filter keeps the matching frames and their ancestors only
    rows, more = tree_rows(parents, frames, keep=lambda n: n == "cam")
    assert (rows, more) == ([TreeRow("map", 0, 1), TreeRow("odom", 1, 1),
                             TreeRow("base", 2, 1), TreeRow("cam", 3, 0)], 0)
    # the limit: counted, and a parent counts only the children listed
    rows, more = tree_rows(parents, frames, fixed_frame="odom", limit=4)
    assert (rows, more) == ([TreeRow("map", 0, 1), TreeRow("odom", 1, 1),
                             TreeRow("base", 2, 1), TreeRow("cam", 3, 0)], 5)


def test_ten_thousand_frames_make_a_bounded_tree(page: TfPage) -> None:
    """10 000 frames under one root: MAX_TREE_ROWS boxes and one "N more" line, not
    10 000 GUI elements; the filter narrows the tree to what matches (and its root)."""
    core = BufferCore()
    for k in range(10_000):
        core.set_transform(tf("map", f"f{k:05d}", 1.0), "bc")
    stats = TfSummary()
    clock = ManualClock(Time.from_sec(10.0))
    gui = page.server.gui
    inputs_before = len(gui._gui_input_handle_from_uuid)
    folders_before = len(gui._container_handle_from_uuid)
    draw_live(page, core, stats, clock.now())
    tree = page.frame_tree
    assert len(tree.checkboxes) == MAX_TREE_ROWS
    assert tree.more == 10_001 - MAX_TREE_ROWS
    html = [h for h in tree._handles if hasattr(h, "content")]
    assert len(html) == 1 and f"{10_001 - MAX_TREE_ROWS} more frames not listed" \
        in html[0].content
    # the GUI elements made: one box per listed frame, one folder (map's)
    assert len(gui._gui_input_handle_from_uuid) - inputs_before == MAX_TREE_ROWS
    assert len(gui._container_handle_from_uuid) - folders_before == 1
    assert page.set_frame_filter("^f0000[0-4]$") is None
    draw_live(page, core, stats, clock.now())
    assert [r.frame_id for r in tree.rows] == ["map", "f00000", "f00001", "f00002",
                                               "f00003", "f00004"]
    assert tree.more == 0 and len(tree.checkboxes) == 6
    rebuilds = tree.rebuilds
    draw_live(page, core, stats, clock.now())  # nothing changed: nothing made again
    assert tree.rebuilds == rebuilds


@pytest.fixture
def playing(page: TfPage) -> Iterator[BagPlayer]:
    """The turtle bag paused at 5 s, its player's loop running as ``tfbus view --bag``."""
    player = BagPlayer(page, BagTimeline.read(TURTLE), paused=True)
    player.seek(5.0)
    stop = threading.Event()
    runner = threading.Thread(target=player.run, args=(stop,), daemon=True)
    runner.start()
    try:
        yield player
    finally:
        stop.set()
        runner.join(timeout=10)


def _box(label: str) -> str:
    """JS: the checkbox input of the frame tree row labelled ``label``."""
    return (f"[...document.querySelectorAll('label')].find(e => e.textContent === "
            f"{json.dumps(label)})?.closest('.mantine-Flex-root')"
            "?.querySelector('input[type=checkbox]')")


def _toggle(c: object, label: str) -> None:
    """Click the frame tree box labelled ``label`` (a real mouse click) once its place
    on the page is settled (folders open with a transition); again if the click landed
    before it settled (at most 3 clicks)."""
    from cdp import Chromium

    assert isinstance(c, Chromium)
    before = c.js(f"{_box(label)}.checked")
    for _ in range(3):
        now = _centre(c, _box(label))
        for _ in range(50):  # until the box stops moving
            previous, now = now, _centre(c, _box(label))
            if now == previous:
                break
        c.click(*now)
        try:
            c.wait(f"{_box(label)}.checked === {json.dumps(not before)}", timeout=5.0)
            return
        except TimeoutError:
            continue
    raise AssertionError(f"the box of {label!r} did not change")


def test_show_hide_in_chromium_on_a_bag(chromium: str, page: TfPage, playing: BagPlayer,
                                        tmp_path: Path) -> None:
    """The turtle bag: world > turtle1 > carrot, world > turtle2. Unticking turtle1 hides
    its axes and label, carrot (its child) stays; after re-rooting at turtle2 and moving
    the slider, turtle1 is still unticked and hidden; ticking it again shows it."""
    from cdp import Chromium

    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("document.body && document.body.innerText.includes('bag time 5.00')")
        assert [(r.frame_id, r.depth) for r in page.frame_tree.rows] == [
            ("world", 0), ("turtle1", 1), ("carrot", 2), ("turtle2", 1)]
        for name in ("world", "turtle1", "carrot", "turtle2"):
            assert c.js(f"{_box(name)}.checked") is True, name
        assert page.frames["turtle1"].visible and "turtle1" in page.axes_rows
        _toggle(c, "turtle1")
        until(lambda: page.frame_tree.hidden == {"turtle1"}, "turtle1 unticked")
        until(lambda: not page.frames["turtle1"].visible, "turtle1 hidden")
        assert "turtle1" not in page.axes_rows  # no axes drawn for it
        assert page.frames["carrot"].visible and "carrot" in page.axes_rows
        assert page.frames["turtle2"].visible and page.frames["world"].visible
        shot = c.screenshot(tmp_path / "tree_hidden.png")
        assert len(shot) > 10_000
        # re-rooted at turtle2, and the slider moved: turtle1 still hidden, box unticked
        _pick(c, "fixed frame", "turtle2")
        until(lambda: playing.last_scene is not None
              and playing.last_scene.fixed_frame == "turtle2", "re-rooted")
        playing.seek(7.0)
        c.wait("document.body.innerText.includes('bag time 7.00')")
        assert tuple(page.frames["turtle2"].position) == (0.0, 0.0, 0.0)
        assert not page.frames["turtle1"].visible and page.frames["carrot"].visible
        assert c.js(f"{_box('turtle1')}.checked") is False
        assert c.js(f"{_box('carrot')}.checked") is True
        _toggle(c, "turtle1")
        until(lambda: not page.frame_tree.hidden, "turtle1 ticked again")
        until(lambda: page.frames["turtle1"].visible, "turtle1 shown again")
        assert "turtle1" in page.axes_rows


@pytest.mark.anyio
async def test_show_hide_live_in_chromium(chromium: str, page: TfPage) -> None:
    """Live (LiveView.render is the draw loop's tick): a hostile id is a box label as
    text; unticking it hides it at the next redraw, a frame arriving later keeps it
    hidden, and its child stays drawn."""
    import anyio
    from cdp import Chromium

    from tfbus.broadcaster import TransformBroadcaster
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink
    from tfbus.view.live import LiveView

    clock = ManualClock(Time.from_sec(20.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "/bc")
    view = LiveView(page, buffer, stats, clock)
    async with Bus() as bus, TransformListener(sink, bus, clock=clock):
        b = TransformBroadcaster(bus)
        for parent, child, x in (("odom", "base", 1.0), ("base", HOSTILE, 2.0),
                                 (HOSTILE, "arm", 0.5)):
            await b.send_transform(tf(parent, child, x, 20.0))
        with anyio.fail_after(5):
            while stats.messages.get("/tf", 0) < 3:
                await anyio.sleep(0)
        view.render()
        assert [(r.frame_id, r.depth) for r in page.frame_tree.rows] == [
            ("odom", 0), ("base", 1), (HOSTILE, 2), ("arm", 3)]

        def untick() -> tuple[bool, int]:
            with Chromium(chromium) as c:
                c.open(f"http://127.0.0.1:{page.port}/")
                c.wait(f"!!({_box(HOSTILE)})")
                _toggle(c, HOSTILE)
                until(lambda: HOSTILE in page.frame_tree.hidden, "hostile frame unticked")
                made = int(c.js("document.querySelectorAll('[onerror], img[src=x]').length"))
                label = c.js(f"[...document.querySelectorAll('label')].some(e => "
                             f"e.textContent === {json.dumps(HOSTILE)})")
                return bool(label), made

        label, images = await anyio.to_thread.run_sync(untick)
        assert label and images == 0  # the id is a label's text, no element made of it
        view.render()  # the draw loop's next tick
        assert not page.frames[HOSTILE].visible and page.frames["arm"].visible
        assert tuple(page.frames["arm"].position) == (3.5, 0.0, 0.0)
        await b.send_transform(tf("odom", "dock", 4.0, 20.0))  # the tree changes
        with anyio.fail_after(5):
            while stats.messages.get("/tf", 0) < 4:
                await anyio.sleep(0)
        view.render()
        assert "dock" in page.frame_tree.checkboxes
        assert page.frame_tree.checkboxes[HOSTILE].value is False
        assert not page.frames[HOSTILE].visible and page.frames["dock"].visible
    buffer.close()


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)
