"""``tfbus replay``: rosbag play for /tf and /tf_static, with a progress bar."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from tfbus.cli._bag_source import check_bag
from tfbus.cli._bus_spec import publish_bus, publish_options
from tfbus.cli._common import (
    MAX_HZ,
    MAX_SECONDS,
    TIME,
    FiniteFloat,
    bag_path,
    console,
    fail,
    fmt_sec,
    literal,
    one_line,
    warn,
)
from tfbus.cli._live_session import cancel_on_signal, run_live
from tfbus.time import NSEC_PER_SEC, Time
from tfbus.topics import DEFAULT_CLOCK_HZ, MAX_CLOCK_HZ

if TYPE_CHECKING:
    from tfbus.bag import ReplayControl

__all__ = ["command"]

PAUSE_KEY = b" "
"""The key that pauses and resumes a replay whose standard input is a terminal (rosbag
play's and ros2 bag play's space)."""


@click.command("replay")
@click.argument("path", type=bag_path())
@click.option("--rate", "-r", type=FiniteFloat(min=0, max=MAX_HZ), default=1.0, show_default=True,
              help="Speed factor (2 = twice as fast); 0 = as fast as possible.")
@click.option("--start", type=TIME, default=None, help="Start at this bag time (seconds).")
@click.option("--stop", type=TIME, default=None, help="Stop before this bag time.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@click.option("--clock", "clock_hz", type=FiniteFloat(min=0, min_open=True, max=MAX_CLOCK_HZ),
              is_flag=False, flag_value=DEFAULT_CLOCK_HZ, default=None, metavar="[HZ]",
              help="Publish bag time on /clock (rosgraph_msgs/Clock) at HZ per second "
                   f"(default {DEFAULT_CLOCK_HZ:g}, rosbag play --clock's --hz), for nodes "
                   "with use_sim_time ('--use-sim-time' of the other commands).")
@click.option("--pause", "start_paused", is_flag=True,
              help="Start paused (rosbag play --pause); the space key resumes.")
@publish_options
def command(path: Path, rate: float, start: Time | None, stop: Time | None, quiet: bool,
            clock_hz: float | None, start_paused: bool, bus: str | None, local: bool) -> int:
    """Publish a bag's /tf and /tf_static on the bus at recorded timing.

    It publishes on --bus (default 'zenoh', where 'tfbus echo --bus zenoh' and every
    other process see it). A ManualClock follows bag time, so anything awaiting on the
    bus sees the recording's time. Statics recorded before --start are published first
    (latched). Ctrl-C or SIGTERM stop it (exit status 130). With --clock it also
    publishes bag time on /clock, as 'rosbag play --clock' does (never past the next
    message's time; a ROS 1 bus gets rosgraph_msgs/Clock from this node), so 'tfbus
    demo listener --use-sim-time' and ROS nodes with use_sim_time follow the recording.
    When standard input is a terminal, the space key pauses and resumes the replay, as
    in 'rosbag play': while paused nothing is published and /clock repeats the paused
    time (rosbag's behaviour); --pause starts paused.

    \b
    Examples:
      tfbus replay turtle.bag
      tfbus replay nav2.mcap --rate 4
      tfbus replay turtle.bag --rate 0 --start 1396293900
      tfbus replay turtle.bag --bus 'zenoh?listen=tcp/127.0.0.1:7500'
      tfbus replay turtle.bag --clock --bus ros1     # drives /use_sim_time nodes
      tfbus replay turtle.bag --clock 40             # ros2 bag play --clock's rate
      tfbus replay turtle.bag --clock --pause        # space starts it
    """
    from tfbus.bag import BagReadError, read_messages

    check_bag(path)
    if start_paused and _keys_fd() is None:
        raise click.BadParameter("needs a terminal on standard input, in the foreground "
                                 "(the space key resumes)", param_hint="'--pause'")
    open_bus = publish_bus(bus, local, name="tfbus-replay")
    n_total = 0
    first = last = None
    try:
        for rec in read_messages(path):
            n_total += 1
            first = rec.time.ns if first is None else min(first, rec.time.ns)
            last = rec.time.ns if last is None else max(last, rec.time.ns)
    except BagReadError:
        pass
    if rate and first is not None and last is not None:
        span = (last - first) / NSEC_PER_SEC
        if span / rate > MAX_SECONDS:
            fail(f"--rate {rate:g}: replaying {span:.3f} s of bag time would take "
                 f"{span / rate:.3g} s, more than {MAX_SECONDS:g} s")
    result: list[int] = []
    problem: list[BagReadError] = []
    code = run_live(lambda: _replay(open_bus, path, rate, start, stop, quiet, n_total,
                                    result, problem, clock_hz, start_paused))
    n = result[0] if result else 0
    if problem:
        click.echo(f"replayed {problem[0].messages_read} messages from {literal(path)}")
        warn(one_line(str(problem[0])))
        return 1
    if code is not None:
        return code
    if len(result) < 2:  # interrupted
        click.echo(f"replayed {n} messages from {literal(path)} (interrupted)")
        return 130
    click.echo(f"replayed {n} messages from {literal(path)}")
    return 0


async def _replay(
    open_bus: Callable[[], object], path: Path, rate: float, start: Time | None,
    stop: Time | None, quiet: bool, total: int, result: list[int],
    problem: list[Any], clock_hz: float | None = None, start_paused: bool = False,
) -> None:
    import anyio
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    from tfbus.bag import BagMessage, BagReadError, ReplayControl, replay
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock

    clock = ManualClock()
    control = ReplayControl(paused=start_paused)
    progress = Progress(
        TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
        TimeElapsedColumn(), console=console(err=True), disable=quiet, transient=False,
    )
    result.append(0)
    bus = open_bus()
    assert isinstance(bus, Bus)
    with progress:
        task = progress.add_task(f"replay {literal(path.name)}", total=total or None)

        def advance(rec: BagMessage) -> None:
            result[0] += 1
            progress.update(task, advance=1, description=f"bag time {fmt_sec(rec.time.ns)}")

        def say(line: str) -> None:
            progress.console.print(line, markup=False, highlight=False)

        async with bus, anyio.create_task_group() as tg:
            await tg.start(cancel_on_signal, tg.cancel_scope)
            if not quiet:
                say(f"replaying {literal(path)} ...")
            keys = _keys_fd()
            if keys is not None:
                tg.start_soon(_pause_on_key, keys, control, clock, say)
            if control.paused:
                say("[PAUSED]  press space to resume")
            try:
                result[0] = await replay(
                    path, bus, clock=clock, rate=rate or None, start=start, stop=stop,
                    on_message=advance, publish_clock=clock_hz, control=control,
                )
                result.append(1)  # finished
            except BagReadError as err:
                problem.append(err)  # reported outside the bus's task group
            tg.cancel_scope.cancel()


def _keys_fd() -> int | None:
    """Standard input's descriptor when it is a terminal this platform can put in
    cbreak mode and this process is not a background job of it, else None (no pause
    key: a pipe, a file, ``tfbus replay ... &``, Windows)."""
    try:
        import termios  # noqa: F401
    except ImportError:
        return None
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, OSError, ValueError):
        return None
    if not os.isatty(fd):
        return None
    try:
        if os.tcgetpgrp(fd) != os.getpgrp():  # a background job ('&'): setting the
            return None  # terminal would stop it (SIGTTOU)
    except OSError:  # not this process's controlling terminal: no job control on it
        pass
    return fd


@contextlib.contextmanager
def _cbreak(fd: int) -> Iterator[None]:
    """The terminal ``fd`` without line buffering and echo (a key arrives as it is
    pressed, as rosbag's ``Player::setupTerminal`` sets it), restored on the way out."""
    import termios
    import tty

    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd, termios.TCSANOW)
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


async def _pause_on_key(
    fd: int, control: ReplayControl, clock: Any, say: Callable[[str], None]
) -> None:
    """Toggle ``control`` at each space key read from the terminal ``fd`` (other keys
    are ignored), saying the bag time it paused or resumed at; until cancelled or the
    terminal closes."""
    import anyio

    with _cbreak(fd):
        while True:
            await anyio.wait_readable(fd)
            try:
                keys = os.read(fd, 64)
            except BlockingIOError:
                continue
            except OSError:  # the terminal went away
                return
            if not keys:
                return
            for _ in range(keys.count(PAUSE_KEY)):
                paused = control.toggle()
                state = "[PAUSED] " if paused else "[RUNNING]"
                say(f"{state} bag time {fmt_sec(clock.now().ns)}")
