"""``tfbus monitor``: tf_monitor on a bag or a live bus; the summary tables are
:mod:`tfbus.monitor`'s."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bag_source import BagSource
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
from tfbus.time import Time

_ZERO = Time(0)

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table

    from tfbus.doctor import Doctor
    from tfbus.fleet import FleetBuffer
    from tfbus.monitor import AuthoritySummary, TfSummary
    from tfbus.transports._base import PeerInfo

__all__ = ["chain_lines", "command", "liveliness_table", "print_monitor", "robots_table",
           "tf2_chain"]


def tf2_chain(parents: dict[str, str], a: str, b: str) -> list[str] | None:
    """tf_monitor's ``Chain is:`` list for ``A B``: tf2 ``_chainAsVector(B, 0, A, 0, B)``
    (:func:`tfbus.compat.tf2_py.chain`, tf2_py's ``_chain`` exactly) over each frame's latest
    parent; None when tf2 would raise (unconnected, a loop)."""
    from tfbus.compat.tf2_py import chain
    from tfbus.core import BufferCore
    from tfbus.errors import TransformException
    from tfbus.messages import Header, Transform, TransformStamped

    core = BufferCore()
    for child, parent in parents.items():
        core.set_transform_static(TransformStamped(Header(frame_id=parent), child, Transform()))
    try:
        return chain(core, b, _ZERO, a, _ZERO, b)
    except TransformException:
        return None


def chain_lines(stats: TfSummary, frames: Sequence[str]) -> list[str]:
    """tf_monitor's lines for ``A B`` (ros/geometry ``tf/src/tf_monitor.cpp``, spin)::

        Chain is: A -> ... -> B
        Net delay     avg = <avg>: max = <max>

    numbers as C++'s default ``ostream`` writes doubles (``%g``), names literal; tf_monitor's
    waiting line while the two frames are not connected."""
    source, target = frames
    chain = next((c for c in stats.chains if (c.source, c.target) == (source, target)), None)
    if chain is None or chain.frames is None:
        return [f"Waiting for transform chain to become available between {literal(source)} "
                f"and {literal(target)}"]
    shown = tf2_chain(stats.parents(), source, target)
    return [
        "Chain is: " + " -> ".join(literal(f) for f in (chain.frames if shown is None else shown)),
        f"Net delay     avg = {chain.delay_avg:g}: max = {chain.delay_max:g}",
    ]


def _table(title: str, names: Sequence[str], numbers: Sequence[str]) -> Table:
    from rich.table import Table

    table = Table(title=title, show_edge=False, header_style="bold")
    for col in names:  # ids wrap, they are never cut off
        table.add_column(col, overflow="fold")
    for col in numbers:
        table.add_column(col, justify="right", no_wrap=True, min_width=len(col))
    return table


def print_monitor(
    out: Console, s: TfSummary, frames: Sequence[str], live_src: BusSource | None = None,
    doctor: Doctor | None = None,
) -> None:
    """tf_monitor's report: ``RESULTS`` (and for ``A B`` the chain and its net delay),
    the frames table, the broadcasters table and, for a live bus, the broadcasters known
    through liveliness (when the transport has it).

    On a live bus the rates are the recent ones (:data:`tfbus.monitor.RATE_WINDOW`
    seconds before now): the frames of a broadcaster that stopped fall to 0.000 and read
    ``stale`` (silent for :data:`tfbus.monitor.STALE_PERIODS` of their periods, at least
    :data:`tfbus.monitor.STALE_AFTER` s); a bag's are over the whole recording.

    With a ``doctor`` watching the live bus (:func:`tfbus.cli.doctor.watch`), its findings
    so far follow (``tfbus doctor``'s table), or one line saying there are none."""
    from tfbus.monitor import FrameSummary, expiry_line

    now = live_src.clock.now() if live_src is not None else None

    def rate(x: FrameSummary | AuthoritySummary) -> float:
        return x.rate if now is None else x.recent_rate(now)

    def shown(x: FrameSummary | AuthoritySummary) -> str:
        stale = now is not None and x.stale(now)
        return f"{rate(x):.3f}" + (" stale" if stale else "")

    # Frames the buffer has forgotten (expire_after) have left the summary already
    # (MonitoredSink drops them as the buffer removes their links).
    selected = list(s.frames.values())
    expiring = live_src.buffer() if live_src is not None else None
    policy = expiring.cache_policy if expiring is not None else None
    title = (f"RESULTS: for {literal(frames[0])} to {literal(frames[1])}" if frames
             else "RESULTS: for all Frames")
    if live_src is not None:
        title += f" (live, {s.duration:.1f} s, {sum(s.messages.values())} messages)"
    out.print(title)
    if frames:
        for line in chain_lines(s, frames):
            out.print(line)
        chain = s.chain(frames[0], frames[1]) or ()
        selected = [f for f in selected if f.child in chain]
    if s.sim_time:
        out.print("note: header stamps are simulated time (far from the receive clock): "
                  "delays are measured against the newest stamp received, not the clock")
    table = _table("Frames", ("frame", "parent", "published by"),
                   ("rate Hz", "avg delay s", "max delay s"))
    for f in sorted(selected, key=lambda f: f.child):
        dyn = not f.static
        table.add_row(
            literal(f.child), literal(f.parent), literal(f.authority),
            shown(f) if dyn else "static",
            f"{f.delay_avg:.6f}" if dyn else "-",
            f"{f.delay_max:.6f}" if dyn and f.delay_count else "-",
        )
    out.print(table)
    btable = _table("All Broadcasters", ("node",), ("rate Hz", "avg delay s", "max delay s"))
    for a in sorted(s.authorities.values(), key=lambda a: a.authority):
        btable.add_row(
            literal(a.authority), shown(a),
            f"{a.delay_avg:.6f}" if a.delay_count else "-",
            f"{a.delay_max:.6f}" if a.delay_count else "-",
        )
    out.print(btable)
    if live_src is not None:
        line = transport_line(live_src)
        if line:
            out.print(line)
    if expiring is not None and policy is not None:
        out.print(expiry_line(expiring.statistics(), policy))
    if live_src is not None and doctor is not None:
        from tfbus.cli.doctor import findings_table, live_report

        found = live_report(live_src, doctor)
        if found.findings:
            out.print(findings_table(found, title="Findings (tfbus doctor)"))
        else:
            out.print("doctor: no problems found")
    if live_src is not None and live_src.fleet is not None:
        out.print(robots_table(live_src.fleet, s, rate))
    if live_src is not None and live_src.has_liveliness:
        out.print(liveliness_table(live_src))


def transport_line(src: BusSource) -> str:
    """What the transport lost or dropped on the way in, for a transport that counts it
    (Zenoh's :class:`~tfbus.transports.zenoh.counters.ZenohStatistics`): ``lost`` is the
    gaps in the publishers' sequence numbers (messages a congested network or a sender's
    ``congestion_control="drop"`` publisher dropped: the sender cannot count those),
    ``dropped`` the payloads refused on receipt. Empty for a transport without them."""
    statistics = getattr(src.transport, "statistics", None)
    stats = statistics() if callable(statistics) else None
    if stats is None or not hasattr(stats, "lost"):
        return ""
    return (f"transport: {stats.received} received, {stats.lost} lost (gaps in the "
            f"publishers' sequence numbers), {stats.dropped} dropped on receipt")


def robots_table(fleet: FleetBuffer, s: TfSummary,
                 rate: Callable[[AuthoritySummary], float]) -> Table:
    """The robots of a fleet bus (``--bus "zenoh:namespace=*"``): alive or gone (Zenoh
    liveliness), their broadcasters, messages received and their rate (the sum of their
    broadcasters' rates, Hz)."""
    table = _table("Robots", ("robot", "status", "broadcasters"), ("messages", "rate Hz"))
    for name, info in sorted(fleet.robots().items()):
        hz = sum(rate(a) for a in s.authorities.values() if a.authority.startswith(name + "/"))
        table.add_row(literal(name), "alive" if info.alive else "gone",
                      ", ".join(literal(b) for b in sorted(info.broadcasters)),
                      str(info.messages), f"{hz:.3f}")
    return table


def liveliness_table(src: BusSource) -> Table:
    """Broadcasters by Zenoh liveliness: the alive ones (``transport.broadcasters()``)
    and those whose liveliness went away while we listened."""
    table = _table("Broadcasters (liveliness)", ("node", "status", "node id", "topics"), ())
    alive = src.alive_broadcasters()
    rows = [(info, "alive") for info in alive.values()]
    rows += [(info, "gone") for nid, info in src.gone.items() if nid not in alive]
    for info, status in sorted(rows, key=lambda r: (r[1], r[0].name, r[0].node_id)):
        table.add_row(literal(info.name), status, literal(info.node_id),
                      ", ".join(literal(t) for t in sorted(info.topics)))
    return table


@click.command("monitor", epilog=RATE_HELP)
@click.argument("frames", nargs=-1)
@source_options
@use_sim_time_option
@click.option("--duration", type=seconds(), default=None,
              help="With --bus: stop after this many seconds (default: Ctrl-C).")
@click.option("--interval", type=seconds(), default=None,
              help="With --bus: print the tables every this many seconds (default 1).")
@click.option("--expire-after", "expire_seconds", type=seconds(), default=None,
              help="With --bus: forget frames whose data stopped this many seconds (of "
                   "stamp time) before the newest; they leave the table and are counted.")
def command(
    frames: tuple[str, ...], bag: Path | None, bus: str | None, use_sim_time: bool,
    duration: float | None, interval: float | None, expire_seconds: float | None,
) -> int:
    """Per-frame rates, delays and broadcasters, like tf_monitor.

    Delay is receive (bag) time minus header stamp. With [SOURCE TARGET] only the
    frames on the chain between them are listed, after tf_monitor's "Chain is:" and
    "Net delay avg/max" lines. On a bag recorded with simulated time (stamps far from
    the recorder's clock) delays are measured against the newest stamp, with a note.

    Without --bag it listens to a live bus (--bus, default 'zenoh'): the tables
    (cumulative since it attached) are printed every --interval seconds and on exit,
    with the broadcasters known through
    Zenoh liveliness (alive / gone); a line is printed as soon as a broadcaster appears
    ("[alive] ...") or its liveliness is lost because it exited or died ("[dead] ...").
    With --expire-after S the buffer forgets frames whose data stopped S seconds of
    stamp time before the newest (tf2 keeps them forever): they leave the Frames table
    and a "buffer: ... frames expired" line counts them.

    \b
    Examples:
      tfbus monitor --bag turtle.bag
      tfbus monitor world turtle1 --bag turtle.bag
      tfbus monitor --bus zenoh
      tfbus monitor base_link base_laser --bus zenoh --duration 10 --interval 5
      tfbus monitor --bus 'zenoh:mode=client&connect=tcp/127.0.0.1:7447&namespace=*'

    With --bus 'zenoh:...&namespace=*' it listens to every robot (each robot's bus has
    its own namespace=NAME): frames are listed as NAME/frame and a Robots table says
    which robots are alive or gone, their broadcasters and rates.
    """
    if len(frames) not in (0, 2):
        fail("give no frames, or exactly two: SOURCE TARGET")
    from tfbus.core.policy import expire_after

    policy = None
    if expire_seconds is not None:
        try:
            policy = expire_after(expire_seconds)
        except ValueError as exc:  # a positive value below 1 ns
            fail(f"--expire-after: {exc}")
    src = source(bag, bus, name="tfbus-monitor", use_sim_time=use_sim_time,
                 cache_policy=policy)
    live_only(src, duration=duration, interval=interval, expire_after=expire_seconds)
    if isinstance(src, BusSource):
        if frames:
            src.summary().watch_chain(frames[0], frames[1])
        return _monitor_live(src, frames, duration=duration, interval=interval or 1.0)
    assert isinstance(src, BagSource)
    if frames:
        stats = src.summary()
        for name in frames:
            if name not in stats.frames and all(f.parent != name for f in stats.frames.values()):
                fail(f"frame {name!r} does not exist in {src.label}")
        if stats.chain(frames[0], frames[1]) is None:
            error(f"frames {frames[0]!r} and {frames[1]!r} are not connected in {src.label} "
                  "(they are in different trees)")
            return 1
        src.chain = list(frames)
        src.reset_summary()
    print_monitor(console(), src.summary(), frames)
    return finish_status(src.problem)


def _monitor_live(
    src: BusSource, frames: Sequence[str], *, duration: float | None, interval: float
) -> int:
    from tfbus.cli.doctor import watch
    from tfbus.clock import every

    out = console()
    doctor = None if src.is_fleet else watch(src)

    def on_peer(what: str, info: PeerInfo) -> None:
        if what == "alive":
            out.print(f"[alive] broadcaster {literal(info.name)} (node {literal(info.node_id)}) "
                      f"publishes {', '.join(literal(t) for t in sorted(info.topics))}")
        else:
            out.print(f"[dead] broadcaster {literal(info.name)} (node {literal(info.node_id)}) "
                      "is gone: liveliness lost (it exited, was killed or is unreachable)")

    def report() -> None:
        print_monitor(out, src.summary(), frames, live_src=src, doctor=doctor)

    async def body() -> None:
        async for _ in every(interval, clock=src.clock):
            report()

    out.print(f"listening to {literal(src.label)} ...")
    code = run_live(lambda: live(src, duration, body, on_peer=on_peer, finish=report))
    return code if code is not None else 0
