"""``tfbus demo``: the seed demo and the tutorial's two nodes. The options are
parsed here, once; :mod:`tfbus.demos.tutorial` holds the nodes and runners."""

from __future__ import annotations

import importlib
import math
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

from tfbus.cli._bus_spec import check_bus_spec
from tfbus.cli._common import (
    anyio_run_args,
    error,
    fail,
    hertz,
    interrupted,
    literal,
    seconds,
    use_sim_time_option,
)
from tfbus.cli._live_session import cancel_on_signal, is_bus_error, run_live
from tfbus.transports.spec import BUS_HELP

__all__ = ["command", "node_label"]

F = TypeVar("F", bound=Callable[..., Any])



def _demo_options(*, rate: bool, listen_rate: bool) -> Callable[[F], F]:
    """The options of ``tfbus demo`` and its roles (all default to None: demo's own)."""

    def decorate(f: F) -> F:
        f = click.option("--backend", type=click.Choice(["asyncio", "trio", "uvloop"]),
                         default=None,
                         help="Event loop (default asyncio; uvloop: asyncio on uvloop's "
                              "loop).")(f)
        if listen_rate:
            f = click.option("--listen-rate", type=hertz(),
                             default=None, help="Listener rate, Hz (default 1).")(f)
        if rate:
            f = click.option("--rate", type=hertz(),
                             default=None, help="Broadcast rate, Hz (default 100).")(f)
        return click.option("--duration", type=seconds(zero=True), default=None,
                            help="Seconds to run (default: until Ctrl-C).")(f)

    return decorate


def _inherit(ctx: click.Context, **options: Any) -> dict[str, Any]:
    """A role's options, falling back to those given to ``tfbus demo`` before the role."""
    parent = ctx.parent.params if ctx.parent is not None else {}
    return {k: v if v is not None else parent.get(k) for k, v in options.items()}


def _backend(name: str | None) -> str:
    backend = name or "asyncio"
    if backend in ("trio", "uvloop"):
        try:
            importlib.import_module(backend)
        except ImportError:
            fail(f"--backend {backend} needs the '{backend}' package: pip install {backend}")
    return backend


def _print_line(line: str) -> None:
    print(literal(line), flush=True)


def run_both(*, duration: float | None, rate: float, listen_rate: float, backend: str) -> int:
    """Both nodes in this process on an in-process bus, until ``duration`` or a signal."""
    import anyio

    from tfbus.demos.tutorial import run_demo

    try:
        anyio.run(
            lambda: run_demo(duration=duration, rate=rate, listen_rate=listen_rate,
                             handle_signals=True, out=_print_line),
            **anyio_run_args(backend),
        )
    except BaseException as err:
        if not interrupted(err):
            raise
        return 130  # Ctrl-C, maybe grouped by a task group
    return 0


def node_label(transport: object, default: str) -> tuple[str, str]:
    """(name, id) of the node a transport makes, for the "running the ... node" line:
    the name is never empty (the transport's ``name`` or ROS 1 ``node_name``, else
    ``default``); the id is Zenoh's node id, the ROS 1 caller id or the ROS 2 domain,
    ``""`` when the transport has none."""
    from tfbus.transports._base import NodeLabelled

    name, ident = transport.node_label() if isinstance(transport, NodeLabelled) else ("", "")
    return name or default, ident


def run_role(role: str, spec: str, *, duration: float | None, rate: float,
             listen_rate: float, backend: str, use_sim_time: bool = False) -> int:
    """One node (``broadcaster`` or ``listener``) on the bus ``spec`` over Zenoh.

    ``use_sim_time``: the node's clock is a :class:`~tfbus.clock.SimClock` on the bus
    (stamps, the listener's period and lookups follow ``/clock``; ``duration`` stays
    seconds of wall time)."""
    import anyio

    from tfbus.bus import Bus
    from tfbus.cli._bus_spec import open_spec_transport
    from tfbus.clock import Clock, SimClock
    from tfbus.demos.tutorial import BROADCASTER_NAME, LISTENER_NAME, run_broadcaster, run_listener
    from tfbus.transports import spec as bus_spec

    name = BROADCASTER_NAME if role == "broadcaster" else LISTENER_NAME
    try:
        bus = Bus(transport=open_spec_transport(bus_spec.parse_bus_spec(spec), name=name,
                                                use_sim_time=use_sim_time))
    except ValueError as err:
        fail(str(err))
    except Exception as err:
        if not is_bus_error(err):
            raise
        raise click.ClickException(f"cannot configure the bus {spec!r}: {err}") from None

    async def run_node(clock: Clock | None, node_duration: float | None) -> None:
        if role == "broadcaster":
            await run_broadcaster(bus, clock=clock, duration=node_duration, rate=rate,
                                  out=_print_line, handle_signals=True)
        else:
            await run_listener(bus, clock=clock, duration=node_duration,
                               listen_rate=listen_rate, out=_print_line, handle_signals=True)

    async def main() -> None:
        async with bus:
            shown, node = node_label(bus.transport, name)
            print(f"[ INFO] {literal(shown)}: running the {role} node on {literal(spec)}"
                  + (f" (node {literal(node)})" if node else "")
                  + (" on simulated time (/clock)" if use_sim_time else ""),
                  file=sys.stderr, flush=True)
            if not use_sim_time:
                await run_node(None, duration)
                return
            # simulated time: the node's clock follows /clock; --duration stays wall time
            async with SimClock(bus) as clock:
                with anyio.move_on_after(math.inf if duration is None else duration):
                    await run_node(clock, None)

    code = run_live(main, backend=backend)
    return code if code is not None else 0


