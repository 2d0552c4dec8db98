"""``tfbus robot-state-publisher``: ROS's robot_state_publisher.

Fixed joints once on the latched /tf_static, moving joints on /tf from the JointStates on
/joint_states (:class:`tfbus.robot.RobotStatePublisher`), until Ctrl-C or SIGTERM
(or ``--duration``), then one summary line.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING

import click

from tfbus.cli._bus_spec import publish_bus, publish_options
from tfbus.cli._common import hertz, literal, seconds, use_sim_time_option
from tfbus.cli._robot import bus_label, duration_option, load_model, model_argument, serve

if TYPE_CHECKING:
    import anyio.abc

    from tfbus.bus import Bus
    from tfbus.clock import Clock

__all__ = ["command"]


@click.command("robot-state-publisher")
@model_argument
@publish_options
@click.option("--publish-frequency", type=hertz(),
              default=20.0, show_default=True,
              help="Most /tf updates per joint per second of joint-state stamps (ROS's "
                   "publish_frequency; below 1 Hz counts as 1).")
@click.option("--max-stamp-ahead", type=seconds(zero=True), default=None, metavar="S",
              help="Drop a JointState stamped more than S seconds ahead of the clock "
                   "(default: none, as ROS, where one such message holds back every later "
                   "one until the clock reaches its stamp).")
@click.option("--frame-prefix", default="", metavar="P",
              help="Prepended to every link name in frame ids (ROS 2's frame_prefix).")
@duration_option
@use_sim_time_option
def command(model: Path, bus: str | None, local: bool, publish_frequency: float,
            max_stamp_ahead: float | None, frame_prefix: str, duration: float | None,
            use_sim_time: bool) -> int:
    """Publish a robot's links on /tf and /tf_static from its URDF and /joint_states,
    like ROS's robot_state_publisher.

    It runs on --bus (default 'zenoh', where 'tfbus joint-states' and 'tfbus echo --bus
    zenoh' in other terminals meet it) until Ctrl-C or SIGTERM, then prints a summary.
    The 'ros1' and 'ros2' buses carry /tf and /tf_static only, not /joint_states.

    \b
    Examples:
      tfbus robot-state-publisher demos/robot.urdf
      tfbus joint-states demos/robot.urdf                   # another terminal
      tfbus echo base_link left_wheel --bus zenoh           # a third one
      tfbus robot-state-publisher pr2.urdf --frame-prefix pr2/ --bus 'zenoh:tcp/10.0.0.2:7448'
    """
    from tfbus.robot import RobotStatePublisher

    rsp = RobotStatePublisher(load_model(model), frame_prefix=frame_prefix)
    open_bus = publish_bus(bus, local, name="robot_state_publisher", use_sim_time=use_sim_time)
    moving = sum(j.movable for j in rsp.model.joints)

    async def start(b: Bus, tg: anyio.abc.TaskGroup, clock: Clock | None) -> None:
        await tg.start(functools.partial(rsp.run, b, publish_frequency=publish_frequency,
                                         max_stamp_ahead=max_stamp_ahead, clock=clock))
        click.echo(f"[ INFO] robot_state_publisher: {literal(rsp.model.name)}: "
                   f"{len(rsp.model.joints)} joints ({moving} moving), root "
                   f"{literal(rsp.model.root)}, on {bus_label(bus, local)}", err=True)

    def finish(b: Bus) -> None:
        s = rsp.statistics()
        click.echo(f"[ INFO] summary: {s.received} joint states received, {s.published} "
                   f"published ({s.transforms} transforms), {s.rate_limited} rate-limited, "
                   f"{s.invalid} invalid, {s.refused_positions} positions refused"
                   + (f", {s.ahead} stamped too far ahead" if max_stamp_ahead is not None
                      else ""))

    return serve(open_bus, duration, start, finish, use_sim_time=use_sim_time)
