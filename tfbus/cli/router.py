"""``tfbus router``: Zenoh's own router with tfbus's defaults, for fleets (layer 5).

A Zenoh session in ``router`` mode (:class:`~tfbus.transports.zenoh.router.ZenohRouter`):
no multicast scouting, loopback unless told. It prints one line once listening and runs
until Ctrl-C or SIGTERM (or ``--duration``).
"""

from __future__ import annotations

import re
from pathlib import Path

import click

from tfbus.cli._common import fail, literal, seconds
from tfbus.cli._live_session import cancel_on_signal, run_live

__all__ = ["command"]

_ENDPOINT = re.compile(r"^[a-z][a-z0-9+-]*/[^\s/][^\s]*$")
"""A Zenoh endpoint's shape, ``<protocol>/<address>[?<metadata>][#<config>]``
(zenoh-protocol ``core/endpoint.rs``); Zenoh checks the rest."""
_RUST_LOCATION = re.compile(r" at /\S+?:\d+(?::\d+)?\.?")


@click.command("router")
@click.option("--listen", "listen", metavar="ENDPOINT", multiple=True,
              help="Endpoint to listen on (repeatable; default tcp/127.0.0.1:7447, "
                   "loopback only). Give tcp/0.0.0.0:7447 to serve other hosts.")
@click.option("--connect", "connect", metavar="ENDPOINT", multiple=True,
              help="Another router to connect to (repeatable).")
@click.option("--config", "config", metavar="FILE",
              type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="A Zenoh JSON5 configuration file (its settings rule; mode is "
                   "router). See docs/zenoh.md for TLS and access control.")
@click.option("--duration", type=seconds(), default=None,
              help="Stop after this many seconds (default: until Ctrl-C or SIGTERM).")
def command(listen: tuple[str, ...], connect: tuple[str, ...], config: Path | None,
            duration: float | None) -> int | None:
    """Run Zenoh's router (a Zenoh session in router mode) with tfbus's defaults: no
    multicast scouting, listening on tcp/127.0.0.1:7447 unless told. Robots, base
    stations and viewers connect to it with --bus 'zenoh:mode=client&connect=...'.

    \b
    Examples:
      tfbus router
      tfbus router --listen tcp/0.0.0.0:7447
      tfbus monitor --bus 'zenoh:mode=client&connect=tcp/127.0.0.1:7447&namespace=*'
    """
    import anyio

    from tfbus.errors import TransportError
    from tfbus.transports.zenoh.router import ZenohRouter

    for option, endpoints in (("--listen", listen), ("--connect", connect)):
        for endpoint in endpoints:
            if not _ENDPOINT.match(endpoint):
                fail(f"{option} {endpoint!r}: a Zenoh endpoint is PROTOCOL/ADDRESS, e.g. "
                     "tcp/127.0.0.1:7447")
    try:
        router = ZenohRouter(listen=listen or None, connect=connect or None, config=config)
    except TransportError as err:
        # (Zenoh's messages end with the Rust source location: not the user's concern)
        fail(_RUST_LOCATION.sub("", str(err)))

    async def main() -> None:
        async with router, anyio.create_task_group() as tg:
            with anyio.CancelScope() as scope:
                if duration is not None:
                    scope.deadline = anyio.current_time() + duration
                await tg.start(cancel_on_signal, scope)
                click.echo(f"[ INFO] zenoh router {router.zid} listening on "
                           f"{', '.join(literal(e) for e in router.endpoints)}", err=True)
                await anyio.sleep_forever()
            tg.cancel_scope.cancel()

    return run_live(main)
