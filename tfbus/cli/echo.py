"""``tfbus echo``: tf2_echo / tf_echo on a bag or a live bus."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bus_source import BusSource
from tfbus.cli._common import (
    TIME,
    console,
    error,
    fail,
    finish_status,
    fmt_sec,
    hertz,
    literal,
    literal_lines,
    one_line,
    seconds,
    use_sim_time_option,
    warn,
)
from tfbus.cli._live_session import live, run_live
from tfbus.cli._source_options import live_only, source, source_options
from tfbus.messages import TransformStamped
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["command", "failure_text", "format_transform"]


def format_transform(ts: TransformStamped, *, precision: int, matrix: bool) -> str:
    """tf_echo's report of one transform (``At time``, translation, rotation as quaternion
    x, y, z, w and as RPY in radians and degrees; optionally the 4x4 matrix)."""
    from tfbus.geometry import euler_from_quaternion, transform_to_matrix

    p = precision
    tr, q = ts.transform.translation, ts.transform.rotation
    r, pi, y = euler_from_quaternion((q.x, q.y, q.z, q.w))
    lines = [
        f"At time {fmt_sec(ts.header.stamp.ns)}",
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


def failure_text(t: Time, error: Exception, core: BufferCore) -> str:
    """tf_echo's failure report, word for word (ros/geometry ``tf/src/tf_echo.cpp``)::

        Failure at <time>
        Exception thrown:<the exception's message, with the frame names>
        The current list of frames is:
        <allFramesAsString>

    (tf_echo ends it with one more ``endl``: a blank line), every line made literal
    (control characters escaped)."""
    return (
        f"Failure at {fmt_sec(t.ns)}\nException thrown:{literal(error)}\n"
        f"The current list of frames is:\n{literal_lines(core.all_frames_as_string())}"
    )


def _chain_span(core: BufferCore, frames: Sequence[str]) -> tuple[int, int] | None:
    """[oldest, newest] stamp range covered by every dynamic link on the chain between
    the two ``frames``; None when the chain is all static or the frames are not
    connected (two trees: the lookup then reports why)."""
    info = {c: (p, st, o, n) for c, p, _a, st, _s, o, n in core.frame_info()}
    chain = core.frame_path(frames[0], frames[1])
    if chain is None:
        return None
    lo, hi = 0, None
    for frame in chain:
        link = info.get(frame)
        if link is None or link[1]:
            continue
        _parent, _static, oldest, newest = link
        # A link below the common ancestor is in the chain with its parent; the top frame
        # of the chain contributes nothing (its own link is not traversed).
        if link[0] not in chain:
            continue
        lo = max(lo, oldest)
        hi = newest if hi is None else min(hi, newest)
    if hi is None:
        return None
    return lo, hi


def _echo_times(core: BufferCore, source: str, target: str, rate: float) -> Iterator[Time]:
    span = _chain_span(core, (source, target))
    if span is None:  # static chain (or none): one answer holds for all time
        yield Time(0)
        return
    lo, hi = span
    step = round(NSEC_PER_SEC / rate)
    t = lo
    while t <= hi:
        yield Time.from_ns(t)
        t += step


@click.command("echo")
@click.argument("source_frame", metavar="SOURCE")
@click.argument("target_frame", metavar="TARGET")
@click.argument("rate_arg", metavar="[RATE]", required=False,
                type=hertz())
@source_options
@use_sim_time_option
@click.option("--rate", type=hertz(), default=None,
              help="Echo rate, Hz (of bag time with --bag); default 1. Also tf2_echo's "
                   "third argument, RATE.")
@click.option("--time", "at", type=TIME, default=None,
              help="Look up once at this time (seconds, or 'latest').")
@click.option("--matrix", is_flag=True, help="Also print the 4x4 homogeneous matrix.")
@click.option("-p", "--precision", type=click.IntRange(0, 12), default=3, show_default=True,
              help="Digits after the decimal point.")
@click.option("-n", "--limit", type=click.IntRange(min=1), default=None,
              help="Stop after this many lookups (with --bus: transforms printed).")
@click.option("--duration", type=seconds(), default=None,
              help="With --bus: stop after this many seconds (default: -n, or Ctrl-C).")
def command(
    source_frame: str, target_frame: str, rate_arg: float | None, bag: Path | None,
    bus: str | None, use_sim_time: bool, rate: float | None, at: Time | None, matrix: bool,
    precision: int, limit: int | None, duration: float | None,
) -> int:
    """Print the transform from SOURCE to TARGET, like tf2_echo.

    As tf2_echo, this is the pose of TARGET in SOURCE, i.e. lookup_transform(SOURCE,
    TARGET, t): it maps points in TARGET into SOURCE. With --bag and no --time, it steps
    through the recording at --rate Hz of bag time. Otherwise it listens to a live bus
    (--bus, default 'zenoh', where 'tfbus static-transform' and the demo publish) and
    prints the latest transform (or the one at --time) at --rate Hz of wall time, saying
    on stderr what it is waiting for until the frames are connected. A failed
    lookup prints tf2_echo's "Failure at ... Exception thrown:..." text (exit status 1).

    As tf2_echo, the rate may be the third argument (tfbus echo A B 10). A frame id
    tf2 refuses (empty, or starting with '/') is tf2's own one-line message, exit
    status 1 (the lookup fails).

    \b
    Examples:
      tfbus echo world turtle1 --bag turtle.bag
      tfbus echo world turtle1 10 --bag turtle.bag        # tf2_echo's rate argument
      tfbus echo world turtle1 --bag turtle.bag --time 1396293900.25 --matrix
      tfbus echo map base_link --bag nav2.mcap --rate 10 -n 5
      tfbus echo base_link base_laser          # the default bus, until Ctrl-C
      tfbus echo base_link base_laser --bus zenoh -n 1
      tfbus echo base_link base_laser --bus zenoh:tcp/192.168.1.10:7448 --duration 10
    """
    from tfbus.core.kernels import INVALID_ARGUMENT
    from tfbus.core.text import bad_frame_exception
    from tfbus.errors import TransformException

    if rate_arg is not None and rate is not None and rate_arg != rate:
        fail(f"two rates: RATE {rate_arg:g} and --rate {rate:g}; give one")
    rate = rate_arg if rate_arg is not None else rate if rate is not None else 1.0
    if source_frame != target_frame:  # tf2 returns the identity before validating
        for label, frame in (("lookupTransform argument target_frame", source_frame),
                             ("lookupTransform argument source_frame", target_frame)):
            if not frame or frame.startswith("/"):  # tf2 validateFrameId: never found
                error(str(bad_frame_exception(label, frame, INVALID_ARGUMENT)))
                return 1
    src = source(bag, bus, name="tfbus-echo", use_sim_time=use_sim_time)
    live_only(src, duration=duration)
    if isinstance(src, BusSource):
        return _echo_live(src, source_frame, target_frame, rate=rate, at=at, matrix=matrix,
                          precision=precision, limit=limit, duration=duration)
    core = src.buffer()
    for name in (source_frame, target_frame):
        if not core.frame_exists(name):
            fail(f"frame {name!r} does not exist in {src.label}")
    times: Iterator[Time] = iter([at]) if at is not None else _echo_times(
        core, source_frame, target_frame, rate
    )
    out = console()
    failures = lookups = 0
    for i, t in enumerate(times):
        if limit is not None and i >= limit:
            break
        lookups += 1
        try:
            ts = core.lookup_transform(source_frame, target_frame, t)
        except TransformException as err:
            failures += 1
            out.print(failure_text(t, err, core))  # + tf_echo's blank line after the list
            continue
        out.print(format_transform(ts, precision=precision, matrix=matrix))
    code = finish_status(src.problem)
    # Exit status 1 when the one lookup asked for, or every lookup, failed.
    return code or (1 if failures and (at is not None or failures == lookups) else 0)


def _echo_live(
    src: BusSource, source: str, target: str, *, rate: float, at: Time | None, matrix: bool,
    precision: int, limit: int | None, duration: float | None,
) -> int:
    """echo --bus: look up at every tick of a ``rate`` Hz timer; when the transform is
    not there yet, say why on stderr and wait for it up to the next tick."""
    from tfbus.clock import every
    from tfbus.errors import TransformException

    out = console()
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
                click.echo(f"Waiting for transform {literal(source)} -> {literal(target)}: "
                           f"{one_line(str(err))}", err=True)
                try:
                    ts = await buffer.lookup_transform_async(
                        source, target, when, timeout=0.9 * period
                    )
                except TransformException:
                    continue
            out.print(format_transform(ts, precision=precision, matrix=matrix))
            printed += 1
            if limit is not None and printed >= limit:
                return

    code = run_live(lambda: live(src, duration, body))
    if code is not None:
        return code
    if printed == 0 or (limit is not None and printed < limit):
        warn(f"{printed} of {limit if limit is not None else 'any'} transform(s) from "
             f"{source!r} to {target!r} received from {src.label}")
        return 1
    return 0
