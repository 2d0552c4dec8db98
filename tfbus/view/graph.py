"""The graph view of ``tfbus view``'s page: the frame tree drawn by Graphviz, as tf2_tools'
``view_frames`` draws it (one node per frame, an edge from each parent to its child),
coloured by state and marked with ``tfbus doctor``'s findings.

Colours (:data:`STATE_COLOURS`): a static link (``/tf_static``), a dynamic one updated
within a third of the frame timeout, a stale one (fading or timed out, rviz's TF display
fade), a frame that cannot be placed in the fixed frame (unconnected: tf2's
``ConnectivityException``, an extrapolation), and a root. The fixed frame has a double
outline. A frame named by a finding of the doctor gets an outline in the finding's level
colour and a line per check (at most :data:`MAX_CHECKS_PER_FRAME`).

Frame ids are hostile input and stay text: nodes are numbered (``n0``, ``n1``, ...), never
named by ids; each label is a quoted DOT string with ``\\`` and ``"`` escaped and control
characters written as escapes (:func:`tfbus.view.escape.text`), long ids shortened
visibly. Graphviz's SVG is then parsed (:mod:`xml.etree.ElementTree`) and written again
with only the drawing's elements and attributes (:func:`clean_svg`): no script, no event
handler, no link, no comment survives, whatever ``dot`` wrote.

Bounded: at most :data:`MAX_GRAPH_FRAMES` frames are drawn (the rest counted in the
legend), ``dot`` runs as a subprocess with a :data:`DOT_TIMEOUT` s timeout and its output
is read up to :data:`MAX_SVG_BYTES`, in a thread of its own so that the drawing loop never
waits for it; only the newest graph asked for is drawn, and only when the "draw graph"
box is ticked.
"""

from __future__ import annotations

import shutil
import subprocess
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from tfbus.view.escape import html_text, text
from tfbus.view.scene import FrameView, Scene

if TYPE_CHECKING:
    from tfbus.doctor import Finding

__all__ = ["DOT_TIMEOUT", "MAX_CHECKS_PER_FRAME", "MAX_GRAPH_FRAMES", "MAX_SVG_BYTES",
           "STATE_COLOURS", "GraphView", "clean_svg", "frame_state", "graph_dot", "render_svg"]

MAX_GRAPH_FRAMES = 300
"""Frames drawn in the graph at most (Graphviz's layout grows faster than linearly); the
rest are counted in the legend."""
DOT_TIMEOUT = 5.0
"""Seconds ``dot`` may take on one graph; past that it is ended and the panel says so."""
MAX_SVG_BYTES = 8 * 2**20
"""Bytes of SVG taken from ``dot`` at most."""
MAX_CHECKS_PER_FRAME = 3
"""Doctor checks written under a frame's id at most (the rest counted)."""
LABEL_MAX = 80
"""Longest id written in full in a node; a longer one is its start, ``...`` and its end."""

STATE_COLOURS = {
    "static": "#9ecae1",
    "dynamic": "#a1d99b",
    "stale": "#d0d0d0",
    "unconnected": "#fc9272",
    "root": "#ffffff",
}
"""Fill colour of a node by :func:`frame_state`."""
_LEVEL_COLOURS = {"error": "#d03030", "warning": "#c08000", "info": "#3070c0"}

_SVG = "http://www.w3.org/2000/svg"
_ELEMENTS = {"svg", "g", "title", "polygon", "polyline", "ellipse", "path", "text",
             "line", "rect", "circle"}
_ATTRIBUTES = {"width", "height", "viewBox", "transform", "class", "fill", "stroke",
               "stroke-width", "stroke-dasharray", "points", "cx", "cy", "rx", "ry", "r",
               "d", "x", "y", "x1", "y1", "x2", "y2", "text-anchor", "font-family",
               "font-size", "font-weight", "font-style", "fill-opacity", "stroke-opacity"}


def frame_state(f: FrameView) -> str:
    """A frame's class in the graph: ``unconnected`` (cannot be placed in the fixed
    frame), ``static``, ``root`` (no parent), ``stale`` (not updated for a third of the
    frame timeout) or ``dynamic``."""
    if f.pose is None:
        return "unconnected"
    if f.static:
        return "static"
    if f.parent is None:
        return "root"
    if f.stale:
        return "stale"
    return "dynamic"


