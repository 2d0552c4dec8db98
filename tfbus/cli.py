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
    tfbus demo listener / demo broadcaster    the tutorial's nodes as two processes (Zenoh)
    tfbus echo SOURCE TARGET --bus zenoh      ... echo, monitor, frames on a live bus

Every command has ``--help`` with examples. A bad argument prints one line,
``tfbus <command>: error: ...``, and exits with status 2; a damaged bag prints what was
readable, a one-line warning, and exits with status 1.

Sources: echo, monitor and frames read a :class:`TfSource`: a bag (``--bag``,
:class:`BagSource`) or a live bus carried over Zenoh (``--bus SPEC``, :class:`BusSource`,
which collects what other processes broadcast while it is attached). Live commands are
bounded by ``--duration`` (and echo by ``-n``); Ctrl-C / SIGTERM end them cleanly.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import math
import shutil
import signal
import sys
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

import click

from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    import anyio
    from rich.console import Console
    from rich.table import Table

    from tfbus.bag import BagSummary
    from tfbus.buffer import Buffer
    from tfbus.bus import Subscription
    from tfbus.core import BufferCore
    from tfbus.transports.zenoh import PeerEvent, PeerInfo, ZenohOptions, ZenohTransport

__all__ = [
    "BagSource",
    "BusSource",
    "TfSource",
    "cli",
    "frames_dot",
    "main",
    "parse_static_args",
    "parse_time",
]


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

    :class:`BagSource` reads a recording; :class:`BusSource` listens to a live bus (other
    processes, over Zenoh) and fills the same two structures while it is attached.
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


_UNKNOWN_AUTHORITY = "unknown"
_SHARED_AUTHORITY = "unattributed"


