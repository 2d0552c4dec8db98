"""The graph view of ``tfbus view``'s page (tfbus/view/graph.py): the frame tree drawn by
Graphviz's ``dot`` as view_frames draws it, static / dynamic / stale / unconnected / root
frames coloured, the doctor's findings outlined; hostile ids stay text (no element made
from them, whatever ``dot`` writes); ``dot`` bounded in time and input size. On a bag
(the slider) and live, in headless Chromium driven through the DevTools protocol."""

from __future__ import annotations

import shutil
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("viser")
if shutil.which("dot") is None:
    pytest.skip("Graphviz's dot is not installed", allow_module_level=True)

from test_view_controls import until
from test_view_doctor import HOSTILE_FRAME, hostile_bag
from test_view_tree import _toggle

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.monitor import TfSummary
from tfbus.view.graph import (
    MAX_GRAPH_FRAMES,
    STATE_COLOURS,
    clean_svg,
    graph_dot,
    render_svg,
)
from tfbus.view.player import BagPlayer, draw_live
from tfbus.view.scene import build_scene
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

SVG = "{http://www.w3.org/2000/svg}"
IMG = "<img src=x onerror=alert(1)>"
QUOTE = '"];evil'
COMMENT = "--><script>alert(2)</script>"
HOSTILE = HOSTILE_FRAME.lstrip("/")
"""The doctor's hostile frame as the buffer holds it (tf2 strips a leading '/')."""


