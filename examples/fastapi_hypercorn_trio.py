"""The FastAPI application of ``examples/fastapi_app.py`` served by hypercorn on trio.

Run: ``python examples/fastapi_hypercorn_trio.py 8000`` (127.0.0.1), then
``curl '127.0.0.1:8000/transform/odom/base_link?ahead=0.2'``; Ctrl-C to stop.

hypercorn's own command line runs the application in worker processes that never see the
signal (the parent tells them through a shared event after it), so a request awaiting a
transform is cut when the graceful timeout ends, not answered. Served from code with
``hypercorn.trio.serve``, the application's lifespan receives SIGINT / SIGTERM itself
(:func:`examples.fastapi_app.close_on_shutdown_signal`): it closes the buffer, so the
waiting requests are answered 503 at once, and sets ``app.state.stopping``, which is
hypercorn's ``shutdown_trigger``: the server stops accepting, finishes its requests, runs
the lifespan's exit and returns.
"""

from __future__ import annotations

import sys

import trio
from hypercorn.config import Config
from hypercorn.trio import serve

from examples.fastapi_app import app


async def main(port: int) -> None:
    config = Config()
    config.bind = [f"127.0.0.1:{port}"]
    # Called once the lifespan's start-up is complete, so app.state.stopping exists.
    await serve(app, config, shutdown_trigger=lambda: app.state.stopping.wait())
    print("server stopped", flush=True)


if __name__ == "__main__":
    trio.run(main, int(sys.argv[1]) if len(sys.argv) > 1 else 8000)