class BusSource(TfSource):
    """Transforms from a live bus carried over Zenoh (``--bus SPEC``).

    While :meth:`attach` is open, every ``/tf`` and ``/tf_static`` message other
    processes broadcast is stored in :meth:`buffer` (a :class:`~tfbus.buffer.Buffer`, so
    lookups can be awaited) and accounted in :meth:`summary` (receive time = wall clock,
    delay = receive time - header stamp, as tf_monitor measures it), and liveliness
    changes of broadcasters are tracked (:attr:`gone`).

    Authority: the wire format does not say which node sent a message, so a message is
    attributed to the one live broadcaster publishing its topic (``"unknown"`` before
    any is known, ``"unattributed"`` when several publish it).

    Args:
        spec: a ``--bus`` value (:func:`tfbus.transports.zenoh.parse_bus_spec`).
        name: this node's name unless ``spec`` gives one (``zenoh?name=...``).
        cache_time: seconds of history the buffer keeps.
    """

    def __init__(self, spec: str, *, name: str = "tfbus-cli", cache_time: float = 10.0) -> None:
        from tfbus.bag import BagSummary
        from tfbus.buffer import Buffer
        from tfbus.clock import SystemClock

        try:
            zenoh_module = importlib.import_module("tfbus.transports.zenoh")
        except ImportError as err:
            _fail(f"--bus needs the Zenoh transport (pip install 'tfbus[zenoh]'): {err}")
        try:
            options: ZenohOptions = zenoh_module.parse_bus_spec(spec)
        except ValueError as err:
            _fail(_one_line(str(err)))
        if options.name is None:
            options = dataclasses.replace(options, name=name)
        self.spec = spec
        self.options = options
        self.label = f"the bus {spec!r}"
        self.clock = SystemClock()
        self._buffer: Buffer = Buffer(cache_time=cache_time, clock=self.clock)
        self._summary: BagSummary = BagSummary()
        self.transport: ZenohTransport | None = None
        self.broadcasters_seen: dict[str, PeerInfo] = {}
        """Every broadcaster heard of through liveliness, by node id."""
        self.gone: dict[str, PeerInfo] = {}
        """Broadcasters whose liveliness went away (exited, killed or unreachable)."""
        self.invalid = 0
        """Transforms the buffer rejected (NaN, bad quaternion, bad frame ids)."""
        self._problem: str | None = None

    def buffer(self) -> Buffer:
        return self._buffer

    def summary(self) -> BagSummary:
        return self._summary

    @property
    def problem(self) -> str | None:
        return self._problem

    def report_problem(self, message: str) -> None:
        """Record a one-line warning (printed at the end, exit status 1)."""
        self._problem = message

    def alive_broadcasters(self) -> dict[str, PeerInfo]:
        """The live broadcasters now (``transport.broadcasters()``), empty when detached."""
        return self.transport.broadcasters() if self.transport is not None else {}

    @contextlib.asynccontextmanager
    async def attach(
        self, on_peer: Callable[[str, PeerInfo], None] | None = None
    ) -> AsyncIterator[BusSource]:
        """Open the bus and collect until the block ends.

        ``on_peer(what, info)`` is called with ``what`` = ``"alive"`` when a node starts
        broadcasting (its first ``/tf`` or ``/tf_static``) and ``"gone"`` when a known
        broadcaster's liveliness disappears.

        Raises:
            zenoh.ZError: if the session cannot be opened (endpoint in use, bad config).
        """
        import anyio

        from tfbus.bus import Bus
        from tfbus.transports.zenoh import PEERS_TOPIC

        transport = self.options.transport()
        async with Bus(transport=transport, queue_size=10_000) as bus:
            self.transport = transport
            tf = bus.subscribe("/tf")
            tf_static = bus.subscribe("/tf_static")
            peers = bus.subscribe(PEERS_TOPIC, queue_size=1000)
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._feed, tf, False)
                tg.start_soon(self._feed, tf_static, True)
                tg.start_soon(self._watch, peers, on_peer)
                try:
                    yield self
                finally:
                    tg.cancel_scope.cancel()
        self.transport = None

    def _authority(self, topic: str) -> str:
        names = {p.name for p in self.alive_broadcasters().values() if topic in p.topics}
        if len(names) == 1:
            return names.pop()
        return _SHARED_AUTHORITY if names else _UNKNOWN_AUTHORITY

    async def _feed(self, sub: Subscription[Any], static: bool) -> None:
        from tfbus.bag import BagMessage
        from tfbus.errors import TransformException
        from tfbus.messages import TFMessage

        buffer = self._buffer
        store = buffer.set_transform_static if static else buffer.set_transform
        async for msg in sub:
            if not isinstance(msg, TFMessage):
                continue
            authority = self._authority(sub.topic)
            self._summary.add(BagMessage(self.clock.now(), sub.topic, msg, authority))
            for ts in msg.transforms:
                try:
                    store(ts, authority)
                except TransformException:
                    self.invalid += 1

    async def _watch(
        self, sub: Subscription[Any], on_peer: Callable[[str, PeerInfo], None] | None
    ) -> None:
        from tfbus.transports.zenoh import PeerInfo

        async for event in sub:
            ev: PeerEvent = event
            known = self.broadcasters_seen.get(ev.node_id)
            if ev.alive and ev.topic in ("/tf", "/tf_static"):
                topics = (known.topics if known else frozenset()) | {ev.topic}
                info = PeerInfo(ev.node_id, ev.name, topics)
                self.broadcasters_seen[ev.node_id] = info
                self.gone.pop(ev.node_id, None)
                if known is None and on_peer is not None:
                    on_peer("alive", info)
            elif (
                not ev.alive and not ev.topic and known is not None
                and ev.node_id not in self.gone
            ):
                self.gone[ev.node_id] = known
                if on_peer is not None:
                    on_peer("gone", known)


F = TypeVar("F", bound=Callable[..., Any])


def _source_options(f: F) -> F:
    """``--bag PATH`` and ``--bus SPEC``: the transform source of echo/monitor/frames."""
    f = click.option(
        "--bus", "bus", metavar="SPEC", default=None,
        help="Attach to a live bus over Zenoh instead: 'zenoh' (this machine, no "
             "configuration), 'zenoh:tcp/HOST:7448', 'zenoh?connect=...&namespace=...'.",
    )(f)
    return click.option("--bag", type=_bag_path(), help="Read transforms from this bag.")(f)


def _source(bag: Path | None, bus: str | None = None, *, name: str = "tfbus-cli") -> TfSource:
    if bus is not None and bag is not None:
        _fail("give --bag PATH or --bus SPEC, not both")
    if bus is not None:
        return BusSource(bus, name=name)
    if bag is None:
        _fail("no transform source: pass --bag PATH or --bus SPEC (e.g. --bus zenoh)")
    return BagSource(bag)


