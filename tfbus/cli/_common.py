"""What every ``tfbus`` command shares: the group, one-line errors, literal printing of
ids, time arguments, and the exit paths."""

from __future__ import annotations

import logging
import math
import re
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

import click

from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from rich.console import Console

__all__ = [
    "HOST",
    "MAX_HZ",
    "MAX_SECONDS",
    "MISSING_EXTRA_STATUS",
    "TIME",
    "FiniteFloat",
    "bag_path",
    "cli",
    "console",
    "fail",
    "finish_status",
    "fmt_sec",
    "hertz",
    "literal",
    "missing_extra",
    "one_line",
    "parse_time",
    "seconds",
    "warn",
]

F = TypeVar("F", bound=Callable[..., Any])

# --------------------------------------------------------------------------- literal text

# C0 and C1 controls, DEL, and the Unicode line separators and bidirectional controls that
# reorder or hide text in a terminal.
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u200e\u200f\u202a-\u202e\u2066-\u2069]")


def _escape_char(match: re.Match[str]) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def literal(text: object) -> str:
    """``text`` as it must reach a terminal: every control character (ESC, BEL, CR, NUL,
    newline, ...) and bidirectional control written as a ``\\xNN`` / ``\\uNNNN`` escape,
    so a frame id or broadcaster name from a bag or a peer can neither move the cursor,
    set the window title nor clear the screen. The commands print with rich markup off,
    so ``[bold]`` or ``[/]`` in an id are printed as they are."""
    return _UNSAFE.sub(_escape_char, str(text))


def literal_lines(text: str) -> str:
    """Multi-line text (e.g. ``all_frames_as_string``) with each line made literal."""
    return "\n".join(literal(line) for line in text.split("\n"))


def one_line(text: str) -> str:
    """An error message on one line: whitespace runs collapsed, controls escaped."""
    return literal(" ".join(str(text).split()))


def console(err: bool = False) -> Console:
    """A rich console that never interprets markup or emoji codes in what it prints
    (ids are data, not markup). In a terminal, table cells holding ids wrap at its width
    (never cut off); pipes and files get the full width of every line instead."""
    from rich.console import Console

    out = Console(stderr=err, highlight=False, soft_wrap=True, markup=False, emoji=False)
    if not out.is_terminal:
        out.width = NON_TERMINAL_WIDTH
    return out


NON_TERMINAL_WIDTH = 100_000
"""Columns of a pipe or file: wide enough that no id is ever wrapped there."""


# --------------------------------------------------------------------------- errors


def fail(message: str) -> NoReturn:
    """A bad argument: one line and exit code 2."""
    raise click.UsageError(one_line(message), click.get_current_context(silent=True))


def command_path() -> str:
    """``tfbus CMD`` of the running command (``tfbus`` outside one)."""
    ctx = click.get_current_context(silent=True)
    return ctx.command_path if ctx is not None else "tfbus"


def warn(message: str) -> None:
    """A one-line warning on stderr."""
    click.echo(f"{command_path()}: warning: {one_line(message)}", err=True)


def error(message: str) -> None:
    """A one-line error on stderr (the caller returns the exit status)."""
    click.echo(f"{command_path()}: error: {one_line(message)}", err=True)


MISSING_EXTRA_STATUS = 2
"""The exit status of a command whose optional dependency is not installed: 2, the
status of a usage error (click's), after one line naming the extra to install."""

# Which extra brings which importable module, beyond tfbus._extras.EXTRAS.
_CLI_EXTRAS = {"click": "cli", "rich": "cli", "graphviz": "cli"}


def missing_extra(err: ImportError) -> str | None:
    """The one-line advice for an optional dependency that is not installed (a
    :class:`~tfbus.errors.MissingExtraError`, or an ImportError of a package an extra
    brings), or None when ``err`` is not about one."""
    from tfbus._extras import EXTRAS, MissingExtraError, extra_advice

    if isinstance(err, MissingExtraError):
        return str(err)
    name = (getattr(err, "name", None) or "").partition(".")[0]
    extra = _CLI_EXTRAS.get(name) or EXTRAS.get(name)
    if extra is None:
        return None
    return f"the '{name}' package is not installed: {extra_advice(name, extra)}"