def tf(parent: str, child: str, sec: float, x: float = 1.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(sec), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def nodes(svg: str) -> dict[str, tuple[str, str, list[str]]]:
    """Each node of a cleaned SVG by its texts' first line: (fill, stroke, texts)."""
    root = ET.fromstring(svg)
    out = {}
    for g in root.iter(f"{SVG}g"):
        if g.get("class") != "node":
            continue
        shape = next(e for e in g if e.tag in (f"{SVG}path", f"{SVG}polygon",
                                                f"{SVG}ellipse"))
        texts = [t.text or "" for t in g.iter(f"{SVG}text")]
        out[texts[0]] = (shape.get("fill", ""), shape.get("stroke", ""), texts)
    return out


def hostile_core() -> tuple[BufferCore, dict[str, Time]]:
    """odom (root) -> base (dynamic, 1 s old) -> IMG (dynamic, 9 s old: stale with a 15 s
    timeout) -> QUOTE (static); odom -> COMMENT (dynamic); x -> y (another tree)."""
    core = BufferCore()
    core.set_transform(tf("odom", "base", 20.0), "bc")
    core.set_transform(tf("base", IMG, 20.0), "bc")
    core.set_transform_static(tf(IMG, QUOTE, 0.0), "bc")
    core.set_transform(tf("odom", COMMENT, 20.0), "bc")
    core.set_transform(tf("x", "y", 20.0), "bc")
    last = {"base": Time.from_sec(20.0), IMG: Time.from_sec(12.0),
            COMMENT: Time.from_sec(21.0), "y": Time.from_sec(21.0)}
    return core, last


def test_states_coloured_and_ids_kept_as_text() -> None:
    core, last = hostile_core()
    scene = build_scene(core, fixed_frame="odom", now=Time.from_sec(21.0), last_update=last)
    dot = graph_dot(scene)
    svg = render_svg(dot)
    got = nodes(svg)
    assert {k: v[0] for k, v in got.items() if not k.startswith(("static", "dynamic",
                                                                  "stale", "unconn",
                                                                  "root"))} == {
        "odom": STATE_COLOURS["root"], "base": STATE_COLOURS["dynamic"],
        IMG: STATE_COLOURS["stale"], QUOTE: STATE_COLOURS["static"],
        COMMENT: STATE_COLOURS["dynamic"], "x": STATE_COLOURS["unconnected"],
        "y": STATE_COLOURS["unconnected"]}
    # the ids are texts: no element but the drawing's own, no attribute but geometry
    tags = {e.tag.removeprefix(SVG) for e in ET.fromstring(svg).iter()}
    assert tags <= {"svg", "g", "title", "path", "polygon", "ellipse", "text", "polyline"}
    assert "<img" not in svg and "<script" not in svg and "&lt;img src=x" in svg
    # edges: parent -> child, numbered nodes (never named by ids)
    titles = [t.text for t in ET.fromstring(svg).iter(f"{SVG}title")]
    assert "n1->n0" in [t.replace("&gt;", ">") for t in titles if t]  # odom -> base


def test_findings_outlined_and_the_size_bounded() -> None:
    from tfbus.doctor import Doctor

    core, last = hostile_core()
    scene = build_scene(core, fixed_frame="odom", now=Time.from_sec(21.0), last_update=last)
    doctor = Doctor(source="test")
    doctor.add(Time.from_sec(20.0).ns, [tf("odom", "/lead", 20.0)], "bc", static=False)
    core.set_transform(tf("odom", "/lead", 20.0), "bc")
    scene = build_scene(core, fixed_frame="odom", now=Time.from_sec(21.0), last_update=last)
    findings = doctor.report(now=Time.from_sec(21.0)).findings
    assert [(f.check, f.level) for f in findings] == [("leading_slash", "error")]
    got = nodes(render_svg(graph_dot(scene, findings)))
    _fill, stroke, texts = got["lead"]  # the buffer strips the '/' (tf2), the doctor not
    assert texts == ["lead", "! leading_slash"] and stroke == "#d03030"
    assert got["base"][1] == "black" and len(got["base"][2]) == 1
    # 1 000 frames: MAX_GRAPH_FRAMES drawn, the rest counted
    big = BufferCore()
    for k in range(1000):
        big.set_transform(tf("map", f"f{k}", 1.0), "bc")
    svg = render_svg(graph_dot(build_scene(big, fixed_frame="map")))
    assert sum(1 for g in ET.fromstring(svg).iter(f"{SVG}g")
               if g.get("class") == "node") == MAX_GRAPH_FRAMES + 5 + 1  # legend, note
    assert f"{1001 - MAX_GRAPH_FRAMES} more frames not drawn" in svg


def test_dot_is_ended_at_its_timeout(tmp_path: Path) -> None:
    """A ``dot`` that never answers (a program that waits for a minute) is ended after
    the timeout and reported, not waited for."""
    slow = tmp_path / "dot"
    slow.write_text("#!/bin/sh\nexec sleep 60\n")
    slow.chmod(0o755)
    t0 = time.monotonic()
    with pytest.raises(TimeoutError, match=r"dot took longer than 0\.5 s"):
        render_svg("digraph { a }", timeout=0.5, exe=str(slow))
    assert time.monotonic() - t0 < 30.0
    with pytest.raises(RuntimeError, match="dot failed"):
        render_svg("digraph { a -> }")


def test_clean_svg_keeps_only_the_drawing() -> None:
    """Whatever ``dot`` writes, only drawing elements and geometry attributes are kept."""
    hostile = ('<svg xmlns="http://www.w3.org/2000/svg" onload="alert(1)" width="10">'
               '<script>alert(2)</script><!-- c --><img src="x" onerror="alert(5)"/>'
               '<g class="node" onclick="alert(3)"><title>a</title>'
               '<a href="javascript:alert(4)"><text x="1">t</text></a>'
               '<foreignObject><div>x</div></foreignObject>'
               '<text x="2" style="x">&lt;b&gt;</text></g></svg>')
    out = clean_svg(hostile)
    assert out == ('<svg width="10" xmlns="http://www.w3.org/2000/svg" class="tfbus-graph">'
                   '<g class="node"><title>a</title><text x="2">&lt;b&gt;</text></g></svg>')
    with pytest.raises(ValueError, match="not well-formed"):
        clean_svg("<svg><g></svg>")
    with pytest.raises(ValueError, match="not an SVG"):
        clean_svg("<html/>")


def _tick_graph(c: object) -> None:
    _toggle(c, "draw graph")
    c.wait("!!document.querySelector('svg.tfbus-graph')")


def test_graph_on_a_bag_follows_the_slider(chromium: str, page: TfPage,
                                           tmp_path: Path) -> None:
    """The doctor's hostile bag: at 5 s the markup frame is a node (its id as text,
    outlined for ``leading_slash``), at 2 s it is not in the graph."""
    from cdp import Chromium

    player = BagPlayer(page, BagTimeline.read(hostile_bag(tmp_path / "h.bag")), paused=True)
    player.seek(5.0)
    stop = threading.Event()
    runner = threading.Thread(target=player.run, args=(stop,), daemon=True)
    runner.start()
    try:
        with Chromium(chromium) as c:
            c.open(f"http://127.0.0.1:{page.port}/")
            c.wait("document.body && document.body.innerText.includes('bag time 5.00')")
            _tick_graph(c)
            until(lambda: page.graph.wait_drawn(1.0), "graph drawn")
            got = nodes(page.graph.svg_html.split(">", 1)[1].rsplit("</div>", 1)[0])
            assert set(got) >= {"world", "base", HOSTILE}
            assert got[HOSTILE][2] == [HOSTILE, "! leading_slash"]
            assert got["base"][2] == ["base", "! several_authorities"]
            assert got["world"][0] == STATE_COLOURS["root"]
            assert got["base"][0] == STATE_COLOURS["dynamic"]
            texts = c.js("[...document.querySelectorAll('svg.tfbus-graph text')]"
                         ".map(e => e.textContent)")
            assert HOSTILE in texts
            assert c.js("document.querySelectorAll('[onerror], img[src=x]').length") == 0
            c.screenshot(tmp_path / "graph_bag.png")
            player.seek(2.0)
            c.wait("![...document.querySelectorAll('svg.tfbus-graph text')]"
                   f".some(e => e.textContent === {HOSTILE!r})")
            texts = c.js("[...document.querySelectorAll('svg.tfbus-graph text')]"
                         ".map(e => e.textContent)")
            assert "base" in texts and HOSTILE not in texts
    finally:
        stop.set()
        runner.join(timeout=10)


def test_graph_live_in_chromium(chromium: str, page: TfPage, tmp_path: Path) -> None:
    """Live (draw_live, as LiveView.render draws): hostile ids as node texts, states
    coloured as the clock moves on (base goes stale), no element made from an id."""
    from cdp import Chromium

    core, _ = hostile_core()
    stats = TfSummary()
    for t in (tf("odom", "base", 20.0), tf("base", IMG, 20.0), tf("odom", COMMENT, 20.0),
              tf("x", "y", 20.0)):
        stats.add(Time.from_sec(20.0), [t], "bc", static=False)
    clock = ManualClock(Time.from_sec(21.0))
    draw_live(page, core, stats, clock.now(), fixed_frame="odom")
    assert page.graph.svg_html == ""  # not drawn until ticked
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("!!document.querySelector('input')")
        _toggle(c, "draw graph")
        until(lambda: bool(page.graph.enabled.value), "graph ticked")
        draw_live(page, core, stats, clock.now(), fixed_frame="odom")  # the next tick
        c.wait("!!document.querySelector('svg.tfbus-graph')")
        texts = c.js("[...document.querySelectorAll('svg.tfbus-graph text')]"
                     ".map(e => e.textContent)")
        assert {IMG, QUOTE, COMMENT, "odom", "base", "x", "y"} <= set(texts)
        assert c.js("document.querySelectorAll('[onerror], img[src=x], script').length") \
            == c.js("document.querySelectorAll('script').length")
        assert c.js("[...document.querySelectorAll('svg.tfbus-graph *')].some(e => "
                    "[...e.attributes].some(a => a.name.startsWith('on')))") is False
        got = nodes(page.graph.svg_html.split(">", 1)[1].rsplit("</div>", 1)[0])
        assert got["base"][0] == STATE_COLOURS["dynamic"]
        clock.advance_nowait(9.0)  # base 10 s old: stale (a third of the 15 s timeout is 5 s)
        draw_live(page, core, stats, clock.now(), fixed_frame="odom")
        until(lambda: page.graph.wait_drawn(1.0), "graph drawn again")
        got = nodes(page.graph.svg_html.split(">", 1)[1].rsplit("</div>", 1)[0])
        assert got["base"][0] == STATE_COLOURS["stale"]
        c.wait(f"[...document.querySelectorAll('svg.tfbus-graph path')].some(e => "
               f"e.getAttribute('fill') === {STATE_COLOURS['stale']!r})")
        c.screenshot(tmp_path / "graph_live.png")