def _positive_or_none(value: float | None, flag: str) -> None:
    if value is not None and not value > 0:
        _fail(f"{flag} must be positive")


def _live_only(src: TfSource, **options: object) -> None:
    """Options that only mean something on a live bus: an error with --bag."""
    if not isinstance(src, BusSource):
        for name, value in options.items():
            if value is not None:
                _fail(f"--{name.replace('_', '-')} applies to --bus sources only")


def _run_live(main: Callable[[], Awaitable[None]]) -> int | None:
    """``anyio.run(main)``; None when it ran, 1 (after a one-line error) when the bus
    could not be opened, 130 on a Ctrl-C before the signal handler was installed."""
    import anyio

    try:
        anyio.run(main)
    except KeyboardInterrupt:  # Ctrl-C while the session was still opening
        return 130
    except Exception as err:
        if not _is_bus_error(err):
            raise
        click.echo(f"{click.get_current_context().command_path}: error: cannot open the "
                   f"bus: {_one_line(str(err))}", err=True)
        return 1
    return None


def _is_bus_error(err: BaseException) -> bool:
    return isinstance(err, OSError) or type(err).__module__.partition(".")[0] == "zenoh"


async def _cancel_on_signal(scope: anyio.CancelScope) -> None:
    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            scope.cancel()
            return


async def _live(
    source: BusSource,
    duration: float | None,
    body: Callable[[], Awaitable[None]],
    *,
    on_peer: Callable[[str, PeerInfo], None] | None = None,
    finish: Callable[[], None] | None = None,
) -> None:
    """Attach ``source`` and run ``body`` until it returns, ``duration`` seconds have
    passed (None: no limit) or SIGINT/SIGTERM arrives; then call ``finish`` while still
    attached (so liveliness is current) and detach."""
    import anyio

    async with source.attach(on_peer), anyio.create_task_group() as tg:
        with anyio.CancelScope() as scope:
            if duration is not None:
                scope.deadline = anyio.current_time() + duration
            tg.start_soon(_cancel_on_signal, scope)
            await body()
        if finish is not None:
            finish()
        tg.cancel_scope.cancel()


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
              help="Stop after this many lookups (with --bus: transforms printed).")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=None,
              help="With --bus: stop after this many seconds (default: -n, or Ctrl-C).")
def echo(
    source: str, target: str, bag: Path | None, bus: str | None, rate: float, at: Time | None,
    matrix: bool, precision: int, limit: int | None, duration: float | None,
) -> int:
    """Print the transform from SOURCE to TARGET, like tf2_echo.

    As tf2_echo, this is the pose of TARGET in SOURCE, i.e. lookup_transform(SOURCE,
    TARGET, t): it maps points in TARGET into SOURCE. With --bag and no --time, it steps
    through the recording at --rate Hz of bag time. With --bus it listens to a live bus
    and prints the latest transform (or the one at --time) at --rate Hz of wall time,
    saying on stderr what it is waiting for until the frames are connected.

    \b
    Examples:
      tfbus echo world turtle1 --bag turtle.bag
      tfbus echo world turtle1 --bag turtle.bag --time 1396293900.25 --matrix
      tfbus echo map base_link --bag nav2.mcap --rate 10 -n 5
      tfbus echo base_link base_laser --bus zenoh -n 1
      tfbus echo base_link base_laser --bus zenoh:tcp/192.168.1.10:7448 --duration 10
    """
    from tfbus.errors import TransformException

    src = _source(bag, bus, name="tfbus-echo")
    _live_only(src, duration=duration)
    if isinstance(src, BusSource):
        return _echo_live(src, source, target, rate=rate, at=at, matrix=matrix,
                          precision=precision, limit=limit, duration=duration)
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


