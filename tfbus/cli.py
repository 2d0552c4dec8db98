"""The ``tfbus`` command line: the tf2 tools every tf user knows (layer 5).

::

    tfbus bag-info PATH                       frames, parents, rates, span, static/dynamic
    tfbus echo SOURCE TARGET --bag PATH       like tf2_echo
    tfbus monitor --bag PATH                  like tf_monitor
    tfbus frames --bag PATH -o frames.pdf     like view_frames (Graphviz)
    tfbus static-transform x y z yaw pitch roll parent child
    tfbus static-transform x y z qx qy qz qw parent child
    tfbus replay PATH --rate 2                publish a bag on the bus, with a progress bar
    tfbus demo --duration 10                  the seed demo (tfbus.demo)

Every command has ``--help`` with examples. A bad argument prints one line,
``tfbus <command>: error: ...``, and exits with status 2; a damaged bag prints what was
readable, a one-line warning, and exits with status 1.

Sources: echo, monitor and frames read a :class:`TfSource`; today that is a bag
(``--bag``); a live ``--bus`` source (another process, over a transport) plugs in there.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import shutil
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

import click

from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from rich.console import Console

    from tfbus.bag import BagSummary
    from tfbus.core import BufferCore

__all__ = ["cli", "frames_dot", "main", "parse_static_args", "parse_time"]


# --------------------------------------------------------------------------- plumbing


class _Group(click.Group):
    """A click group whose usage errors are one line: ``tfbus CMD: error: MESSAGE``."""

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        try:
            rv = super().main(
                args, prog_name, complete_var, standalone_mode=False, **extra
            )
        except click.ClickException as err:
            ctx = getattr(err, "ctx", None)
            name = ctx.command_path if ctx is not None else "tfbus"
            click.echo(f"{name}: error: {_one_line(err.format_message())}", err=True)
            if standalone_mode:
                sys.exit(err.exit_code)
            raise
        except click.Abort:
            click.echo("Aborted.", err=True)
            if standalone_mode:
                sys.exit(1)
            raise
        if standalone_mode:
            sys.exit(rv if isinstance(rv, int) else 0)
        return rv


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _fail(message: str) -> NoReturn:
    """A bad argument: one line and exit code 2."""
    raise click.UsageError(message, click.get_current_context(silent=True))


def _console(err: bool = False) -> Console:
    from rich.console import Console

    console = Console(stderr=err, highlight=False, soft_wrap=True)
    if not console.is_terminal:
        console.width = 200  # pipes and files: do not squeeze tables into 80 columns
    return console


def _warn(message: str) -> None:
    click.echo(f"{click.get_current_context().command_path}: warning: {message}", err=True)


def parse_time(text: str) -> Time:
    """Parse a time argument: ``latest`` / ``0`` (tf2's latest), ``SEC.NANOSEC`` seconds
    (exact to the nanosecond, e.g. ``1396293909.544282913``) or ``NNNns``.

    Raises:
        ValueError: not a non-negative time.
    """
    t = text.strip().lower()
    if t in ("latest", "0", ""):
        return Time(0)
    if t.endswith("ns"):
        return Time.from_ns(int(t[:-2]))
    if t.startswith("-"):
        raise ValueError(f"time must not be negative: {text!r}")
    whole, _, frac = t.partition(".")
    if not (whole or frac) or not (whole or "0").isdigit() or (frac and not frac.isdigit()):
        # Scientific notation and the like: float seconds.
        value = float(t)
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"not a valid time: {text!r}")
        return Time.from_sec(value)
    frac9 = (frac + "000000000")[:9]
    return Time.from_ns(int(whole or "0") * NSEC_PER_SEC + int(frac9))


class _TimeParam(click.ParamType):  # type: ignore[type-arg,unused-ignore]
    name = "TIME"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Time:
        if isinstance(value, Time):
            return value
        try:
            return parse_time(str(value))
        except ValueError:
            self.fail(f"{value!r} is not a time (seconds, e.g. 1396293909.5, or 'latest')")


TIME = _TimeParam()


def _bag_path() -> click.Path:
    return click.Path(exists=True, dir_okay=True, file_okay=True, path_type=Path)


# --------------------------------------------------------------------------- sources


class TfSource:
    """Where echo / monitor / frames get their transforms.

    :class:`BagSource` is the one implementation today; a live-bus source (listening to
    another process through a transport) implements the same three methods.
    """

    label: str = ""

    def buffer(self) -> BufferCore:
        """A BufferCore holding the transforms (for lookups and the frame tree)."""
        raise NotImplementedError

    def summary(self) -> BagSummary:
        """Per-frame and per-broadcaster statistics (rates, delays)."""
        raise NotImplementedError

    @property
    def problem(self) -> str | None:
        """A one-line warning when the data was incomplete (a damaged bag)."""
        return None


class BagSource(TfSource):
    """Transforms from a bag file, loaded once (``tfbus.bag``)."""

    def __init__(self, path: Path) -> None:
        from tfbus.bag import BagError, detect_format

        self.path = path
        self.label = str(path)
        self._buffer: BufferCore | None = None
        self._summary: BagSummary | None = None
        self._problem: str | None = None
        try:
            detect_format(path)
        except BagError as err:
            _fail(_one_line(str(err)))

    def buffer(self) -> BufferCore:
        from tfbus.bag import BagReadError, load_buffer

        if self._buffer is None:
            try:
                self._buffer = load_buffer(self.path)
            except BagReadError as err:
                self._problem = _one_line(str(err))
                self._buffer = err.partial
        assert self._buffer is not None
        return self._buffer

    def summary(self) -> BagSummary:
        from tfbus.bag import summarize

        if self._summary is None:
            self._summary = summarize(self.path)
            if self._summary.error is not None:
                self._problem = _one_line(str(self._summary.error))
        return self._summary

    @property
    def problem(self) -> str | None:
        return self._problem


F = TypeVar("F", bound=Callable[..., Any])


def _source_options(f: F) -> F:
    """``--bag PATH`` and ``--bus ENDPOINT``: the transform source of echo/monitor/frames."""
    f = click.option("--bus", "bus", metavar="ENDPOINT", default=None, hidden=True,
                     help="Attach to a live bus (comes with the transport).")(f)
    return click.option("--bag", type=_bag_path(), help="Read transforms from this bag.")(f)


def _source(bag: Path | None, bus: str | None = None) -> TfSource:
    if bus is not None:
        _fail("live --bus sources come with the transport; use --bag PATH for now")
    if bag is None:
        _fail("no transform source: pass --bag PATH (live --bus sources come later)")
    return BagSource(bag)


def _finish(source: TfSource) -> int:
    if source.problem:
        _warn(source.problem)
        return 1
    return 0


def _fmt_sec(ns: int | None) -> str:
    if ns is None:
        return "-"
    return f"{ns // NSEC_PER_SEC}.{ns % NSEC_PER_SEC:09d}"


# --------------------------------------------------------------------------- the group


@click.group("tfbus", cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="tfbus", prog_name="tfbus")
def cli() -> None:
    """tfbus: ROS tf2's tools for plain Python (bags, echo, monitor, view_frames).

    \b
    Examples:
      tfbus bag-info turtle.bag
      tfbus echo world turtle1 --bag turtle.bag --time 1396293900
      tfbus frames --bag turtle.bag -o frames.pdf
    """


# --------------------------------------------------------------------------- bag-info


@cli.command("bag-info")
@click.argument("path", type=_bag_path())
def bag_info(path: Path) -> int:
    """Frames, parents, broadcasters, rates and time span of a bag's tf data.

    PATH is a ROS 1 .bag, a ROS 2 bag folder, or a .db3 / .mcap file.

    \b
    Examples:
      tfbus bag-info turtle.bag
      tfbus bag-info rosbag2_2024_05_03/
      tfbus bag-info nav2.mcap
    """
    from rich.table import Table

    src = BagSource(path)
    s = src.summary()
    out = _console()
    out.print(f"path:       {path}")
    out.print(f"format:     {s.format.value if s.format else '?'}")
    out.print(
        f"tf span:    {_fmt_sec(s.start.ns if s.start else None)} .. "
        f"{_fmt_sec(s.end.ns if s.end else None)} ({s.duration:.3f} s bag time)"
    )
    topics = ", ".join(f"{t} {n}" for t, n in sorted(s.messages.items())) or "none"
    out.print(f"messages:   {topics}")
    n_static = sum(1 for f in s.frames.values() if f.static)
    all_frames = set(s.frames) | {f.parent for f in s.frames.values()}
    out.print(
        f"frames:     {len(all_frames)} ({n_static} static links, "
        f"{len(s.frames) - n_static} dynamic links, {s.transform_count} transforms)"
    )
    table = Table(show_edge=False, header_style="bold")
    for col, justify in (
        ("frame", "left"), ("parent", "left"), ("kind", "left"), ("broadcaster", "left"),
        ("samples", "right"), ("rate Hz", "right"), ("oldest", "right"), ("newest", "right"),
    ):
        table.add_column(col, justify=justify)  # type: ignore[arg-type]
    for f in sorted(s.frames.values(), key=lambda f: (f.static, f.parent, f.child)):
        table.add_row(
            f.child, f.parent, "static" if f.static else "dynamic", f.authority,
            str(f.count), "-" if f.static else f"{f.rate:.2f}",
            _fmt_sec(f.first_stamp), _fmt_sec(f.last_stamp),
        )
    out.print(table)
    return _finish(src)


# --------------------------------------------------------------------------- echo


def _format_transform(ts: TransformStamped, *, precision: int, matrix: bool) -> str:
    from tfbus.geometry import euler_from_quaternion, transform_to_matrix

    p = precision
    tr, q = ts.transform.translation, ts.transform.rotation
    r, pi, y = euler_from_quaternion((q.x, q.y, q.z, q.w))
    lines = [
        f"At time {_fmt_sec(ts.header.stamp.ns)}",
        f"- Translation: [{tr.x:.{p}f}, {tr.y:.{p}f}, {tr.z:.{p}f}]",
        f"- Rotation: in Quaternion [{q.x:.{p}f}, {q.y:.{p}f}, {q.z:.{p}f}, {q.w:.{p}f}]",
        f"            in RPY (radian) [{r:.{p}f}, {pi:.{p}f}, {y:.{p}f}]",
        f"            in RPY (degree) [{math.degrees(r):.{p}f}, {math.degrees(pi):.{p}f}, "
        f"{math.degrees(y):.{p}f}]",
    ]
    if matrix:
        m = transform_to_matrix(ts)
        lines.append("- Matrix:")
        lines.extend("  " + " ".join(f"{v:{p + 4}.{p}f}" for v in row) for row in m.tolist())
    return "\n".join(lines)


def _chain_span(core: BufferCore, frames: Sequence[str]) -> tuple[int, int] | None:
    """[oldest, newest] stamp range covered by every dynamic link on the path between
    ``frames`` (up to their lowest common ancestor); None when the path is all static."""
    info = {c: (p, st, o, n) for c, p, _a, st, _s, o, n in core.frame_info()}

    def ancestors(frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in info and info[chain[-1]][0] not in chain:
            chain.append(info[chain[-1]][0])
        return chain

    chains = [ancestors(f) for f in frames]
    common = set(chains[0]).intersection(*chains[1:])
    lo, hi = 0, None
    for chain in chains:
        for frame in chain:
            if frame in common:
                break
            _parent, static, oldest, newest = info[frame]
            if not static:
                lo = max(lo, oldest)
                hi = newest if hi is None else min(hi, newest)
    if hi is None:
        return None
    return lo, hi


def _echo_times(core: BufferCore, source: str, target: str, rate: float) -> Iterator[Time]:
    span = _chain_span(core, (source, target))
    if span is None:  # static chain: one answer holds for all time
        yield Time(0)
        return
    lo, hi = span
    step = round(NSEC_PER_SEC / rate)
    t = lo
    while t <= hi:
        yield Time.from_ns(t)
        t += step


@cli.command()
@click.argument("source")
@click.argument("target")
@_source_options
@click.option("--rate", type=click.FloatRange(min=0, min_open=True), default=1.0,
              show_default=True, help="Echo rate, Hz (of bag time with --bag).")
@click.option("--time", "at", type=TIME, default=None,
              help="Look up once at this time (seconds, or 'latest').")
@click.option("--matrix", is_flag=True, help="Also print the 4x4 homogeneous matrix.")
@click.option("-p", "--precision", type=click.IntRange(0, 12), default=3, show_default=True,
              help="Digits after the decimal point.")
@click.option("-n", "--limit", type=click.IntRange(min=1), default=None,
              help="Stop after this many lookups.")
def echo(
    source: str, target: str, bag: Path | None, bus: str | None, rate: float, at: Time | None,
    matrix: bool, precision: int, limit: int | None,
) -> int:
    """Print the transform from SOURCE to TARGET, like tf2_echo.

    As tf2_echo, this is the pose of TARGET in SOURCE, i.e. lookup_transform(SOURCE,
    TARGET, t): it maps points in TARGET into SOURCE. With --bag and no --time, it steps
    through the recording at --rate Hz of bag time.

    \b
    Examples:
      tfbus echo world turtle1 --bag turtle.bag
      tfbus echo world turtle1 --bag turtle.bag --time 1396293900.25 --matrix
      tfbus echo map base_link --bag nav2.mcap --rate 10 -n 5
    """
    from tfbus.errors import TransformException

    src = _source(bag, bus)
    core = src.buffer()
    for name in (source, target):
        if not core.frame_exists(name):
            _fail(f"frame {name!r} does not exist in {src.label}")
    times: Iterator[Time] = iter([at]) if at is not None else _echo_times(
        core, source, target, rate
    )
    out = _console()
    failures = 0
    for i, t in enumerate(times):
        if limit is not None and i >= limit:
            break
        try:
            ts = core.lookup_transform(source, target, t)
        except TransformException as err:
            failures += 1
            out.print(f"Failure at {_fmt_sec(t.ns)}\nException thrown:{err}\n"
                      "The current list of frames is:")
            out.print(core.all_frames_as_string(), end="")
            continue
        out.print(_format_transform(ts, precision=precision, matrix=matrix))
    code = _finish(src)
    return code or (1 if failures and at is not None else 0)


# --------------------------------------------------------------------------- monitor


@cli.command()
@click.argument("frames", nargs=-1)
@_source_options
def monitor(frames: tuple[str, ...], bag: Path | None, bus: str | None) -> int:
    """Per-frame rates, delays and broadcasters, like tf_monitor.

    Delay is receive (bag) time minus header stamp. With [SOURCE TARGET] only the
    frames on the chain between them are listed, as tf_monitor does.

    \b
    Examples:
      tfbus monitor --bag turtle.bag
      tfbus monitor world turtle1 --bag turtle.bag
    """
    from rich.table import Table

    if len(frames) not in (0, 2):
        _fail("give no frames, or exactly two: SOURCE TARGET")
    src = _source(bag, bus)
    s = src.summary()
    selected = list(s.frames.values())
    if frames:
        chain: set[str] = set()
        for name in frames:
            if name not in s.frames and all(f.parent != name for f in s.frames.values()):
                _fail(f"frame {name!r} does not exist in {src.label}")
            seen: set[str] = set()
            while name in s.frames and name not in seen:
                seen.add(name)
                chain.add(name)
                name = s.frames[name].parent
        selected = [f for f in selected if f.child in chain]
    out = _console()
    title = f"RESULTS: for {' to '.join(frames)}" if frames else "RESULTS: for all Frames"
    out.print(title)
    table = Table(title="Frames", show_edge=False, header_style="bold")
    for col in ("frame", "parent", "published by", "rate Hz", "avg delay s", "max delay s"):
        table.add_column(col, justify="left" if col in ("frame", "parent", "published by")
                         else "right")
    for f in sorted(selected, key=lambda f: f.child):
        dyn = not f.static
        table.add_row(
            f.child, f.parent, f.authority,
            f"{f.rate:.3f}" if dyn else "static",
            f"{f.delay_avg:.6f}" if dyn else "-",
            f"{f.delay_max:.6f}" if dyn and f.count else "-",
        )
    out.print(table)
    btable = Table(title="All Broadcasters", show_edge=False, header_style="bold")
    for col in ("node", "rate Hz", "avg delay s", "max delay s"):
        btable.add_column(col, justify="left" if col == "node" else "right")
    for a in sorted(s.authorities.values(), key=lambda a: a.authority):
        btable.add_row(
            a.authority, f"{a.rate:.3f}",
            f"{a.delay_avg:.6f}" if a.delay_count else "-",
            f"{a.delay_max:.6f}" if a.delay_count else "-",
        )
    out.print(btable)
    return _finish(src)


# --------------------------------------------------------------------------- frames


def frames_dot(core: BufferCore, *, recorded_at: Time | None = None) -> str:
    """The frame tree as Graphviz DOT text, in view_frames' layout: one edge per link,
    labelled with broadcaster, average rate, buffer length, most recent and oldest
    transform (seconds); static links say so. Needs the ``graphviz`` Python package only.
    """
    graphviz = importlib.import_module("graphviz")

    g = graphviz.Digraph("G")
    newest_all = 0
    for child, parent, authority, static, samples, oldest, newest in core.frame_info():
        if static:
            label = f"Broadcaster: {authority}\nAverage rate: static\nBuffer length: 0.0\n"
        else:
            length = (newest - oldest) / NSEC_PER_SEC
            rate = samples / length if length > 0 else 0.0
            newest_all = max(newest_all, newest)
            label = (
                f"Broadcaster: {authority}\nAverage rate: {rate:.3f}\n"
                f"Buffer length: {length:.3f}\n"
                f"Most recent transform: {newest / NSEC_PER_SEC:.3f}\n"
                f"Oldest transform: {oldest / NSEC_PER_SEC:.3f}\n"
            )
        g.edge(parent, child, label=label)
    when = recorded_at.ns if recorded_at is not None else newest_all
    with g.subgraph(name="cluster_legend") as legend:
        legend.attr(style="bold", color="black", label="view_frames Result")
        legend.node("legend", f"Recorded at time: {when / NSEC_PER_SEC:.3f}", shape="plaintext")
    return str(g.source)


@cli.command()
@_source_options
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("frames.pdf"), show_default=True,
              help="Output file: .pdf, .svg, .png (rendered by Graphviz 'dot') or .gv/.dot.")
def frames(bag: Path | None, bus: str | None, output: Path) -> int:
    """Draw the frame tree with Graphviz, like view_frames.

    Each edge is labelled with broadcaster, average rate, buffer length, most recent and
    oldest transform. .gv / .dot output is DOT text and needs nothing else; .pdf / .svg /
    .png need Graphviz's 'dot' program (without it the DOT text is written next to the
    requested file and the exit status is 1).

    \b
    Examples:
      tfbus frames --bag turtle.bag               # frames.pdf
      tfbus frames --bag nav2.mcap -o tree.svg
      tfbus frames --bag turtle.bag -o tree.gv
    """
    fmt = output.suffix.lower().lstrip(".")
    if fmt not in ("pdf", "svg", "png", "gv", "dot"):
        _fail(f"unsupported output {output.name!r}: use .pdf, .svg, .png, .gv or .dot")
    src = _source(bag, bus)
    dot = frames_dot(src.buffer())
    if fmt in ("gv", "dot"):
        output.write_text(dot)
        click.echo(f"wrote {output}")
        return _finish(src)
    gv = output.with_suffix(".gv")
    gv.write_text(dot)
    if shutil.which("dot") is None:
        click.echo(f"{click.get_current_context().command_path}: error: Graphviz 'dot' not "
                   f"found, cannot render {output.name}; DOT text written to {gv}", err=True)
        return 1
    graphviz = importlib.import_module("graphviz")
    try:
        output.write_bytes(graphviz.Source(dot).pipe(format=fmt))
    except (graphviz.ExecutableNotFound, graphviz.CalledProcessError) as err:
        click.echo(f"{click.get_current_context().command_path}: error: "
                   f"{_one_line(str(err))}", err=True)
        return 1
    click.echo(f"wrote {output} (and {gv})")
    return _finish(src)


# --------------------------------------------------------------------------- static-transform


def parse_static_args(args: Sequence[str], stamp: Time | None = None) -> TransformStamped:
    """Parse static_transform_publisher's positional arguments into a TransformStamped.

    ``x y z yaw pitch roll parent child`` (angles in radians, applied as tf2's
    ``setRPY(roll, pitch, yaw)``: fixed axes X, Y, Z) or ``x y z qx qy qz qw parent
    child`` (normalised). A trailing ROS 1 ``period_in_ms`` is accepted and ignored.

    Raises:
        ValueError: wrong count, a non-number, a zero quaternion or parent == child.
    """
    from tfbus.geometry import quaternion_from_euler

    items = list(args)
    if len(items) in (9, 10) and _is_number(items[-1]) and not _is_number(items[-2]):
        items = items[:-1]  # ROS 1 period_in_ms
    if len(items) not in (8, 9):
        raise ValueError(
            f"expected 8 arguments (x y z yaw pitch roll parent child) or 9 "
            f"(x y z qx qy qz qw parent child), got {len(args)}"
        )
    *numbers, parent, child = items
    values = []
    for text in numbers:
        try:
            v = float(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{text!r} is not a finite number")
        values.append(v)
    if not parent or not child:
        raise ValueError("frame ids must not be empty")
    if parent.lstrip("/") == child.lstrip("/"):
        raise ValueError(f"parent and child frame are both {parent!r}")
    x, y, z = values[:3]
    if len(values) == 6:
        yaw, pitch, roll = values[3:]
        qx, qy, qz, qw = (float(c) for c in quaternion_from_euler(roll, pitch, yaw, "sxyz"))
    else:
        qx, qy, qz, qw = values[3:]
        norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        if norm == 0.0:
            raise ValueError("quaternion (0, 0, 0, 0) is not a rotation")
        qx, qy, qz, qw = qx / norm, qy / norm, qz / norm, qw / norm
    return TransformStamped(
        Header(stamp if stamp is not None else Time(0), parent),
        child,
        Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)),
    )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


@cli.command(
    "static-transform",
    context_settings={"ignore_unknown_options": True},
)
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
@click.option("--once", is_flag=True, help="Publish once and exit (default: until Ctrl-C).")
def static_transform(args: tuple[str, ...], once: bool) -> int:
    """Publish a static transform on /tf_static, like static_transform_publisher.

    \b
    Arguments (static_transform_publisher's conventions):
      x y z yaw pitch roll parent child       metres, radians (yaw about Z, pitch
                                              about Y, roll about X: setRPY)
      x y z qx qy qz qw parent child          quaternion, normalised

    \b
    Examples:
      tfbus static-transform 0.1 0 0.2 0 0 0 base_link base_laser
      tfbus static-transform 0 0 1 0 0 0.7071068 0.7071068 world camera --once
      tfbus static-transform -1 0 0 1.5708 0 0 map odom    # negatives need no --
    """
    import anyio

    try:
        ts = parse_static_args(args)
    except ValueError as err:
        _fail(str(err))
    out = _console()
    tr, q = ts.transform.translation, ts.transform.rotation
    out.print(
        f"publishing static transform {ts.header.frame_id} -> {ts.child_frame_id}: "
        f"translation ({tr.x}, {tr.y}, {tr.z}), rotation ({q.x:.9g}, {q.y:.9g}, "
        f"{q.z:.9g}, {q.w:.9g})"
    )
    with contextlib.suppress(KeyboardInterrupt):
        anyio.run(_publish_static, ts, once)
    return 0


async def _publish_static(ts: TransformStamped, once: bool) -> None:
    import anyio

    from tfbus.broadcaster import StaticTransformBroadcaster
    from tfbus.bus import Bus

    async with Bus() as bus:
        await StaticTransformBroadcaster(bus).send_transform(ts)
        if not once:
            await anyio.sleep_forever()


# --------------------------------------------------------------------------- replay


@cli.command()
@click.argument("path", type=_bag_path())
@click.option("--rate", "-r", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Speed factor (2 = twice as fast); 0 = as fast as possible.")
@click.option("--start", type=TIME, default=None, help="Start at this bag time (seconds).")
@click.option("--stop", type=TIME, default=None, help="Stop before this bag time.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def replay(path: Path, rate: float, start: Time | None, stop: Time | None, quiet: bool) -> int:
    """Publish a bag's /tf and /tf_static on the bus at recorded timing.

    A ManualClock follows bag time, so anything awaiting on the bus sees the recording's
    time. Statics recorded before --start are published first (latched).

    \b
    Examples:
      tfbus replay turtle.bag
      tfbus replay nav2.mcap --rate 4
      tfbus replay turtle.bag --rate 0 --start 1396293900
    """
    import anyio

    from tfbus.bag import BagError, BagReadError, detect_format, summarize

    try:
        detect_format(path)
    except BagError as err:
        _fail(_one_line(str(err)))
    total = summarize(path)
    n_total = sum(total.messages.values())
    try:
        n = anyio.run(_replay, path, rate, start, stop, quiet, n_total)
    except BagReadError as err:
        click.echo(f"replayed {err.messages_read} messages from {path}")
        _warn(_one_line(str(err)))
        return 1
    except KeyboardInterrupt:
        return 130
    click.echo(f"replayed {n} messages from {path}")
    return 0


async def _replay(
    path: Path, rate: float, start: Time | None, stop: Time | None, quiet: bool, total: int
) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from tfbus.bag import BagMessage, BagReadError, replay
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    clock = ManualClock()
    progress = Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
        TimeElapsedColumn(), console=_console(err=True), disable=quiet, transient=False,
    )
    with progress:
        task = progress.add_task(f"replay {path.name}", total=total or None)

        def advance(rec: BagMessage) -> None:
            progress.update(task, advance=1, description=f"bag time {_fmt_sec(rec.time.ns)}")

        async with Bus() as bus:
            try:
                return await replay(
                    path, bus, clock=clock, rate=rate or None, start=start, stop=stop,
                    on_message=advance,
                )
            except BagReadError as err:
                # Raise it outside the bus's task group (no exception group soup).
                problem = err
        raise problem


# --------------------------------------------------------------------------- demo


@cli.command()
@click.option("--duration", type=click.FloatRange(min=0), default=None,
              help="Seconds to run (default: until Ctrl-C).")
@click.option("--rate", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Broadcast rate, Hz (default 100).")
@click.option("--listen-rate", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Listener rate, Hz (default 1).")
@click.option("--backend", type=click.Choice(["asyncio", "trio"]), default=None,
              help="Event loop (default asyncio).")
def demo(
    duration: float | None, rate: float | None, listen_rate: float | None, backend: str | None
) -> int:
    """Run the seed demo: a 100 Hz broadcaster and a 1 Hz listener on one bus.

    \b
    Examples:
      tfbus demo --duration 10
      tfbus demo --rate 50 --listen-rate 2 --backend trio
    """
    try:
        demo_module = importlib.import_module("tfbus.demo")
    except ImportError as err:
        raise click.ClickException(f"the demo is not available: {err}") from None
    argv: list[str] = []
    for flag, value in (("--duration", duration), ("--rate", rate),
                        ("--listen-rate", listen_rate)):
        if value is not None:
            argv += [flag, repr(value)]
    if backend is not None:
        argv += ["--backend", backend]
    run: Callable[[list[str] | None], int] = demo_module.main
    return int(run(argv) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tfbus`` command (``pyproject.toml``); returns the exit status."""
    try:
        rv = cli.main(args=list(argv) if argv is not None else None, prog_name="tfbus",
                      standalone_mode=False)
    except click.ClickException as err:
        return err.exit_code
    except click.Abort:
        return 1
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":
    sys.exit(main())