@click.group("demo", invoke_without_command=True)
@_demo_options(rate=True, listen_rate=True)
@click.pass_context
def command(
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
      tfbus demo laser --duration 10       # a simulated laser projected three ways
    """
    if ctx.invoked_subcommand is not None:
        return 0
    return run_both(duration=duration, rate=rate or 100.0, listen_rate=listen_rate or 1.0,
                    backend=_backend(backend))


@command.command("broadcaster")
@click.option("--bus", metavar="SPEC", default=None, help=BUS_HELP)
@_demo_options(rate=True, listen_rate=False)
@use_sim_time_option
@click.pass_context
def broadcaster(
    ctx: click.Context, bus: str | None, duration: float | None, rate: float | None,
    backend: str | None, use_sim_time: bool,
) -> int:
    """The tutorial's robot_tf_publisher alone: base_link -> base_laser over Zenoh.

    It prints nothing but its summary line on exit (a startup note goes to stderr).

    \b
    Examples:
      tfbus demo broadcaster
      tfbus demo broadcaster --rate 50 --duration 30
      tfbus demo broadcaster --bus 'zenoh?listen=tcp/127.0.0.1:7500'
    """
    check_bus_spec(bus)
    o = _inherit(ctx, duration=duration, rate=rate, backend=backend)
    return run_role("broadcaster", bus or "zenoh", duration=o["duration"],
                    rate=o["rate"] or 100.0, listen_rate=1.0, backend=_backend(o["backend"]),
                    use_sim_time=use_sim_time)


@command.command("listener")
@click.option("--bus", metavar="SPEC", default=None, help=BUS_HELP)
@_demo_options(rate=False, listen_rate=True)
@use_sim_time_option
@click.pass_context
def listener(
    ctx: click.Context, bus: str | None, duration: float | None, listen_rate: float | None,
    backend: str | None, use_sim_time: bool,
) -> int:
    """The tutorial's robot_tf_listener alone, over Zenoh: the tutorial's line each second.

    \b
    Examples:
      tfbus demo listener
      tfbus demo listener --listen-rate 2 --duration 10
      tfbus demo listener --bus 'zenoh?connect=tcp/127.0.0.1:7500'
      tfbus demo listener --use-sim-time     # one line per second of /clock time
    """
    check_bus_spec(bus)
    o = _inherit(ctx, duration=duration, listen_rate=listen_rate, backend=backend)
    return run_role("listener", bus or "zenoh", duration=o["duration"], rate=100.0,
                    listen_rate=o["listen_rate"] or 1.0, backend=_backend(o["backend"]),
                    use_sim_time=use_sim_time)


def run_laser(*, duration: float | None, backend: str, beams: int, scan_rate: float,
              odom_rate: float) -> int:
    """The laser demo (:func:`tfbus.demos.laser.run_laser_demo`) on an in-process bus,
    until ``duration`` or a signal; its summary line is printed either way."""
    import anyio

    try:  # imported by name: the module may be absent from an installation
        run_laser_demo = importlib.import_module("tfbus.demos.laser").run_laser_demo
    except ModuleNotFoundError as err:
        if err.name != "tfbus.demos.laser":
            raise
        error("the laser demo (tfbus.demos.laser) is not part of this installation")
        return 1

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            await tg.start(cancel_on_signal, tg.cancel_scope)
            await run_laser_demo(duration, out=_print_line, beams=beams,
                                 scan_rate=scan_rate, odom_rate=odom_rate)
            tg.cancel_scope.cancel()

    try:
        anyio.run(main, **anyio_run_args(backend))
    except BaseException as err:
        if not interrupted(err):
            raise
        return 130  # Ctrl-C, maybe grouped by a task group
    return 0


@command.command("laser")
@_demo_options(rate=False, listen_rate=False)
@click.option("--beams", type=click.IntRange(2, 100_000), default=720, show_default=True,
              help="Beams per sweep (one full turn).")
@click.option("--scan-rate", type=hertz(), default=40.0,
              show_default=True, help="Laser sweeps per second, Hz.")
@click.option("--odom-rate", type=hertz(), default=50.0,
              show_default=True, help="odom -> base_link transforms per second, Hz.")
@click.pass_context
def laser(
    ctx: click.Context, duration: float | None, backend: str | None, beams: int,
    scan_rate: float, odom_rate: float,
) -> int:
    """The tutorial's robot with a simulated laser: scans projected into odom three ways.

    The robot drives a 2 m circle in a 10 m square room; a 40 Hz, 720-beam laser sweeps
    while it moves. Each scan waits for odometry (a MessageFilter), then is projected
    with one transform at its stamp, with laser_geometry's start/end interpolation and
    beam by beam. Each second a line gives the distance of the projected points from
    the walls per method; a summary line at the end (tfbus.demos.laser).

    \b
    Examples:
      tfbus demo laser --duration 10
      tfbus demo laser --beams 360 --scan-rate 10 --backend trio
    """
    o = _inherit(ctx, duration=duration, backend=backend)
    if o["duration"] is not None and o["duration"] <= 0:
        fail(f"--duration must be above 0 for the laser demo, got {o['duration']:g}")
    return run_laser(duration=o["duration"], backend=_backend(o["backend"]), beams=beams,
                     scan_rate=scan_rate, odom_rate=odom_rate)
