"""``tfbus web``: tf for roslibjs / roslibpy web apps over rosbridge's JSON protocol
(:mod:`tfbus.web`), from a live bus or a bag, without ROS or rosbridge (layer 5)."""

from __future__ import annotations

from pathlib import Path

import click

from tfbus.cli._common import HOST, FiniteFloat, bag_path, fail

__all__ = ["command"]


@click.command("web")
@click.option("--bus", "bus", metavar="SPEC", default=None,
              help="Serve the transforms of this live bus (default 'zenoh' without --bag).")
@click.option("--bag", type=bag_path(), default=None,
              help="Serve this bag's transforms, replayed at recorded timing (in a loop).")
@click.option("--host", type=HOST, default="127.0.0.1", show_default=True,
              help="Address to serve on. Only requests addressed to this machine's names "
                   "(localhost, 127.0.0.1, [::1]) or to --host, from a page of those names, "
                   "are let in; from another machine give --token too.")
@click.option("--port", type=click.IntRange(0, 65535), default=9090, show_default=True,
              help="TCP port (rosbridge's default 9090; 0: any free port).")
@click.option("--token", default=None, metavar="SECRET",
              help="Let a client in from any name when its URL carries this secret "
                   "(ws://HOST:PORT/?token=SECRET).")
@click.option("--cache-time", type=FiniteFloat(min=1.0, max=3600.0), default=10.0,
              show_default=True, help="Seconds of transforms the buffer keeps.")
def command(bus: str | None, bag: Path | None, host: str, port: int, token: str | None,
            cache_time: float) -> None:
    """Serve tf to web apps (roslibjs TFClient / ROS2TFClient, roslibpy TFClient) over
    the rosbridge v2 protocol: /tf, /tf_static and tf2_web_republisher's goals and
    republish_tfs service, thresholds and rate applied per client.

    \b
    Examples:
      tfbus web --bus zenoh --port 9090
      tfbus web --bag tests/data/webviz_turtle_tf_example.bag
    """
    if bag is not None and bus is not None:
        fail("give --bag PATH or --bus SPEC, not both")
    if token is not None:
        from tfbus.view.guard import PageGuard

        try:
            PageGuard(host, port, token)
        except ValueError as err:
            fail(f"--token: {err}")
    try:
        import wsproto  # noqa: F401
    except ImportError:
        fail("the 'wsproto' package is not installed: pip install 'tfbus[web]'")
    from tfbus.errors import PortInUseError
    from tfbus.view.guard import check_port

    try:
        check_port(host, port)
    except PortInUseError as err:
        fail(str(err))
    if bag is not None:
        from tfbus.cli._bag_source import check_bag

        check_bag(bag)
        _serve_bag(bag, host, port, token, cache_time)
    else:
        _serve_bus(bus or "zenoh", host, port, token, cache_time)


def _announce(port: int, host: str, token: str | None) -> None:
    query = "" if token is None else "?token=" + token
    click.echo(f"tfbus web: ws://{host}:{port}/{query}", err=True)


def _serve_bus(spec: str, host: str, port: int, token: str | None, cache_time: float) -> None:
    from tfbus.cli._bus_source import BusSource
    from tfbus.cli._bus_spec import check_bus_spec
    from tfbus.cli._live_session import live, run_live
    from tfbus.web.server import TfWebServer

    check_bus_spec(spec)
    src = BusSource(spec, name="tfbus-web", cache_time=cache_time)

    async def body() -> None:
        import anyio

        assert src.bus is not None
        server = TfWebServer(src.buffer(), src.bus, host=host, port=port, clock=src.clock,
                             token=token)
        async with anyio.create_task_group() as tg:
            bound = await tg.start(server.serve)
            _announce(bound, host, token)

    code = run_live(lambda: live(src, None, body))
    if code:
        raise SystemExit(code)


def _serve_bag(bag: Path, host: str, port: int, token: str | None, cache_time: float) -> None:
    import anyio

    from tfbus.bag.playback import replay
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.cli._live_session import cancel_on_signal
    from tfbus.listener import TransformListener
    from tfbus.web.server import TfWebServer

    async def main() -> None:
        buffer = Buffer(cache_time=cache_time)
        async with Bus() as bus, TransformListener(buffer, bus), \
                anyio.create_task_group() as tg:
            await tg.start(cancel_on_signal, tg.cancel_scope)
            server = TfWebServer(buffer, bus, host=host, port=port, token=token)
            bound = await tg.start(server.serve)
            _announce(bound, host, token)
            while True:  # the bag again and again, as `rosbag play -l`
                if await replay(bag, bus) == 0:
                    await anyio.sleep_forever()
                buffer.clear()

    try:
        anyio.run(main)
    except KeyboardInterrupt:
        raise SystemExit(130) from None
