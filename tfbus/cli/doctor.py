"""``tfbus doctor``: what is wrong with a tf tree, in a recording or live on a bus
(:mod:`tfbus.doctor`): a table (or ``--json``), exit status by ``--fail-on``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bag_source import BagSource
from tfbus.cli._bus_source import BusSource
from tfbus.cli._common import (
    console,
    fail,
    fmt_sec,
    literal,
    seconds,
    use_sim_time_option,
)
from tfbus.cli._live_session import live, run_live
from tfbus.cli._source_options import live_only, source, source_options

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rich.console import Console
    from rich.table import Table

    from tfbus.doctor import Doctor, Report
    from tfbus.messages import TransformStamped
    from tfbus.time import Time

__all__ = ["DEFAULT_DURATION", "FAIL_ON", "command", "exit_status", "findings_table",
           "live_report", "print_report", "watch"]

DEFAULT_DURATION = 10.0
"""Seconds ``tfbus doctor --bus`` listens when no ``--duration`` is given."""
FAIL_ON = ("error", "warning", "info", "never")
"""``--fail-on`` values: exit 1 when a finding is at that level or worse (never: 0)."""


def exit_status(report: Report, fail_on: str) -> int:
    """1 when ``report`` has a finding at ``fail_on`` or worse, else 0 (``never``: 0)."""
    if fail_on == "never":
        return 0
    return 1 if report.at_least(fail_on) else 0


def print_report(out: Console, report: Report) -> None:
    """The report as a heading, the findings table (most severe first) and the
    broadcasters' delays; every id printed literally (no markup, control characters
    escaped)."""
    span = (report.end_ns - report.start_ns) / 1e9 if report.start_ns is not None \
        and report.end_ns is not None else 0.0
    out.print(f"tfbus doctor: {literal(report.source)}: {report.messages} messages, "
              f"{report.transforms} transforms, {report.frames} frames ({report.links} "
              f"links), {span:.3f} s"
              + (" (simulated time stamps)" if report.sim_time else ""))
    counts = {lv: sum(f.level.value == lv for f in report.findings) for lv in FAIL_ON[:3]}
    if not report.findings:
        out.print("no problems found")
    else:
        out.print(", ".join(f"{n} {lv}{'s' if n != 1 else ''}" for lv, n in counts.items()))
        out.print(findings_table(report))
    if report.broadcasters:
        from rich.table import Table

        table = Table(title="Broadcasters: receive time - header stamp", show_edge=False,
                      header_style="bold")
        table.add_column("sender", overflow="fold")
        for col in ("transforms", "median delay s", "spread s"):
            table.add_column(col, justify="right", no_wrap=True)
        for b in report.broadcasters:
            table.add_row(literal(b.sender), str(b.transforms), f"{b.median:.6f}",
                          f"{b.spread:.6f}")
        out.print(table)


def findings_table(report: Report, *, title: str | None = None) -> Table:
    """The findings, most severe first: level, check, frames, senders, receive-time span,
    what was found and the advice (ids literal: no markup, control characters escaped)."""
    from rich.table import Table

    table = Table(title=title, show_edge=False, header_style="bold", show_lines=True)
    for col in ("level", "check", "frames", "senders", "span (receive time)", "finding",
                "advice"):
        table.add_column(col, overflow="fold")
    for f in report.findings:
        when = "-" if f.start_ns is None else f"{fmt_sec(f.start_ns)} .. {fmt_sec(f.end_ns)}"
        table.add_row(
            f.level.value, f.check, "\n".join(literal(x) for x in f.frames[:10]),
            "\n".join(literal(x) for x in f.senders[:10]), when, literal(f.message),
            literal(f.advice))
    return table


@click.command("doctor")
@source_options
@use_sim_time_option
@click.option("--duration", type=seconds(), default=None,
              help=f"With --bus: listen this many seconds (default {DEFAULT_DURATION:g}; "
                   "Ctrl-C reports early).")
@click.option("--json", "as_json", is_flag=True,
              help="Print the report as JSON (schema: docs/doctor.md) instead of tables.")
@click.option("--fail-on", type=click.Choice(FAIL_ON), default="error", show_default=True,
              help="Exit with status 1 when a finding is at this level or worse.")
def command(bag: Path | None, bus: str | None, use_sim_time: bool, duration: float | None,
            as_json: bool, fail_on: str) -> int:
    """Find what is wrong with a tf tree: several broadcasters of one frame, a frame both
    static and dynamic, parent changes, loops, REP 105 order, frame ids starting with '/',
    stopped frames, gaps, rate drops, repeated and out-of-order stamps, clock offsets and
    latency per broadcaster, disconnected trees, a damaged recording.

    One finding per problem: its level (error, warning, info), the frames and senders
    involved, the time span, and one line of advice. Senders are named where the source
    knows them (ROS 1 bags and buses: the caller id; Zenoh: liveliness).

    \b
    Examples:
      tfbus doctor --bag run.bag
      tfbus doctor --bag run.mcap --json > report.json
      tfbus doctor --bag run.bag --fail-on warning      # CI: exit 1 on a warning
      tfbus doctor --bus zenoh --duration 30
      tfbus doctor --bus ros1 --duration 5
    """
    from tfbus.doctor import diagnose

    src = source(bag, bus, name="tfbus-doctor", use_sim_time=use_sim_time)
    live_only(src, duration=duration)
    if isinstance(src, BusSource):
        report = _doctor_live(src, duration if duration is not None else DEFAULT_DURATION)
        if report is None:
            return 1
    else:
        assert isinstance(src, BagSource)
        report = diagnose(src.path)
    if as_json:
        click.echo(report.to_json())
    else:
        print_report(console(), report)
    return exit_status(report, fail_on)


def watch(src: BusSource) -> Doctor:
    """A :class:`~tfbus.doctor.Doctor` fed by ``src`` once attached: through the monitor
    sink's observers where liveliness names the sender (Zenoh), else a
    :class:`~tfbus.doctor.DoctorSink` in front of the sink (the transport's sender: ROS
    1's caller id; ``unknown`` where the transport names none, as ``tfbus monitor``).
    Call before :meth:`BusSource.attach`."""
    from tfbus.doctor import Doctor, DoctorSink

    doctor = Doctor(source=src.spec)
    if src.has_liveliness:  # the sender is the broadcaster liveliness names
        def observe(now: Time, items: Sequence[TransformStamped], authority: str,
                    static: bool) -> None:
            doctor.add(now, items, authority, static=static)

        src.sink.observers.append(observe)
    else:  # the sender is the transport's (ROS 1: the caller id of the connection)
        from tfbus.transports.spec import schemes

        scheme = schemes().get(src.bus_spec.scheme)
        unnamed = (scheme.unknown_authority if scheme is not None else None) or "unknown"

        def sender(static: bool, authority: str) -> str:
            # the listener's own default: the transport did not name the publisher
            return unnamed if authority == "default_authority" else authority

        src.sink = DoctorSink(doctor, src.clock, src.sink,  # type: ignore[assignment]
                              authority=sender)
    return doctor


def live_report(src: BusSource, doctor: Doctor) -> Report:
    """The doctor's report now (silence measured up to ``src``'s clock), the messages that
    came before their broadcaster's liveliness accounted to it."""
    _name_unknown(src, doctor)
    return doctor.report(now=src.clock.now())


def _doctor_live(src: BusSource, duration: float) -> Report | None:
    """Listen for ``duration`` seconds (or until Ctrl-C), then the report; None when the
    bus could not be opened (after a one-line error)."""
    import anyio

    if src.is_fleet:
        fail("doctor reads one robot's bus: give the robot's namespace, not namespace=*")
    doctor = watch(src)
    result: list[Report] = []

    def finish() -> None:
        result.append(live_report(src, doctor))

    code = run_live(lambda: live(src, duration, anyio.sleep_forever, finish=finish))
    if code == 1 or not result:
        return None
    return result[0]


def _name_unknown(src: BusSource, doctor: Doctor) -> None:
    """What arrived before its broadcaster's liveliness (sender ``"unknown"``) goes, topic
    by topic, to the one broadcaster liveliness names on that topic, as the monitor's
    summary does (:meth:`tfbus.monitor.TfSummary.rename_authority`)."""
    from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

    for topic, static in ((TF_TOPIC, False), (TF_STATIC_TOPIC, True)):
        names = {p.name for p in src.broadcasters_seen.values() if topic in p.topics}
        if len(names) == 1:
            doctor.rename_authority("unknown", names.pop(), static=static)
