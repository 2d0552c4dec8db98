"""The ``--bus SPEC`` option: a spec parsed by the scheme table
(:mod:`tfbus.transports.spec`) with its values checked before anything runs
(:func:`parse_spec`, :func:`check_bus_spec`), the transport it opens
(:func:`open_spec_transport`), and the bus of the publishing commands
(:func:`publish_options`, :func:`publish_bus`: ``--bus`` or ``--local``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import click

from tfbus.cli._common import fail
from tfbus.transports.spec import BUS_HELP, DEFAULT_BUS  # DEFAULT_BUS: no --bus

if TYPE_CHECKING:
    from tfbus.bus import Bus, Transport
    from tfbus.transports.spec import BusSpec

__all__ = ["DEFAULT_BUS", "check_bus_spec", "open_spec_transport", "parse_spec",
           "publish_bus", "publish_options"]

F = TypeVar("F", bound=Callable[..., Any])


def parse_spec(spec: str, *, name: str = "tfbus-cli") -> BusSpec:
    """``--bus SPEC`` parsed by the scheme table (:mod:`tfbus.transports.spec`: ``zenoh``,
    ``ros2``, ``ros1``, ``memory``, ...), or a one-line usage error (exit status 2).

    Option values are checked here too, before anything runs: a transport is built from
    the spec (not opened: no socket, no thread) and dropped, so a value its factory or
    constructor refuses (``zenoh?port=abc``, ``ros2:domain=999``, ``ros1:name=bad name``,
    an unreadable ``ros2:config`` file, ...) is the same one-line usage error. A missing
    extra raises :class:`~tfbus.errors.MissingExtraError` naming it (the ``tfbus`` group
    prints it on one line, exit status 2).
    """
    from tfbus.errors import TransportError
    from tfbus.transports.spec import parse_bus_spec, schemes

    try:
        parsed = parse_bus_spec(spec)
    except ValueError as err:
        fail(str(err))
    scheme = schemes().get(parsed.scheme)
    if scheme is not None:  # a missing extra: named now, as every one (exit status 2)
        from tfbus._extras import require

        require(f"the {parsed.scheme!r} bus", *scheme.requires, extra=scheme.extra or None)
    try:
        open_spec_transport(parsed, name=name)
    except ValueError as err:
        fail(f"--bus {spec!r}: {err}")
    except TransportError:
        pass  # the transport refused its configuration: said when the bus is opened
    return parsed


def open_spec_transport(
    spec: BusSpec, *, name: str, scan_topics: Sequence[str] = (), use_sim_time: bool = False
) -> Transport:
    """A new transport for ``spec``; ``name`` is this node's name unless the spec gives
    one (:func:`tfbus.transports.spec.open_transport`'s ``default_name``); ``scan_topics``
    are the LaserScan topics it must carry (``tfbus view --scan``); ``use_sim_time``: it
    must carry ``/clock`` too (a ROS 1 node or a ROS 2 participant subscribes to it by
    type: the transport's ``clock_topic``, where the scheme table says it takes one;
    Zenoh and memory carry every topic).

    Raises:
        TransportError: the scheme's extra is not installed (named), or the transport
            rejects its configuration.
        ValueError: an option value the transport does not understand.
    """
    from tfbus.transports.spec import open_transport, schemes

    scheme = schemes().get(spec.scheme)
    if use_sim_time and scheme is not None and scheme.clock_topic:
        from tfbus.topics import CLOCK_TOPIC

        return open_transport(spec, default_name=name, scan_topics=scan_topics,
                              clock_topic=CLOCK_TOPIC)
    return open_transport(spec, default_name=name, scan_topics=scan_topics)


def check_bus_spec(bus: str | None) -> None:
    """A bad ``--bus`` is a one-line usage error here, before anything runs."""
    if bus is not None:
        parse_spec(bus)


def publish_options(f: F) -> F:
    """``--bus SPEC`` and ``--local``: where static-transform and replay publish."""
    f = click.option("--local", is_flag=True,
                     help="Publish on a private in-process bus instead (nobody else sees "
                          "it: for trying the command out).")(f)
    return click.option("--bus", "bus", metavar="SPEC", default=None, help=BUS_HELP)(f)


def publish_bus(bus: str | None, local: bool, *, name: str,
                use_sim_time: bool = False) -> Callable[[], Any]:
    """A factory of the (unopened) bus the options name: in-process with ``--local``, else
    the ``--bus`` spec (default ``zenoh``). Bad options are a one-line usage error now.
    ``use_sim_time``: the transport carries ``/clock`` too (:func:`open_spec_transport`)."""
    from tfbus.bus import Bus

    if local:
        if bus is not None:
            fail("give --bus SPEC or --local, not both")
        return Bus
    chosen = parse_spec(bus if bus is not None else DEFAULT_BUS, name=name)

    def open_bus() -> Bus:
        return Bus(transport=open_spec_transport(chosen, name=name, use_sim_time=use_sim_time))

    return open_bus
