"""``tfbus serve-buffer``: tf2_ros's buffer_server on a bus (layer 5).

Listens to ``/tf`` and ``/tf_static`` on ``--bus`` into one
:class:`~tfbus.buffer.Buffer` and answers :class:`~tfbus.remote.BufferClient` lookups
from it (:class:`~tfbus.remote.BufferServer`), until Ctrl-C or SIGTERM (or
``--duration``); then one summary line.
"""

from __future__ import annotations

import click

from tfbus.cli._common import fail, literal
from tfbus.cli._sources import (
    DEFAULT_BUS,
    cancel_on_signal,
    open_spec_transport,
    parse_spec,
    run_live,
)

__all__ = ["command"]


@click.command("serve-buffer")
@click.option("--bus", "bus", metavar="SPEC", default=DEFAULT_BUS, show_default=True,
              help="The Zenoh bus to listen and answer on, e.g. "
                   "'zenoh:mode=client&connect=tcp/127.0.0.1:7447&namespace=robot7'.")
@click.option("--name", "name", default="tf2_buffer_server", show_default=True,
              help="The server's name (clients use the same: BufferClient(bus, name=...)).")
@click.option("--cache-time", type=click.FloatRange(min=0, min_open=True), default=10.0,
              show_default=True, help="Seconds of history the buffer keeps.")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Stop after this many seconds (default: until Ctrl-C or SIGTERM).")
def command(bus: str, name: str, cache_time: float, duration: float | None) -> int | None:
    """Answer transform lookups for thin clients (tf2_ros buffer_server): keep one
    buffer of /tf and /tf_static from --bus and serve lookup_transform,
    lookup_transform_full and can_transform to tfbus.remote.BufferClient.

    \b
    Examples:
      tfbus serve-buffer
      tfbus serve-buffer --bus 'zenoh:mode=client&connect=tcp/127.0.0.1:7447'
    """
    import anyio

    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.listener import TransformListener
    from tfbus.remote import BufferServer

    spec = parse_spec(bus, name="tf2_buffer_server")
    if spec.scheme != "zenoh":
        fail(f"--bus {bus!r}: serve-buffer answers over Zenoh only (a 'zenoh' bus)")
    if spec.value("namespace") == "*":
        fail(f"--bus {bus!r}: serve one robot's namespace, not namespace=*")
    if not name:
        fail("--name must not be empty")
    served: list[BufferServer] = []

    async def main() -> None:
        buffer = Buffer(cache_time=cache_time)
        transport = open_spec_transport(spec, name="tf2_buffer_server")
        async with Bus(transport=transport) as b, TransformListener(buffer, b), \
                BufferServer(buffer, b, name=name) as server, anyio.create_task_group() as tg:
            served.append(server)
            with anyio.CancelScope() as scope:
                if duration is not None:
                    scope.deadline = anyio.current_time() + duration
                await tg.start(cancel_on_signal, scope)
                click.echo(f"[ INFO] buffer server on {literal(server.key)}", err=True)
                await anyio.sleep_forever()
            tg.cancel_scope.cancel()

    status = run_live(main)
    if served:
        s = served[0].statistics()
        click.echo(f"[ INFO] summary: {s.requests} requests, {s.answered} answered, "
                   f"{s.errors} errors, {s.malformed} malformed")
    return status
