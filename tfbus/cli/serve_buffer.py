"""``tfbus serve-buffer``: tf2_ros's buffer_server on a bus (layer 5).

Listens to ``/tf`` and ``/tf_static`` on ``--bus`` into one
:class:`~tfbus.buffer.Buffer` and answers lookups from it
(:class:`~tfbus.remote.BufferServer`: on every bus whose transport serves lookups, the
:class:`~tfbus.transports._base.LookupServing` capability; Zenoh: a queryable, ROS 1:
tf2_ros's LookupTransform action on the node that also carries ``/tf``, ROS 2: that action
over DDS on the transport's participant), until Ctrl-C or
SIGTERM (or ``--duration``); then one summary line.
"""

from __future__ import annotations

import contextlib
from typing import Any

import click

from tfbus.cli._bus_spec import DEFAULT_BUS, open_spec_transport, parse_spec
from tfbus.cli._common import fail, literal, seconds
from tfbus.cli._live_session import cancel_on_signal, run_live

__all__ = ["command"]


@click.command("serve-buffer")
@click.option("--bus", "bus", metavar="SPEC", default=DEFAULT_BUS, show_default=True,
              help="The bus to listen and answer on: Zenoh (e.g. "
                   "'zenoh:mode=client&connect=tcp/127.0.0.1:7447&namespace=robot7') or ROS 1 "
                   "('ros1', 'ros1:master=http://127.0.0.1:11311': the LookupTransform "
                   "action of tf2_ros, as /NAME) or ROS 2 ('ros2', 'ros2:domain=7': the same "
                   "action over DDS).")
@click.option("--name", "name", default="tf2_buffer_server", show_default=True,
              help="The server's name (clients use the same: BufferClient(bus, name=...)).")
@click.option("--cache-time", type=seconds(), default=10.0,
              show_default=True, help="Seconds of history the buffer keeps.")
@click.option("--max-wait", type=seconds(), default=60.0, show_default=True,
              help="Longest wait of one lookup, seconds (a timeout of none or longer waits "
                   "this long; tf2_ros's buffer_server has no bound).")
@click.option("--max-pending", type=click.IntRange(min=1, max=1_000_000), default=1000,
              show_default=True,
              help="Most lookups (ROS 1: goals) waiting at once; more are refused as busy.")
@click.option("--max-per-peer", type=click.IntRange(min=1, max=1_000_000), default=None,
              help="Zenoh: most lookups of one querier waiting at once (default: "
                   "max-pending / 4); ROS 2: most goals of one client (default 100).")
@click.option("--duration", type=seconds(), default=None,
              help="Stop after this many seconds (default: until Ctrl-C or SIGTERM).")
def command(bus: str, name: str, cache_time: float, max_wait: float, max_pending: int,
            max_per_peer: int | None, duration: float | None) -> int | None:
    """Answer transform lookups for thin clients (tf2_ros buffer_server): keep one
    buffer of /tf and /tf_static from --bus and serve lookup_transform,
    lookup_transform_full and can_transform to tfbus.remote.BufferClient (Zenoh), or
    tf2_ros's LookupTransform action as /tf2_buffer_server to tf2_ros.BufferClient
    (ROS 1; ROS 2 over DDS). Every lookup waits at most --max-wait seconds; at most
    --max-pending wait at once (Zenoh, ROS 2: --max-per-peer of one client); a lookup
    whose client cancelled it or left (ROS 1: an actionlib cancel request) ends at once.

    \b
    Examples:
      tfbus serve-buffer
      tfbus serve-buffer --bus 'zenoh:mode=client&connect=tcp/127.0.0.1:7447'
      tfbus serve-buffer --bus ros1
      tfbus serve-buffer --bus ros2:domain=7
    """
    import anyio

    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.listener import TransformListener
    from tfbus.remote import BufferServer
    from tfbus.transports._base import LookupServing

    # the node (ROS 1) or Zenoh session takes tf2_ros's name: the action and /tf share it
    spec = parse_spec(bus, name="tf2_buffer_server")
    if not name:
        fail("--name must not be empty")
    transport = open_spec_transport(spec, name="tf2_buffer_server")
    if not isinstance(transport, LookupServing):
        fail(f"--bus {bus!r}: the {spec.scheme!r} transport does not serve lookups "
             "(Zenoh, ROS 1 and ROS 2 do)")
    options: dict[str, Any] = {"name": name, "max_pending": max_pending, "max_wait": max_wait}
    if max_per_peer is not None:
        options["max_per_peer"] = max_per_peer
    buffer = Buffer(cache_time=cache_time)
    the_bus = Bus(transport=transport)
    try:
        server = BufferServer(buffer, the_bus, **options)
    except (TypeError, ValueError) as err:
        fail(f"--bus {bus!r}: {err}")

    async def main() -> None:
        async with contextlib.AsyncExitStack() as stack:
            b = await stack.enter_async_context(the_bus)
            await stack.enter_async_context(TransformListener(buffer, b))
            await stack.enter_async_context(server)
            tg = await stack.enter_async_context(anyio.create_task_group())
            with anyio.CancelScope() as scope:
                if duration is not None:
                    scope.deadline = anyio.current_time() + duration
                await tg.start(cancel_on_signal, scope)
                click.echo(f"[ INFO] buffer server on {literal(server.where)}", err=True)
                await anyio.sleep_forever()
            tg.cancel_scope.cancel()

    status = run_live(main)
    s = server.statistics()
    click.echo(f"[ INFO] summary: {s.requests} requests, {s.answered} answered, "
               f"{s.errors} errors, {s.malformed} malformed, {s.busy} busy, "
               f"{s.cancelled} cancelled")
    return status