def _quote(value: str) -> str:
    """``value`` as a quoted DOT string drawn literally: backslashes doubled (no ``\\N``,
    ``\\l`` escapes), quotes escaped, control characters written as escapes."""
    shown = text(value)
    if len(shown) > LABEL_MAX:
        shown = f"{shown[:50]}...({len(shown)} chars)...{shown[-20:]}"
    return '"' + shown.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _finding_frames(findings: Sequence[Finding], ids: set[str]) -> dict[str, list[Finding]]:
    """The findings naming each frame id of ``ids`` (the doctor writes an id with its
    leading '/' stripped in some checks: both spellings match)."""
    stripped: dict[str, str] = {}
    for i in ids:
        stripped.setdefault(i.lstrip("/"), i)
    out: dict[str, list[Finding]] = {}
    for finding in findings:
        for name in dict.fromkeys(finding.frames):
            frame = name if name in ids else stripped.get(name.lstrip("/"))
            if frame is not None:
                out.setdefault(frame, []).append(finding)
    return out


def graph_dot(scene: Scene, findings: Sequence[Finding] = (), *,
              max_frames: int = MAX_GRAPH_FRAMES) -> str:
    """The scene's frame tree as Graphviz DOT (module doc): nodes numbered in the scene's
    order, each labelled with its id (and its frames' doctor checks), filled by
    :func:`frame_state`; an edge parent -> child per link whose two frames are drawn; a
    legend with the colours and the number of frames left out beyond ``max_frames``."""
    frames = scene.frames[:max_frames]
    ids = {f.frame_id: f"n{k}" for k, f in enumerate(frames)}
    marked = _finding_frames(findings, set(ids))
    lines = ["digraph tf {", '  graph [rankdir=TB, bgcolor="transparent"];',
             '  node [shape=box, style="rounded,filled", fontname="Helvetica", '
             'fontsize=11];', '  edge [color="#606060"];']
    for f in frames:
        attrs = [f'fillcolor="{STATE_COLOURS[frame_state(f)]}"']
        label = _quote(f.frame_id)
        found = marked.get(f.frame_id)
        if found:
            order = {"error": 0, "warning": 1, "info": 2}
            worst = min(found, key=lambda x: order.get(str(x.level), 3))
            attrs.append(f'color="{_LEVEL_COLOURS.get(str(worst.level), "#000000")}"')
            attrs.append("penwidth=3")
            checks = list(dict.fromkeys(str(x.check) for x in found))
            extra = [f"! {c}" for c in checks[:MAX_CHECKS_PER_FRAME]]
            if len(checks) > MAX_CHECKS_PER_FRAME:
                extra.append(f"+{len(checks) - MAX_CHECKS_PER_FRAME} more")
            label = label[:-1] + "".join("\\n" + _quote(e)[1:-1] for e in extra) + '"'
        if f.frame_id == scene.fixed_frame:
            attrs.append("peripheries=2")
        lines.append(f"  {ids[f.frame_id]} [label={label}, {', '.join(attrs)}];")
    for f in frames:
        if f.parent is not None and f.parent in ids:
            lines.append(f"  {ids[f.parent]} -> {ids[f.frame_id]};")
    more = len(scene.frames) - len(frames)
    legend = " ".join(f'legend_{k} [label="{k}", fillcolor="{c}", fontsize=9];'
                      for k, c in STATE_COLOURS.items())
    lines.append('  subgraph cluster_legend { label="legend"; fontsize=10; '
                 + legend
                 + (f' left_out [shape=plaintext, style="", label="{more} more frames '
                    f'not drawn (at most {max_frames})"];' if more > 0 else "")
                 + " }")
    lines.append("}")
    return "\n".join(lines) + "\n"


def clean_svg(svg: str) -> str:
    """Graphviz's SVG parsed and written again with only drawing elements
    (``svg``, ``g``, ``title``, shapes, ``text``) and their geometry and style attributes:
    everything else (scripts, ``foreignObject``, links, event handlers, comments,
    processing instructions) is dropped, and every text is escaped by the writer.

    Raises:
        ValueError: ``svg`` is not well-formed XML or is not an SVG document.
    """
    try:
        root = ET.fromstring(svg)
    except ET.ParseError as err:
        raise ValueError(f"dot wrote SVG that is not well-formed: {err}") from err

    def local(tag: object) -> str:
        return str(tag).rsplit("}", 1)[-1]

    if local(root.tag) != "svg":
        raise ValueError(f"dot wrote a {local(root.tag)!r} document, not an SVG")

    def copy(el: ET.Element) -> ET.Element:
        out = ET.Element(local(el.tag), {local(k): v for k, v in el.attrib.items()
                                         if local(k) in _ATTRIBUTES})
        out.text = el.text
        for child in el:
            if not isinstance(child.tag, str) or local(child.tag) not in _ELEMENTS:
                continue
            c = copy(child)
            c.tail = child.tail
            out.append(c)
        return out

    clean = copy(root)
    clean.set("xmlns", _SVG)
    clean.set("class", "tfbus-graph")
    return ET.tostring(clean, encoding="unicode", short_empty_elements=True)


