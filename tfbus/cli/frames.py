"""``tfbus frames``: view_frames, the frame tree drawn by Graphviz."""

from __future__ import annotations

import hashlib
import importlib
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bus_source import BusSource
from tfbus.cli._common import (
    RATE_HELP,
    console,
    error,
    fail,
    finish_status,
    literal,
    seconds,
    use_sim_time_option,
)
from tfbus.cli._live_session import live, run_live
from tfbus.cli._source_options import live_only, source, source_options
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["LABEL_MAX", "command", "dot_id", "frames_dot"]

LABEL_MAX = 120
"""Longest id drawn in full; a longer one is drawn as its start, ``...(N chars)...`` and
its end."""


def _shorten(text: str) -> str:
    if len(text) <= LABEL_MAX:
        return text
    return f"{text[:60]}...({len(text)} chars)...{text[-40:]}"


def dot_id(text: str) -> str:
    """``text`` as one DOT identifier, drawn literally: backslashes doubled and controls
    escaped (:func:`literal`), as Python's ``repr`` writes them, so two ids never become
    one node (``'a\\nb'`` is drawn ``a\\x0ab``, the 6-character text ``a\\x0ab`` is drawn
    ``a\\\\x0ab``); backslashes and ``<...>`` disarmed for DOT (``graphviz.escape``),
    quoted where DOT needs it (``graphviz`` package quoting: ``cam:left`` is one node,
    not node ``cam`` port ``left``); a very long id is shortened visibly, with a hash
    keeping it unique."""
    shown = literal(text.replace("\\", "\\\\"))
    if len(shown) > LABEL_MAX:
        digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:12]
        shown = f"{_shorten(shown)} #{digest}"
    return _label(shown)


def _label(text: str) -> str:
    """``text`` as a quoted DOT string drawn literally (the ``graphviz`` package's
    ``escape`` and ``quoting.quote``)."""
    graphviz = importlib.import_module("graphviz")
    return str(graphviz.quoting.quote(graphviz.escape(text)))


def frames_dot(core: BufferCore, *, recorded_at: Time | None = None) -> str:
    """The frame tree as Graphviz DOT text, in view_frames' layout: one edge per link,
    labelled with broadcaster, average rate (:func:`tfbus.monitor.link_rate`), buffer
    length, most recent and oldest transform (seconds); static links say so. Every id
    goes through :func:`dot_id`, so any frame id gives one node and valid DOT. Needs the
    ``graphviz`` Python package only."""
    from tfbus.monitor import link_rate

    graphviz = importlib.import_module("graphviz")
    g = graphviz.Digraph("G")
    newest_all = 0
    for child, parent, authority, static, samples, oldest, newest in core.frame_info():
        who = _shorten(literal(authority))
        if static:
            label = f"Broadcaster: {who}\nAverage rate: static\nBuffer length: 0.0\n"
        else:
            length = (newest - oldest) / NSEC_PER_SEC
            newest_all = max(newest_all, newest)
            label = (
                f"Broadcaster: {who}\nAverage rate: {link_rate(samples, oldest, newest):.3f}\n"
                f"Buffer length: {length:.3f}\n"
                f"Most recent transform: {newest / NSEC_PER_SEC:.3f}\n"
                f"Oldest transform: {oldest / NSEC_PER_SEC:.3f}\n"
            )
        # Built by hand: Digraph.edge() would split "cam:left" into node and port.
        g.body.append(f"\t{dot_id(parent)} -> {dot_id(child)} [label={_label(label)}]\n")
    when = recorded_at.ns if recorded_at is not None else newest_all
    with g.subgraph(name="cluster_legend") as legend:
        legend.attr(style="bold", color="black", label="view_frames Result")
        legend.node("legend", f"Recorded at time: {when / NSEC_PER_SEC:.3f}", shape="plaintext")
    return str(g.source)


def _write(path: Path, data: str | bytes) -> bool:
    """Write ``path``; False after a one-line error when it cannot be written."""
    try:
        if isinstance(data, str):
            path.write_text(data, encoding="utf-8")
        else:
            path.write_bytes(data)
    except OSError as err:
        error(f"cannot write {str(path)!r}: {err.strerror or err}")
        return False
    return True


@click.command("frames", epilog=RATE_HELP)
@source_options
@use_sim_time_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("frames.pdf"), show_default=True,
              help="Output file: .pdf, .svg, .png (rendered by Graphviz 'dot') or .gv/.dot.")
@click.option("--duration", "--wait", "duration", default=None,
              type=seconds(),
              help="With --bus: seconds to listen before drawing (default 5).")
def command(bag: Path | None, bus: str | None, use_sim_time: bool, output: Path,
            duration: float | None) -> int:
    """Draw the frame tree with Graphviz, like view_frames.

    Each edge is labelled with broadcaster, average rate, buffer length, most recent and
    oldest transform. .gv / .dot output is DOT text and needs nothing else; .pdf / .svg /
    .png need Graphviz's 'dot' program (without it the DOT text is written next to the
    requested file and the exit status is 1). Without --bag it listens to a live bus
    (--bus, default 'zenoh') for --duration seconds first, as view_frames does (exit
    status 1 if nothing was heard).
    Every frame id is drawn literally as one node (very long ids shortened visibly).

    \b
    Examples:
      tfbus frames --bag turtle.bag               # frames.pdf
      tfbus frames --bag nav2.mcap -o tree.svg
      tfbus frames --bag turtle.bag -o tree.gv
      tfbus frames --bus zenoh --duration 2 -o live.gv
    """
    fmt = output.suffix.lower().lstrip(".")
    if fmt not in ("pdf", "svg", "png", "gv", "dot"):
        fail(f"unsupported output {output.name!r}: use .pdf, .svg, .png, .gv or .dot")
    if not output.parent.is_dir():
        fail(f"cannot write {str(output)!r}: directory {str(output.parent)!r} does not exist")
    src = source(bag, bus, name="tfbus-frames", use_sim_time=use_sim_time)
    live_only(src, duration=duration)
    if isinstance(src, BusSource):
        import anyio

        seconds = duration if duration is not None else 5.0
        click.echo(f"Listening to {literal(src.label)} for {seconds:g} s ...", err=True)
        code = run_live(lambda: live(src, seconds, anyio.sleep_forever))
        if code is not None:
            return code
        if not src.summary().messages:
            src.report_problem(f"no transforms received from {src.label} in {seconds:g} s")
        dot = frames_dot(src.buffer(), recorded_at=src.clock.now())
    else:
        dot = frames_dot(src.buffer())
    if fmt in ("gv", "dot"):
        if not _write(output, dot):
            return 1
        console().print(f"wrote {literal(output)}")
        return finish_status(src.problem)
    gv = output.with_suffix(".gv")
    if not _write(gv, dot):
        return 1
    if shutil.which("dot") is None:
        error(f"Graphviz 'dot' not found, cannot render {output.name}; DOT text written to {gv}")
        return 1
    graphviz = importlib.import_module("graphviz")
    try:
        rendered = graphviz.Source(dot).pipe(format=fmt, quiet=True)
    except graphviz.CalledProcessError as err:
        stderr = err.stderr.decode("utf-8", "replace") if isinstance(err.stderr, bytes) else ""
        error(f"dot failed (exit status {err.returncode}): "
              f"{stderr.strip() or 'no message from dot'}")
        return 1
    except (graphviz.ExecutableNotFound, OSError) as err:
        error(f"cannot run Graphviz 'dot': {err}")
        return 1
    if not _write(output, rendered):
        return 1
    console().print(f"wrote {literal(output)} (and {literal(gv)})")
    return finish_status(src.problem)


