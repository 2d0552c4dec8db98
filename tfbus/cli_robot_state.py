"""``tfbus robot-state-publisher`` and ``tfbus joint-states`` (layer 5).

::

    tfbus robot-state-publisher MODEL.urdf [--bus SPEC] [--publish-frequency HZ] [--frame-prefix P]
    tfbus joint-states MODEL.urdf [--bus SPEC] [--rate HZ]

The first is ROS's robot_state_publisher (:class:`tfbus.robot_state.RobotStatePublisher`):
fixed joints once on the latched /tf_static, moving joints on /tf from the JointStates on
/joint_states. The second is joint_state_publisher without a GUI, animated: every movable
joint swings sinusoidally within its limits (:func:`tfbus.robot_state.sinusoidal_joint_state`).
Both run until Ctrl-C or SIGTERM (or ``--duration``), then print one summary line. A bad
URDF or option prints one line, ``tfbus <command>: error: ...``, exit status 2; a bus that
cannot be opened, exit status 1.

The commands are ``click.Command`` objects (:data:`robot_state_publisher_cmd`,
:data:`joint_states_cmd`) for the ``tfbus`` group; ``python -m tfbus.cli_robot_state
COMMAND ...`` runs them alone.
"""

from __future__ import annotations

import functools
import signal
import sys
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    import anyio
    import anyio.abc

    from tfbus.bus import Bus
    from tfbus.robot_state import RobotStatePublisher
    from tfbus.urdf import RobotModel

__all__ = ["joint_states_cmd", "main", "open_bus", "robot_state_publisher_cmd"]

_BUS_HELP = ("Bus to run on: 'zenoh' (this machine, no configuration), "
             "'zenoh?listen=tcp/127.0.0.1:7500', 'zenoh:tcp/192.168.1.10:7448' "
             "(default: an in-process bus).")


def _printable(text: str) -> str:
    """One line with control characters escaped: nothing from a file reaches the terminal raw."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in " ".join(text.split()))


def open_bus(spec: str | None, *, name: str) -> Bus:
    """A new (not yet opened) bus for ``--bus SPEC``: in-process when ``spec`` is None,
    else Zenoh (:func:`tfbus.transports.zenoh.parse_bus_spec`) with ``name`` as the node
    name unless the spec gives one. JointState is registered with the wire format.

    Raises:
        click.UsageError: if the Zenoh transport is missing or ``spec`` is invalid.
    """
    from tfbus.bus import Bus

    if spec is None:
        return Bus()
    try:
        from tfbus.messages import JointState
        from tfbus.transports.wire import register_message_type
        from tfbus.transports.zenoh import parse_bus_spec, zenoh_bus_from_options
    except ImportError as err:
        raise click.UsageError(
            f"--bus needs the Zenoh transport (pip install 'tfbus[zenoh]'): {err}") from None
    try:
        options = parse_bus_spec(spec)
    except ValueError as err:
        raise click.UsageError(_printable(str(err))) from None
    register_message_type(JointState)
    if options.name is None:
        return zenoh_bus_from_options(options, name=name)
    return zenoh_bus_from_options(options)


def _model(path: Path) -> RobotModel:
    from tfbus.urdf import URDFError, load_urdf

    try:
        return load_urdf(path)
    except URDFError as err:
        raise click.UsageError(f"{_printable(str(path))}: {_printable(str(err))}") from None
    except ImportError as err:
        raise click.UsageError(
            f"reading URDF needs urdfdom-py (pip install 'tfbus[robot]'): {err}") from None


async def _cancel_on_signal(scope: anyio.CancelScope) -> None:
    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            scope.cancel()
            return


async def _serve(bus: Bus, duration: float | None,
                 start: Callable[[Bus, anyio.abc.TaskGroup], Awaitable[None]]) -> None:
    """Open ``bus``, run ``start``'s tasks until SIGINT/SIGTERM or ``duration`` s."""
    import anyio

    async with bus, anyio.create_task_group() as tg:
        tg.start_soon(_cancel_on_signal, tg.cancel_scope)
        await start(bus, tg)
        if duration is not None:
            await anyio.sleep(duration)
            tg.cancel_scope.cancel()


def _run(main: Callable[[], Awaitable[None]]) -> int:
    """``anyio.run(main)``: 0 when it ran (or a Ctrl-C came before the handler), 1 with a
    one-line error when the bus could not be opened."""
    import anyio

    try:
        anyio.run(main)
    except KeyboardInterrupt:
        return 0
    except Exception as err:
        if not (isinstance(err, OSError) or type(err).__module__.partition(".")[0] == "zenoh"
                or type(err).__name__ == "TransportError"):
            raise
        ctx = click.get_current_context(silent=True)
        name = ctx.command_path if ctx is not None else "tfbus"
        click.echo(f"{name}: error: cannot open the bus: {_printable(str(err))}", err=True)
        return 1
    return 0


