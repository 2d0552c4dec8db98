"""The tutorial's "next step": the robot state publisher does all the tf publishing.

    python demos/robot_state.py --duration 10 [--backend trio]

``demos/robot.urdf`` describes the tutorial's robot once (base_link; base_laser 10 cm
forward and 20 cm up on a fixed joint; two continuous wheels). Three tasks share one
in-process bus:

* robot_state_publisher (:class:`tfbus.robot.RobotStatePublisher`) publishes the
  fixed laser mount once on the latched /tf_static and the wheels on /tf from
* a joint-state source turning the wheels (:func:`tfbus.robot.publish_joint_states`,
  10 Hz), in place of the tutorial's hand-written 100 Hz broadcaster;
* the tutorial's listener, unchanged (:func:`tfbus.demos.tutorial.listener_node`), which keeps
  printing once a second::

    [ INFO] ...: base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20) at time 0.00

  ("at time 0.00": the laser mount is now a static transform, which has no time).

Ctrl-C / SIGTERM exit cleanly; the last line is the robot state publisher's summary.
"""

from __future__ import annotations

import functools
import signal
from collections.abc import Callable
from pathlib import Path

import anyio
import click

from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import Clock, SystemClock
from tfbus.demos.tutorial import listener_node
from tfbus.listener import TransformListener
from tfbus.robot import RobotStatePublisher, RobotStateStatistics, publish_joint_states

ROBOT_URDF = Path(__file__).with_name("robot.urdf")


async def run_robot_state_demo(
    *,
    clock: Clock | None = None,
    duration: float | None = None,
    out: Callable[[str], None] = print,
    handle_signals: bool = False,
    urdf: Path = ROBOT_URDF,
) -> RobotStateStatistics:
    """Run the three tasks for ``duration`` seconds of ``clock`` time (None: until
    cancelled, or SIGINT/SIGTERM when ``handle_signals``); print the listener's lines and
    the publisher's summary through ``out``; return the publisher's statistics.

    Raises:
        tfbus.robot.URDFError: if ``urdf`` is not a usable robot description.
    """
    clock = clock if clock is not None else SystemClock()
    rsp = RobotStatePublisher(urdf)
    buffer = Buffer(cache_time=10.0, clock=clock)
    try:
        async with (
            Bus() as bus,
            TransformListener(buffer, bus, clock=clock),
            anyio.create_task_group() as tg,
        ):
            if handle_signals:
                tg.start_soon(_cancel_on_signal, tg.cancel_scope)
            await tg.start(functools.partial(rsp.run, bus, clock=clock))
            await tg.start(functools.partial(publish_joint_states, bus, rsp.model, rate=10.0,
                                             clock=clock))
            tg.start_soon(listener_node, buffer, clock, 1.0, out)
            if duration is not None:
                await clock.sleep(duration)
                tg.cancel_scope.cancel()
    finally:
        buffer.close()
        s = rsp.statistics()
        out(f"[ INFO] summary: robot_state_publisher published {s.transforms} wheel "
            f"transforms from {s.received} joint states")
    return rsp.statistics()


async def _cancel_on_signal(scope: anyio.CancelScope) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            scope.cancel()
            return


@click.command(help=__doc__.split("\n")[0] if __doc__ else None)
@click.option("--duration", type=click.FloatRange(min=0), default=None,
              help="Seconds to run (default: until Ctrl-C).")
@click.option("--backend", type=click.Choice(["asyncio", "trio"]), default="asyncio",
              show_default=True, help="Event loop.")
def main(duration: float | None, backend: str) -> None:
    """Run the demo from the command line (exit status 130 after a Ctrl-C that came
    before the signal handler; bad options are click's one usage error, status 2)."""

    def line(text: str) -> None:
        print(text, flush=True)

    try:
        anyio.run(functools.partial(run_robot_state_demo, duration=duration, out=line,
                                    handle_signals=True), backend=backend)
    except KeyboardInterrupt:  # before the signal handler was installed
        click.get_current_context().exit(130)


if __name__ == "__main__":
    main()
