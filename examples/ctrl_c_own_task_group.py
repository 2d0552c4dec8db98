"""Ctrl-C in a program whose own anyio task group runs inside ``Bus`` and
``TransformListener`` (the nesting ``docs/async.md`` recommends).

tfbus's context managers let what their body raises leave as itself; the application's
own task group does not: anyio's task groups gather what their tasks raise into a
``BaseExceptionGroup``. On trio a Ctrl-C lands in whichever task runs, so it leaves that
group as ``BaseExceptionGroup([KeyboardInterrupt()])`` and a plain
``except KeyboardInterrupt`` misses it; ``except* KeyboardInterrupt`` (Python 3.11+)
catches it grouped or not, on both backends. Python 3.10: ``exceptiongroup.catch`` (a
tfbus dependency there), shown in ``docs/async.md``.

Run: ``python examples/ctrl_c_own_task_group.py [asyncio|trio] [star|plain]``; it prints
``READY`` once its tasks run, then waits for Ctrl-C and says how it was caught.
"""

from __future__ import annotations

import sys

import anyio

from tfbus import Buffer, Bus, TransformListener


async def main() -> None:
    buffer = Buffer()
    async with Bus() as bus, TransformListener(buffer, bus), \
            anyio.create_task_group() as tg:
        tg.start_soon(anyio.sleep_forever)  # the application's own work
        print("READY", flush=True)
        await anyio.sleep_forever()


def star(backend: str) -> None:
    try:
        anyio.run(main, backend=backend)
    except* KeyboardInterrupt:  # grouped (trio) or not (asyncio): caught here
        print("stopped by Ctrl-C (except* KeyboardInterrupt)", flush=True)


def plain(backend: str) -> None:
    try:
        anyio.run(main, backend=backend)
    except KeyboardInterrupt:
        print("stopped by Ctrl-C (except KeyboardInterrupt)", flush=True)
    except BaseExceptionGroup as group:  # what a plain except misses
        print(f"not caught by except KeyboardInterrupt: {group!r}", flush=True)


if __name__ == "__main__":
    backend = sys.argv[1] if len(sys.argv) > 1 else "asyncio"
    (plain if len(sys.argv) > 2 and sys.argv[2] == "plain" else star)(backend)
