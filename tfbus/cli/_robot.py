"""What ``robot-state-publisher`` and ``joint-states`` share: the URDF argument, the
``--duration`` option, and running a node on the bus until a signal."""

from __future__ import annotations

import contextlib
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from tfbus.cli._common import fail, literal, seconds
from tfbus.cli._live_session import cancel_on_signal, run_live

if TYPE_CHECKING:
    import anyio.abc

    from tfbus.bus import Bus
    from tfbus.clock import Clock
    from tfbus.robot import RobotModel

__all__ = ["bus_label", "duration_option", "load_model", "model_argument", "serve"]

model_argument = click.argument("model", metavar="MODEL.urdf",
                                type=click.Path(dir_okay=False, path_type=Path))
"""``MODEL.urdf``: the robot description (read by :func:`load_model`)."""

duration_option = click.option("--duration", type=seconds(zero=True), default=None,
                               help="Seconds to run (default: until Ctrl-C / SIGTERM).")
"""``--duration S``: stop after ``S`` seconds of wall-clock time."""


def load_model(path: Path) -> RobotModel:
    """The URDF at ``path`` (:func:`tfbus.robot.load_urdf`), or a one-line usage error
    naming the file and the element at fault. Without urdfdom-py the ``ImportError``
    propagates: the ``tfbus`` group turns it into one line naming the ``robot`` extra."""
    from tfbus.robot import URDFError, load_urdf

    try:
        return load_urdf(path)
    except URDFError as err:
        fail(f"{path}: {err}")


def bus_label(bus: str | None, local: bool) -> str:
    """How the startup line names the bus (``publish_bus``'s choice, made literal)."""
    return "an in-process bus" if local else literal(bus if bus is not None else "zenoh")


def serve(
    open_bus: Callable[[], Any],
    duration: float | None,
    start: Callable[[Bus, anyio.abc.TaskGroup, Clock | None], Awaitable[None]],
    finish: Callable[[Bus], None],
    *,
    use_sim_time: bool = False,
) -> int:
    """Open the bus ``open_bus()`` makes, ``await start(bus, task_group, clock)`` (which
    starts the node's tasks on ``clock``: a :class:`~tfbus.clock.SimClock` on the bus
    with ``use_sim_time``, else None, the wall clock), and run until SIGINT/SIGTERM or
    ``duration`` seconds of wall time; then call ``finish(bus)`` (the summary line) and
    return 0. A bus that cannot be opened is a one-line error and status 1
    (:func:`~tfbus.cli._live_session.run_live`)."""
    opened: list[Bus] = []

    async def main() -> None:
        import anyio

        from tfbus.clock import SimClock

        bus = open_bus()
        opened.append(bus)

        async with bus, contextlib.AsyncExitStack() as stack:
            clock = await stack.enter_async_context(SimClock(bus)) if use_sim_time else None
            tg = await stack.enter_async_context(anyio.create_task_group())
            await tg.start(cancel_on_signal, tg.cancel_scope)
            await start(bus, tg, clock)
            if duration is not None:
                await anyio.sleep(duration)
                tg.cancel_scope.cancel()

    code = run_live(main)
    if code not in (None, 130):  # 130: a Ctrl-C before the handler, a clean end too
        return code
    if opened:
        finish(opened[0])
    return 0