class _Group(click.Group):
    """A click group whose usage errors are one line (``tfbus CMD: error: MESSAGE``),
    which turns a missing optional dependency into one line naming the extra (exit status
    :data:`MISSING_EXTRA_STATUS`), and which
    exits with 130 on Ctrl-C and SIGTERM (see :func:`tfbus.cli.main`) with no traceback."""

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.ClickException as err:
            ctx = getattr(err, "ctx", None)
            name = ctx.command_path if ctx is not None else "tfbus"
            click.echo(f"{name}: error: {one_line(err.format_message())}", err=True)
            if standalone_mode:
                sys.exit(err.exit_code)
            raise
        except click.Abort as err:
            if isinstance(err.__cause__, KeyboardInterrupt):  # Ctrl-C or SIGTERM
                rv = 130
            else:
                click.echo("Aborted.", err=True)
                if standalone_mode:
                    sys.exit(1)
                raise
        except KeyboardInterrupt:
            rv = 130
        except ImportError as err:
            advice = missing_extra(err)
            if advice is None:
                raise
            click.echo(f"tfbus: error: {one_line(advice)}", err=True)
            rv = MISSING_EXTRA_STATUS
        except BaseException as err:
            if not interrupted(err):
                raise
            rv = 130  # Ctrl-C raised inside a task group: grouped
        if standalone_mode:
            sys.exit(rv if isinstance(rv, int) else 0)
        return rv


def version() -> str:
    """tfbus's version: the installed distribution's (``importlib.metadata``, through
    :mod:`tfbus._version`), ``0+unknown`` for a source tree that is not installed."""
    from tfbus._version import __version__

    return __version__


def _print_version(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    from tfbus.core.kernels import core_description

    click.echo(f"tfbus {version()} ({core_description()})")
    ctx.exit()


@click.group("tfbus", cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--version", is_flag=True, expose_value=False, is_eager=True,
              callback=_print_version,
              help="Print 'tfbus <version> (<core>)', the core in use, and exit.")
def cli() -> None:
    """tfbus: ROS tf2's tools for plain Python (bags, echo, monitor, view_frames).

    \b
    Examples:
      tfbus bag-info turtle.bag
      tfbus echo world turtle1 --bag turtle.bag --time 1396293900
      tfbus frames --bag turtle.bag -o frames.pdf
    """


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def run_main(argv: Sequence[str] | None = None) -> int:
    """Run the group (``tfbus.cli.main``): SIGTERM is turned into the Ctrl-C path (live
    commands catch both themselves and end cleanly) and the exit status returned."""
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        rv = cli.main(args=list(argv) if argv is not None else None, prog_name="tfbus",
                      standalone_mode=False)
    except click.ClickException as err:
        return err.exit_code
    except click.Abort:
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    return rv if isinstance(rv, int) else 0


def anyio_run_args(loop: str) -> dict[str, Any]:
    """``anyio.run``'s keyword arguments for the event loop a command runs on: ``asyncio``
    (asyncio's own loop), ``trio``, or ``uvloop`` (anyio's asyncio backend on uvloop's
    loop, its ``use_uvloop`` option; the caller has checked that uvloop is installed)."""
    if loop == "uvloop":
        return {"backend": "asyncio", "backend_options": {"use_uvloop": True}}
    return {"backend": loop}


def interrupted(err: BaseException) -> bool:
    """Whether ``err`` is Ctrl-C: a ``KeyboardInterrupt``, or an exception group (trio
    and anyio task groups wrap what a task raised) holding nothing else."""
    if isinstance(err, KeyboardInterrupt):
        return True
    inner = getattr(err, "exceptions", None)
    return isinstance(inner, tuple) and bool(inner) and all(interrupted(e) for e in inner)


class SafeLogFormatter(logging.Formatter):
    """Log records (e.g. the listener's warnings about a peer's bad transform) with
    control characters escaped, so a peer's frame id cannot reach the terminal raw."""

    def format(self, record: logging.LogRecord) -> str:
        """The record, formatted and made literal line by line."""
        return literal_lines(super().format(record))


# --------------------------------------------------------------------------- arguments


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
        except (ValueError, OverflowError):
            self.fail(f"{value!r} is not a time (seconds, e.g. 1396293909.5, or 'latest')")


TIME = _TimeParam()


MAX_SECONDS = 1e9
"""The longest duration, interval, timeout or cache time an option takes, seconds
(about 31.7 years; leave a ``--duration`` out to run until Ctrl-C). Beyond it a value
is a usage error: ``1e300`` seconds is no longer a time anyone waits, and it overflows
the int64 nanoseconds tf2 keeps times in (ROS 2 ``rcl_duration_value_t``)."""

MAX_HZ = 1e6
"""The highest rate an option takes, Hz (a period of 1 microsecond). The lowest is
``1 / MAX_SECONDS``: the period of every rate is a duration an option could take."""


class FiniteFloat(click.FloatRange):
    """A float option that must be a finite number within ``[min, max]``
    (:class:`click.FloatRange`, which lets ``nan`` through every bound and ``inf``
    through a missing one). A bad value is click's usage error naming the option and
    the value (exit status 2)."""

    name = "float"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        """``value`` as a float, or a usage error: not a number, not finite, out of range."""
        if isinstance(value, str) and not value.strip():
            self.fail("an empty value is not a number", param, ctx)
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number (range {self._describe_range()})",
                      param, ctx)
        return rv

    def _describe_range(self) -> str:
        return super()._describe_range().replace("1000000000.0", "1e9").replace(
            "1000000.0", "1e6").replace("1e-09", "1e-9")


