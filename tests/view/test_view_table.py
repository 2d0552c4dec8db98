"""The live page's frame table (tfbus/view/live.py ``TABLE_PERIOD``): written at the first
redraw, then at most every 0.25 s of the view's clock while the scene is redrawn at
every tick, at once when a frame comes or a control changes; the rates it shows are
each frame's recent rate at the redraw's time (``RecentRates``); and the fixed frame a
scene picks by itself is the root of the largest tree (``default_fixed_frame``)."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("viser")

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.view.live import TABLE_PERIOD, LiveView
from tfbus.view.player import RecentRates, draw_live
from tfbus.view.scene import build_scene, default_fixed_frame
from tfbus.view.server import TfPage


def link(parent: str, child: str, sec: float, x: float) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(sec), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def ages(html: str) -> dict[str, str]:
    """Each dynamic frame's age cell in the table, by frame id (a root has none)."""
    return dict(set(re.findall(r"<tr><td>([^<]*)</td><td>[^<]*</td><td>[^<]*</td><td>([^<]*)</td>",
                           html)) - {("odom", "")})


@pytest.mark.anyio
async def test_the_table_is_written_every_table_period_and_at_once_for_a_new_frame(
        page: TfPage) -> None:
    assert TABLE_PERIOD == 0.25
    clock = ManualClock(Time.from_sec(10.0))
    buffer, summary = Buffer(), TfSummary()
    sink = MonitoredSink(buffer, summary, clock)
    view = LiveView(page, buffer, summary, clock)
    sink.set_transforms([link("odom", "base", 10.0, 0.0), link("base", "arm", 10.0, 0.5)],
                        "a", False)

    view.render()  # the first redraw writes the table
    assert ages(page.panel_html) == {"base": "0.0 s", "arm": "0.0 s"}
    for k in range(1, 7):  # 6 ticks of 1/30 s (0.2 s): base moves, arm is not sent again
        clock.advance_nowait(1 / 30)
        sink.set_transforms([link("odom", "base", 10.0 + k / 30, k / 30)], "a", False)
        scene = view.render()
        pose = scene.frame("base").pose
        assert pose is not None and pose.transform.translation.x == pytest.approx(k / 30)
        assert page.frames["base"].position[0] == pytest.approx(k / 30)  # the scene moved
        # arm's one stamp (10 s) is its chain's latest common time: drawn where it was
        assert page.frames["arm"].position[0] == pytest.approx(0.5)
        assert ages(page.panel_html) == {"base": "0.0 s", "arm": "0.0 s"}  # the table kept
    clock.advance_nowait(0.06)  # 0.26 s after the first write: written again
    view.render()
    assert ages(page.panel_html) == {"base": "0.1 s", "arm": "0.3 s"}

    clock.advance_nowait(1 / 30)  # a new frame: written at the next redraw
    sink.set_transforms([link("base", "laser", 10.29, 0.1)], "a", False)
    view.render()
    assert ages(page.panel_html) == {"base": "0.1 s", "arm": "0.3 s", "laser": "0.0 s"}

    clock.advance_nowait(1 / 30)  # a control changed in the page: written too
    before = page.panel_html
    page.set_frame_filter("^las")
    view.render()
    assert ages(page.panel_html) == {"laser": "0.0 s"}
    assert "3 of 4 frames left out by the filter" in page.panel_html
    assert "left out" not in before

    page.set_frame_filter("")
    view.render()  # a control changed again: the whole table
    assert ages(page.panel_html) == {"base": "0.1 s", "arm": "0.3 s", "laser": "0.0 s"}
    clock.set_nowait(Time.from_sec(9.0))  # a clock that went back: written at once
    view.render()
    assert ages(page.panel_html) == {"base": "0.0 s", "arm": "0.0 s", "laser": "0.0 s"}


@pytest.mark.anyio
async def test_draw_live_without_the_table_keeps_the_table_shown(page: TfPage) -> None:
    clock = ManualClock(Time.from_sec(10.0))
    core, summary = BufferCore(), TfSummary()
    sink = MonitoredSink(core, summary, clock)
    sink.set_transforms([link("odom", "base", 10.0, 0.0)], "a", False)
    draw_live(page, core, summary, clock.now())
    shown = page.panel_html
    assert "<td>base</td><td>odom</td>" in shown
    sink.set_transforms([link("base", "laser", 10.0, 1.0)], "a", False)
    clock.advance_nowait(2.0)
    scene = draw_live(page, core, summary, clock.now(), table=False)
    assert [f.frame_id for f in scene.frames] == ["base", "odom", "laser"]
    assert "laser" in page.frames and page.panel_html == shown
    draw_live(page, core, summary, clock.now())
    assert "<td>laser</td><td>base</td>" in page.panel_html and "2.0 s" in page.panel_html


def test_recent_rates_are_each_frames_recent_rate_when_asked() -> None:
    summary = TfSummary()
    for k in range(11):  # 10 Hz over 1 s, received as stamped
        t = Time.from_sec(10.0 + k / 10)
        summary.add(t, [link("odom", "base", 10.0 + k / 10, 0.0)], "a", static=False)
    summary.add(Time.from_sec(10.0), [link("base", "laser", 0.0, 0.0)], "a", static=True)
    now = Time.from_sec(11.0)
    rates = RecentRates(summary, now)
    assert len(rates) == 2 and list(rates) == ["base", "laser"]
    assert rates["base"] == pytest.approx(10.0)
    assert rates["base"] == summary.frames["base"].recent_rate(now)
    assert rates["laser"] == 0.0  # static: no rate
    assert rates.get("nowhere", -1.0) == -1.0
    with pytest.raises(KeyError):
        rates["nowhere"]
    later = RecentRates(summary, Time.from_sec(30.0))
    assert later["base"] == 0.0  # stale: its broadcaster stopped


def _reference_root(names: list[str], parents: dict[str, str]) -> str | None:
    """default_fixed_frame as a walk up from every frame (O(frames x depth))."""
    sizes: dict[str, int] = {}
    for name in names:
        seen = {name}
        root = name
        while root in parents:
            root = parents[root]
            if root in seen:
                break
            seen.add(root)
        else:
            sizes[root] = sizes.get(root, 0) + 1
    if not sizes:
        return None
    return max(sizes, key=lambda r: (sizes[r], -names.index(r)))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), max_size=24))
def test_the_default_fixed_frame_is_the_root_of_the_largest_tree(
        links: list[tuple[int, int]]) -> None:
    core = BufferCore()
    for child, parent in links:  # loops and re-parenting included (the newest parent)
        child_id = f"c{child}" if child % 3 else f"p{child}"
        if child_id != f"p{parent}":
            core.set_transform(link(f"p{parent}", child_id, 1.0, 0.0), "a")
    parents = {i.child: i.parent for i in core.frame_info()}
    names = core.get_frame_names()
    expected = _reference_root(names, parents)
    assert default_fixed_frame(core) == expected
    scene = build_scene(core)
    assert scene.fixed_frame == expected
    if expected is not None:
        assert build_scene(core, fixed_frame=expected) == scene
