"""The transform source of echo, monitor and frames from their options: ``--bag PATH``
or ``--bus SPEC`` (:func:`source_options`), the source they name (:func:`source`: a
:class:`~tfbus.cli._bag_source.BagSource` or a :class:`~tfbus.cli._bus_source.BusSource`)
and the options that only mean something on a live bus (:func:`live_only`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from tfbus.cli._bag_source import BagSource
from tfbus.cli._bus_source import BusSource
from tfbus.cli._common import fail
from tfbus.cli._tf_source import TfSource
from tfbus.transports.spec import DEFAULT_BUS

if TYPE_CHECKING:
    from tfbus.core.policy import ExpireAfter

__all__ = ["live_only", "source", "source_options"]

F = TypeVar("F", bound=Callable[..., Any])


def source_options(f: F) -> F:
    """``--bag PATH`` and ``--bus SPEC``: the transform source of echo/monitor/frames."""
    from tfbus.cli._common import bag_path

    f = click.option(
        "--bus", "bus", metavar="SPEC", default=None,
        help="The live bus to listen to (default, without --bag: 'zenoh', this machine, "
             "where the publishing commands publish by default): 'zenoh', "
             "'zenoh:tcp/HOST:7448', 'zenoh?connect=...&namespace=...', 'ros2' "
             "(ROS 2 over DDS, 'ros2:domain=7'), 'ros1' (a ROS 1 master, "
             "'ros1:http://127.0.0.1:11311').",
    )(f)
    return click.option("--bag", type=bag_path(), help="Read transforms from this bag.")(f)


def source(bag: Path | None, bus: str | None = None, *, name: str = "tfbus-cli",
           use_sim_time: bool = False, cache_policy: ExpireAfter | None = None) -> TfSource:
    """The source the options name: the bag, else the ``--bus`` spec, else the default
    bus (:data:`DEFAULT_BUS`, where the publishing commands publish); a usage error for
    both, and for ``--use-sim-time`` with a bag (a bag has its own times)."""
    if bus is not None and bag is not None:
        fail("give --bag PATH or --bus SPEC, not both")
    if bag is not None:
        if use_sim_time:
            fail("--use-sim-time applies to --bus sources only")
        return BagSource(bag)
    return BusSource(bus if bus is not None else DEFAULT_BUS, name=name,
                     use_sim_time=use_sim_time, cache_policy=cache_policy)


def live_only(src: TfSource, **options: object) -> None:
    """Options that only mean something on a live bus: an error with --bag."""
    if not isinstance(src, BusSource):
        for name, value in options.items():
            if value is not None:
                fail(f"--{name.replace('_', '-')} applies to --bus sources only")