def seconds(*, zero: bool = False) -> FiniteFloat:
    """A ``--duration`` / ``--interval`` / ``--cache-time`` type: finite seconds in
    ``(0, MAX_SECONDS]`` (``[0, MAX_SECONDS]`` with ``zero``)."""
    return FiniteFloat(min=0.0, max=MAX_SECONDS, min_open=not zero)


def hertz() -> FiniteFloat:
    """A rate option type: finite Hz in ``[1 / MAX_SECONDS, MAX_HZ]``."""
    return FiniteFloat(min=1.0 / MAX_SECONDS, max=MAX_HZ)


class _HostParam(click.ParamType):  # type: ignore[type-arg,unused-ignore]
    """An address to serve on: a host name or IP address this machine can resolve
    (``getaddrinfo``), never empty. A server given one it cannot bind would otherwise
    fail in its own thread, after the command said it serves."""

    name = "HOST"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> str:
        """``value`` unchanged, or a usage error: empty, or not resolvable."""
        import socket

        text = str(value)
        if not text.strip():
            self.fail("give an address, e.g. 127.0.0.1 (this machine) or 0.0.0.0 (every "
                      "interface)", param, ctx)
        try:
            socket.getaddrinfo(text, None, type=socket.SOCK_STREAM)
        except (OSError, UnicodeError, ValueError) as err:
            self.fail(f"{text!r} is not an address of this machine's resolver: {err}",
                      param, ctx)
        return text


HOST = _HostParam()
"""The type of a ``--host`` option (an address to serve on)."""


def bag_path() -> click.Path:
    """A ``PATH`` argument that must exist (file or bag folder)."""
    return click.Path(exists=True, dir_okay=True, file_okay=True, path_type=Path)


def fmt_sec(ns: int | None) -> str:
    """``SEC.NANOSEC`` (nine digits), ``-`` for None."""
    if ns is None:
        return "-"
    return f"{ns // NSEC_PER_SEC}.{ns % NSEC_PER_SEC:09d}"


def finish_status(problem: str | None) -> int:
    """1 after a one-line warning when the data was incomplete, else 0."""
    if problem:
        warn(problem)
        return 1
    return 0


RATE_HELP = (
    "Rate of a frame: (distinct header stamps - 1) / (newest - oldest stamp), in Hz; a "
    "repeated stamp counts once (tf2 keeps it once). The same definition in frames, "
    "monitor and bag-info."
)
"""The ``--help`` epilogue of frames, monitor and bag-info: the rate definition
(:func:`tfbus.monitor.link_rate`), the same in every tool."""


USE_SIM_TIME_HELP = (
    "Run on simulated time: the newest /clock (rosgraph_msgs/Clock) heard on the bus, "
    "zero until the first (ROS 2's use_sim_time parameter, ROS 1's /use_sim_time; "
    "tfbus.SimClock). Rates, lookups and delays follow it; --duration stays wall time."
)


def use_sim_time_option(f: F) -> F:
    """``--use-sim-time``: the command's clock is a :class:`~tfbus.clock.SimClock` on
    its bus (the ROS 2 parameter's name, ``rclpy/time_source.py``)."""
    return click.option("--use-sim-time", "use_sim_time", is_flag=True,
                        help=USE_SIM_TIME_HELP)(f)