_duration = click.option("--duration", type=click.FloatRange(min=0), default=None,
                         help="Seconds to run (default: until Ctrl-C / SIGTERM).")
_urdf = click.argument("model", metavar="MODEL.urdf",
                       type=click.Path(dir_okay=False, path_type=Path))


@click.command("robot-state-publisher")
@_urdf
@click.option("--bus", metavar="SPEC", default=None, help=_BUS_HELP)
@click.option("--publish-frequency", type=click.FloatRange(min=0, min_open=True),
              default=20.0, show_default=True,
              help="Most /tf updates per joint per second of joint-state stamps (ROS's "
                   "publish_frequency; below 1 Hz counts as 1).")
@click.option("--frame-prefix", default="", metavar="P",
              help="Prepended to every link name in frame ids (ROS 2's frame_prefix).")
@_duration
def robot_state_publisher_cmd(model: Path, bus: str | None, publish_frequency: float,
                              frame_prefix: str, duration: float | None) -> int:
    """Publish a robot's links on /tf and /tf_static from its URDF and /joint_states,
    like ROS's robot_state_publisher.

    \b
    Examples:
      tfbus robot-state-publisher demos/robot.urdf --bus zenoh
      tfbus joint-states demos/robot.urdf --bus zenoh          # another terminal
      tfbus robot-state-publisher pr2.urdf --bus zenoh --frame-prefix pr2/
    """
    from tfbus.robot_state import RobotStatePublisher

    rsp = RobotStatePublisher(_model(model), frame_prefix=frame_prefix)
    the_bus = open_bus(bus, name="robot_state_publisher")
    moving = sum(j.movable for j in rsp.model.joints)

    async def start(b: Bus, tg: anyio.abc.TaskGroup) -> None:
        await tg.start(functools.partial(rsp.run, b, publish_frequency=publish_frequency))
        click.echo(f"[ INFO] robot_state_publisher: {_printable(rsp.model.name)}: "
                   f"{len(rsp.model.joints)} joints ({moving} moving), root "
                   f"{_printable(rsp.model.root)}, on {_printable(bus or 'an in-process bus')}",
                   err=True)

    code = _run(functools.partial(_serve, the_bus, duration, start))
    if code == 0:
        _summary(rsp)
    return code


def _summary(rsp: RobotStatePublisher) -> None:
    s = rsp.statistics
    click.echo(f"[ INFO] summary: {s.received} joint states received, {s.published} "
               f"published ({s.transforms} transforms), {s.rate_limited} rate-limited, "
               f"{s.invalid} invalid, {s.refused_positions} positions refused")


@click.command("joint-states")
@_urdf
@click.option("--bus", metavar="SPEC", default=None, help=_BUS_HELP)
@click.option("--rate", type=click.FloatRange(min=0, min_open=True), default=10.0,
              show_default=True, help="JointState messages per second.")
@_duration
def joint_states_cmd(model: Path, bus: str | None, rate: float, duration: float | None) -> int:
    """Publish JointStates on /joint_states moving every movable joint sinusoidally within
    its limits (joint_state_publisher without a GUI, animated; mimic joints are left to
    robot_state_publisher).

    \b
    Examples:
      tfbus joint-states demos/robot.urdf --bus zenoh
      tfbus joint-states pr2.urdf --bus 'zenoh?connect=tcp/127.0.0.1:7500' --rate 50
    """
    from tfbus.robot_state import publish_joint_states

    robot = _model(model)
    the_bus = open_bus(bus, name="joint_state_publisher")

    async def start(b: Bus, tg: anyio.abc.TaskGroup) -> None:
        await tg.start(functools.partial(publish_joint_states, b, robot, rate=rate))
        click.echo(f"[ INFO] joint_state_publisher: {_printable(robot.name)}: "
                   f"{sum(j.movable and j.mimic is None for j in robot.joints)} joints at "
                   f"{rate:g} Hz on {_printable(bus or 'an in-process bus')}", err=True)

    code = _run(functools.partial(_serve, the_bus, duration, start))
    if code == 0:
        published = the_bus.statistics().get("/joint_states")
        click.echo(f"[ INFO] summary: {published.published if published else 0} "
                   f"joint states published")
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tfbus.cli_robot_state COMMAND ...``; returns the exit status."""
    group = click.Group("tfbus", commands=[robot_state_publisher_cmd, joint_states_cmd],
                        context_settings={"help_option_names": ["-h", "--help"]})
    try:
        rv: Any = group.main(args=list(argv) if argv is not None else None, prog_name="tfbus",
                             standalone_mode=False)
    except click.ClickException as err:
        ctx = getattr(err, "ctx", None)
        name = ctx.command_path if ctx is not None else "tfbus"
        click.echo(f"{name}: error: {_printable(err.format_message())}", err=True)
        return err.exit_code
    except click.Abort:
        return 1
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":
    sys.exit(main())