def render_svg(dot: str, *, timeout: float = DOT_TIMEOUT, exe: str | None = None) -> str:
    """``dot -Tsvg`` of ``dot``, cleaned (:func:`clean_svg`).

    Raises:
        FileNotFoundError: Graphviz's ``dot`` program is not installed.
        TimeoutError: ``dot`` took longer than ``timeout`` seconds (it is ended).
        RuntimeError: ``dot`` failed (its first error line) or wrote more than
            :data:`MAX_SVG_BYTES`.
        ValueError: its output is not an SVG document.
    """
    program = exe or shutil.which("dot")
    if program is None:
        raise FileNotFoundError("Graphviz's dot program is not installed (apt install graphviz)")
    try:
        done = subprocess.run([program, "-Tsvg"], input=dot.encode("utf-8"),
                              capture_output=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired as err:  # subprocess.run ends the child first
        raise TimeoutError(f"dot took longer than {timeout:g} s") from err
    if done.returncode != 0:
        first = done.stderr.decode("utf-8", "replace").strip().splitlines()[:1]
        raise RuntimeError(f"dot failed (exit status {done.returncode}): "
                           f"{first[0] if first else 'no message'}")
    if len(done.stdout) > MAX_SVG_BYTES:
        raise RuntimeError(f"dot wrote {len(done.stdout)} bytes of SVG "
                           f"(at most {MAX_SVG_BYTES})")
    return clean_svg(done.stdout.decode("utf-8", "replace"))


class GraphView:
    """The page's "graph (view_frames)" folder (module doc): a "draw graph" box (off at
    first: no ``dot`` runs for a page that does not look) and the SVG. Made by
    :class:`~tfbus.view.server.TfPage`; :meth:`update` is called by each redraw and
    only hands the DOT text to the graph's thread when it changed.

    Args:
        gui: the page's viser GUI (``server.gui``).
        lock: the page's lock (held by each redraw; the graph's thread takes it to show
            the SVG).
        changed: called under ``lock`` when the box is ticked or unticked in the page.
    """

    def __init__(self, gui: Any, lock: threading.Lock,
                 changed: Callable[[], None]) -> None:
        self._lock = lock
        self._changed = changed
        with gui.add_folder("graph (view_frames)", expand_by_default=True):
            self.enabled: Any = gui.add_checkbox(
                "draw graph", initial_value=False,
                hint="the frame tree drawn by Graphviz: static, dynamic, stale and "
                     "unconnected frames coloured, the doctor's findings outlined")
            self.html: Any = gui.add_html("")
        self.enabled.on_update(self._on_enable)
        self.svg_html = ""
        """The graph's HTML as last sent (the cleaned SVG, or an error line)."""
        self.dot = ""
        """The DOT text of the graph drawn last (or being drawn)."""
        self.drawn = ""
        """The DOT text of the graph whose SVG (or error) the page shows."""
        self.renders = 0
        """Graphs drawn by ``dot`` (successfully or not)."""
        self.findings: Sequence[Finding] = ()
        """The doctor's findings last shown in the page (outlined in the graph)."""
        self._wanted: str | None = None
        self._cond = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None

    def _on_enable(self, event: Any) -> None:
        if event.client is not None:
            with self._lock:
                self._changed()

    def update(self, scene: Scene) -> None:
        """Ask for the graph of ``scene`` (with :attr:`findings`) if the box is ticked and
        it differs from the last one asked for."""
        if not bool(self.enabled.value):
            return
        dot = graph_dot(scene, self.findings)
        with self._cond:
            if dot == self.dot or self._closed:
                return
            self.dot = dot
            self._wanted = dot
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="tfbus-view-graph",
                                                daemon=True)
                self._thread.start()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._wanted is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                dot, self._wanted = self._wanted, None
                if dot is None:
                    continue
            try:
                value = f"<div style='overflow:auto;max-height:60vh'>{render_svg(dot)}</div>"
            except (OSError, TimeoutError, RuntimeError, ValueError) as err:
                value = f"<p style='color:#d03030'>graph: {html_text(err)}</p>"
            with self._lock:
                self.renders += 1
                self.drawn = dot
                if value != self.svg_html:
                    self.svg_html = value
                    self.html.content = value

    def wait_drawn(self, timeout: float) -> bool:
        """Whether the graph asked for last was drawn within ``timeout`` seconds (polled;
        for tests and scripts)."""
        import time

        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if self.dot and self.drawn == self.dot:
                    return True
            time.sleep(0.02)
        return False

    def close(self) -> None:
        """End the graph's thread (a ``dot`` running is left to its timeout)."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout=DOT_TIMEOUT + 1.0)