def _echo_live(
    src: BusSource, source: str, target: str, *, rate: float, at: Time | None, matrix: bool,
    precision: int, limit: int | None, duration: float | None,
) -> int:
    """echo --bus: look up at every tick of a ``rate`` Hz timer; when the transform is
    not there yet, say why on stderr and wait for it up to the next tick."""
    from tfbus.clock import every
    from tfbus.errors import TransformException

    out = _console()
    buffer = src.buffer()
    period = 1.0 / rate
    when = at if at is not None else Time(0)
    if at is not None and limit is None:
        limit = 1  # one time, one answer
    printed = 0

    async def body() -> None:
        nonlocal printed
        async for _ in every(period, clock=src.clock, immediate=True):
            try:
                ts = buffer.lookup_transform(source, target, when)
            except TransformException as err:
                click.echo(f"Waiting for transform {source} -> {target}: "
                           f"{_one_line(str(err))}", err=True)
                try:
                    ts = await buffer.lookup_transform_async(
                        source, target, when, timeout=0.9 * period
                    )
                except TransformException:
                    continue
            out.print(_format_transform(ts, precision=precision, matrix=matrix))
            printed += 1
            if limit is not None and printed >= limit:
                return

    code = _run_live(lambda: _live(src, duration, body))
    if code is not None:
        return code
    if printed == 0 or (limit is not None and printed < limit):
        _warn(f"{printed} of {limit if limit is not None else 'any'} transform(s) from "
              f"{source} to {target} received from {src.label}")
        return 1
    return 0


# --------------------------------------------------------------------------- monitor


@cli.command()
@click.argument("frames", nargs=-1)
@_source_options
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=None,
              help="With --bus: stop after this many seconds (default: Ctrl-C).")
@click.option("--interval", type=click.FloatRange(min=0, min_open=True), default=None,
              help="With --bus: print the tables every this many seconds (default 1).")
def monitor(
    frames: tuple[str, ...], bag: Path | None, bus: str | None, duration: float | None,
    interval: float | None,
) -> int:
    """Per-frame rates, delays and broadcasters, like tf_monitor.

    Delay is receive (bag) time minus header stamp. With [SOURCE TARGET] only the
    frames on the chain between them are listed, as tf_monitor does.

    With --bus it listens to a live bus: the tables (cumulative since it attached) are
    printed every --interval seconds and on exit, with the broadcasters known through
    Zenoh liveliness (alive / gone); a line is printed as soon as a broadcaster appears
    ("[alive] ...") or its liveliness is lost because it exited or died ("[dead] ...").

    \b
    Examples:
      tfbus monitor --bag turtle.bag
      tfbus monitor world turtle1 --bag turtle.bag
      tfbus monitor --bus zenoh
      tfbus monitor base_link base_laser --bus zenoh --duration 10 --interval 5
    """
    if len(frames) not in (0, 2):
        _fail("give no frames, or exactly two: SOURCE TARGET")
    src = _source(bag, bus, name="tfbus-monitor")
    _live_only(src, duration=duration, interval=interval)
    if isinstance(src, BusSource):
        return _monitor_live(src, frames, duration=duration, interval=interval or 1.0)
    s = src.summary()
    for name in frames:
        if name not in s.frames and all(f.parent != name for f in s.frames.values()):
            _fail(f"frame {name!r} does not exist in {src.label}")
    _print_monitor(_console(), s, frames)
    return _finish(src)


def _print_monitor(
    out: Console, s: BagSummary, frames: Sequence[str], live: BusSource | None = None
) -> None:
    """tf_monitor's report: the frames table, the broadcasters table and, for a live
    bus, the broadcasters known through liveliness."""
    from rich.table import Table

    selected = list(s.frames.values())
    if frames:
        chain: set[str] = set()
        for name in frames:
            seen: set[str] = set()
            while name in s.frames and name not in seen:
                seen.add(name)
                chain.add(name)
                name = s.frames[name].parent
        selected = [f for f in selected if f.child in chain]
    title = f"RESULTS: for {' to '.join(frames)}" if frames else "RESULTS: for all Frames"
    if live is not None:
        title += f" (live, {s.duration:.1f} s, {sum(s.messages.values())} messages)"
    out.print(title, markup=False)
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
    if live is not None:
        out.print(_liveliness_table(live))


def _liveliness_table(src: BusSource) -> Table:
    """Broadcasters by Zenoh liveliness: the alive ones (``transport.broadcasters()``)
    and those whose liveliness went away while we listened."""
    from rich.table import Table

    table = Table(title="Broadcasters (liveliness)", show_edge=False, header_style="bold")
    for col in ("node", "status", "node id", "topics"):
        table.add_column(col)
    alive = src.alive_broadcasters()
    rows = [(info, "alive") for info in alive.values()]
    rows += [(info, "gone") for nid, info in src.gone.items() if nid not in alive]
    for info, status in sorted(rows, key=lambda r: (r[1], r[0].name, r[0].node_id)):
        table.add_row(info.name, status, info.node_id, ", ".join(sorted(info.topics)))
    return table


