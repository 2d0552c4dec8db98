"""``tfbus joint-states``: joint_state_publisher without a GUI, animated.

Every movable joint swings sinusoidally within its limits
(:func:`tfbus.robot.publish_joint_states`), until Ctrl-C or SIGTERM (or
``--duration``), then one summary line.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bus_spec import publish_bus, publish_options
from tfbus.cli._common import hertz, literal, use_sim_time_option
from tfbus.cli._robot import bus_label, duration_option, load_model, model_argument, serve
from tfbus.topics import JOINT_STATES_TOPIC

if TYPE_CHECKING:
    import anyio.abc

    from tfbus.bus import Bus
    from tfbus.clock import Clock

__all__ = ["command"]


@click.command("joint-states")
@model_argument
@publish_options
@click.option("--rate", type=hertz(), default=10.0,
              show_default=True, help="JointState messages per second.")
@duration_option
@use_sim_time_option
def command(model: Path, bus: str | None, local: bool, rate: float,
            duration: float | None, use_sim_time: bool) -> int:
    """Publish JointStates on /joint_states moving every movable joint sinusoidally within
    its limits (joint_state_publisher without a GUI, animated; mimic joints are left to
    robot_state_publisher).

    It publishes on --bus (default 'zenoh', where 'tfbus robot-state-publisher' in
    another terminal hears it) until Ctrl-C or SIGTERM, then prints a summary.
    The 'ros1' and 'ros2' buses carry /tf and /tf_static only, not /joint_states.

    \b
    Examples:
      tfbus joint-states demos/robot.urdf
      tfbus joint-states pr2.urdf --rate 50 --bus 'zenoh?connect=tcp/127.0.0.1:7500'
    """
    from tfbus.robot import publish_joint_states

    robot = load_model(model)
    open_bus = publish_bus(bus, local, name="joint_state_publisher", use_sim_time=use_sim_time)

    async def start(b: Bus, tg: anyio.abc.TaskGroup, clock: Clock | None) -> None:
        await tg.start(functools.partial(publish_joint_states, b, robot, rate=rate,
                                         clock=clock))
        click.echo(f"[ INFO] joint_state_publisher: {literal(robot.name)}: "
                   f"{sum(j.movable and j.mimic is None for j in robot.joints)} joints at "
                   f"{rate:g} Hz on {bus_label(bus, local)}", err=True)

    def finish(b: Bus) -> None:
        published = b.statistics().get(JOINT_STATES_TOPIC)
        click.echo(f"[ INFO] summary: {published.published if published else 0} "
                   f"joint states published")

    return serve(open_bus, duration, start, finish, use_sim_time=use_sim_time)