def _monitor_live(
    src: BusSource, frames: Sequence[str], *, duration: float | None, interval: float
) -> int:
    from tfbus.clock import every

    out = _console()

    def on_peer(what: str, info: PeerInfo) -> None:
        if what == "alive":
            out.print(f"[alive] broadcaster {info.name} (node {info.node_id}) publishes "
                      f"{', '.join(sorted(info.topics))}", markup=False)
        else:
            out.print(f"[dead] broadcaster {info.name} (node {info.node_id}) is gone: "
                      "liveliness lost (it exited, was killed or is unreachable)", markup=False)

    def report() -> None:
        _print_monitor(out, src.summary(), frames, live=src)

    async def body() -> None:
        async for _ in every(interval, clock=src.clock):
            report()

    out.print(f"listening to {src.label} ...", markup=False)
    code = _run_live(lambda: _live(src, duration, body, on_peer=on_peer, finish=report))
    return code if code is not None else 0


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
@click.option("--duration", "--wait", "duration", default=None,
              type=click.FloatRange(min=0, min_open=True),
              help="With --bus: seconds to listen before drawing (default 5).")
def frames(bag: Path | None, bus: str | None, output: Path, duration: float | None) -> int:
    """Draw the frame tree with Graphviz, like view_frames.

    Each edge is labelled with broadcaster, average rate, buffer length, most recent and
    oldest transform. .gv / .dot output is DOT text and needs nothing else; .pdf / .svg /
    .png need Graphviz's 'dot' program (without it the DOT text is written next to the
    requested file and the exit status is 1). With --bus it listens to a live bus for
    --duration seconds first, as view_frames does (exit status 1 if nothing was heard).

    \b
    Examples:
      tfbus frames --bag turtle.bag               # frames.pdf
      tfbus frames --bag nav2.mcap -o tree.svg
      tfbus frames --bag turtle.bag -o tree.gv
      tfbus frames --bus zenoh --duration 2 -o live.gv
    """
    fmt = output.suffix.lower().lstrip(".")
    if fmt not in ("pdf", "svg", "png", "gv", "dot"):
        _fail(f"unsupported output {output.name!r}: use .pdf, .svg, .png, .gv or .dot")
    src = _source(bag, bus, name="tfbus-frames")
    _live_only(src, duration=duration)
    if isinstance(src, BusSource):
        import anyio

        seconds = duration if duration is not None else 5.0
        click.echo(f"Listening to {src.label} for {seconds:g} s ...", err=True)
        code = _run_live(lambda: _live(src, seconds, anyio.sleep_forever))
        if code is not None:
            return code
        if not src.summary().messages:
            src.report_problem(f"no transforms received from {src.label} in {seconds:g} s")
        dot = frames_dot(src.buffer(), recorded_at=src.clock.now())
    else:
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


def _demo_options(*, rate: bool, listen_rate: bool) -> Callable[[F], F]:
    """The options of ``tfbus demo`` and its roles (all default to None: demo's own)."""

    def decorate(f: F) -> F:
        f = click.option("--backend", type=click.Choice(["asyncio", "trio"]), default=None,
                         help="Event loop (default asyncio).")(f)
        if listen_rate:
            f = click.option("--listen-rate", type=click.FloatRange(min=0, min_open=True),
                             default=None, help="Listener rate, Hz (default 1).")(f)
        if rate:
            f = click.option("--rate", type=click.FloatRange(min=0, min_open=True),
                             default=None, help="Broadcast rate, Hz (default 100).")(f)
        return click.option("--duration", type=click.FloatRange(min=0), default=None,
                            help="Seconds to run (default: until Ctrl-C).")(f)

    return decorate


def _run_demo_main(role: str | None, bus: str | None, **options: Any) -> int:
    """Forward to ``tfbus.demo.main`` (the same code as ``python demos/robot_setup_tf.py``)."""
    try:
        demo_module = importlib.import_module("tfbus.demo")
    except ImportError as err:
        raise click.ClickException(f"the demo is not available: {err}") from None
    argv: list[str] = [role] if role is not None else []
    if bus is not None:
        argv += ["--bus", bus]
    for name in ("duration", "rate", "listen_rate"):
        value = options.get(name)
        if value is not None:
            argv += [f"--{name.replace('_', '-')}", repr(value)]
    if options.get("backend") is not None:
        argv += ["--backend", options["backend"]]
    run: Callable[[list[str] | None], int] = demo_module.main
    return int(run(argv) or 0)


def _check_bus_spec(bus: str | None) -> None:
    """A bad ``--bus`` of a demo role is a one-line usage error here, not in the demo."""
    if bus is None:
        return
    try:
        zenoh_module = importlib.import_module("tfbus.transports.zenoh")
    except ImportError as err:
        _fail(f"--bus needs the Zenoh transport (pip install 'tfbus[zenoh]'): {err}")
    try:
        zenoh_module.parse_bus_spec(bus)
    except ValueError as err:
        _fail(_one_line(str(err)))


def _inherit(ctx: click.Context, **options: Any) -> dict[str, Any]:
    """A role's options, falling back to those given to ``tfbus demo`` before the role."""
    parent = ctx.parent.params if ctx.parent is not None else {}
    return {k: v if v is not None else parent.get(k) for k, v in options.items()}


_BUS_HELP = ("Bus to run on (default 'zenoh': this machine, no configuration), e.g. "
             "'zenoh?listen=tcp/127.0.0.1:7500' or 'zenoh:tcp/192.168.1.10:7448'.")


@cli.group(invoke_without_command=True)
@_demo_options(rate=True, listen_rate=True)
@click.pass_context
def demo(
    ctx: click.Context, duration: float | None, rate: float | None,
    listen_rate: float | None, backend: str | None,
) -> int:
    """Run the seed demo: a 100 Hz broadcaster and a 1 Hz listener on one bus.

    Without a command both nodes run in this process. With 'broadcaster' or 'listener'
    that node runs alone over Zenoh, as in the tutorial's separate terminals: the
    listener prints the tutorial's ERROR line each second until a broadcaster is up,
    then the INFO lines.

    \b
    Examples:
      tfbus demo --duration 10
      tfbus demo --rate 50 --listen-rate 2 --backend trio
      tfbus demo listener                  # terminal 1
      tfbus demo broadcaster               # terminal 2
      tfbus monitor --bus zenoh            # terminal 3
    """
    if ctx.invoked_subcommand is not None:
        return 0
    return _run_demo_main(None, None, duration=duration, rate=rate,
                          listen_rate=listen_rate, backend=backend)


@demo.command("broadcaster")
@click.option("--bus", metavar="SPEC", default=None, help=_BUS_HELP)
@_demo_options(rate=True, listen_rate=False)
@click.pass_context
def demo_broadcaster(
    ctx: click.Context, bus: str | None, duration: float | None, rate: float | None,
    backend: str | None,
) -> int:
    """The tutorial's robot_tf_publisher alone: base_link -> base_laser over Zenoh.

    It prints nothing but its summary line on exit (a startup note goes to stderr).

    \b
    Examples:
      tfbus demo broadcaster
      tfbus demo broadcaster --rate 50 --duration 30
      tfbus demo broadcaster --bus 'zenoh?listen=tcp/127.0.0.1:7500'
    """
    _check_bus_spec(bus)
    return _run_demo_main("broadcaster", bus, **_inherit(
        ctx, duration=duration, rate=rate, backend=backend))


@demo.command("listener")
@click.option("--bus", metavar="SPEC", default=None, help=_BUS_HELP)
@_demo_options(rate=False, listen_rate=True)
@click.pass_context
def demo_listener(
    ctx: click.Context, bus: str | None, duration: float | None, listen_rate: float | None,
    backend: str | None,
) -> int:
    """The tutorial's robot_tf_listener alone, over Zenoh: the tutorial's line each second.

    \b
    Examples:
      tfbus demo listener
      tfbus demo listener --listen-rate 2 --duration 10
      tfbus demo listener --bus 'zenoh?connect=tcp/127.0.0.1:7500'
    """
    _check_bus_spec(bus)
    return _run_demo_main("listener", bus, **_inherit(
        ctx, duration=duration, listen_rate=listen_rate, backend=backend))


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
