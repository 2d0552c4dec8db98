"""Running a command on a live bus: :func:`run_live` (a bus that cannot be opened is a
one-line error, exit status 1), :func:`live` (attached until its body returns, a duration
passes or a signal comes), :func:`cancel_on_signal` and :func:`is_bus_error`.
"""

from __future__ import annotations

import signal
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from tfbus.cli._common import anyio_run_args, error, interrupted

if TYPE_CHECKING:
    import anyio

    from tfbus.cli._bus_source import BusSource
    from tfbus.transports._base import PeerInfo

__all__ = ["cancel_on_signal", "is_bus_error", "live", "run_live"]


def is_bus_error(err: BaseException) -> bool:
    """An error opening or using a transport: :class:`~tfbus.errors.TransportError` (every
    transport maps its middleware's errors to it) or an ``OSError``."""
    from tfbus.errors import TransportError

    return isinstance(err, (OSError, TransportError))


def _bus_error_in(err: BaseException) -> BaseException | None:
    """The transport error in ``err`` or in an exception group around it."""
    if is_bus_error(err):
        return err
    for inner in getattr(err, "exceptions", ()):
        found = _bus_error_in(inner)
        if found is not None:
            return found
    return None


def run_live(main: Callable[[], Awaitable[None]], *, backend: str = "asyncio") -> int | None:
    """``anyio.run(main)`` on ``backend`` (``asyncio``, ``trio`` or ``uvloop``:
    :func:`~tfbus.cli._common.anyio_run_args`); None when it ran, 1 (after a one-line
    error) when the bus could not be opened, 130 on a Ctrl-C before the signal handler
    was installed."""
    import anyio

    try:
        anyio.run(main, **anyio_run_args(backend))
    except KeyboardInterrupt:  # Ctrl-C while the session was still opening
        return 130
    except Exception as err:
        found = _bus_error_in(err)
        if found is None:
            raise
        error(f"cannot open the bus: {found}")
        return 1
    except BaseException as err:  # Ctrl-C raised inside a task group comes grouped
        if not interrupted(err):
            raise
        return 130
    return None


async def cancel_on_signal(scope: anyio.CancelScope, *, task_status: Any = None) -> None:
    """Cancel ``scope`` at the first SIGINT or SIGTERM (``await tg.start(...)`` returns
    once the handler is installed)."""
    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        if task_status is not None:
            task_status.started()
        async for _ in signals:
            scope.cancel()
            return


async def live(
    src: BusSource,
    duration: float | None,
    body: Callable[[], Awaitable[None]],
    *,
    on_peer: Callable[[str, PeerInfo], None] | None = None,
    finish: Callable[[], None] | None = None,
) -> None:
    """Attach ``src`` and run ``body`` until it returns, ``duration`` seconds have
    passed (None: no limit) or SIGINT/SIGTERM arrives; then call ``finish`` while still
    attached (so liveliness is current) and detach.

    While ``body`` runs, the objects the process made up to then (modules, the bus, its
    transport and session) are left out of the cyclic garbage collector's generations
    (:func:`gc.freeze`, undone by :func:`gc.unfreeze` when ``body`` ends; nothing is
    done when the process has frozen objects already): most live as long as the
    session (one dropped meanwhile in a reference cycle is collected after it), and a
    full collection -- which a command that allocates as it runs (``tfbus view`` with a
    page: a scene a redraw) triggers every few seconds -- traverses only what the
    session made since (``gc.freeze`` was added to CPython for this and for fork,
    bpo-31558: "... or to speed up collection")."""
    import gc

    import anyio

    async with src.attach(on_peer), anyio.create_task_group() as tg:
        with anyio.CancelScope() as scope:
            if duration is not None:
                scope.deadline = anyio.current_time() + duration
            await tg.start(cancel_on_signal, scope)
            freeze = gc.get_freeze_count() == 0
            if freeze:
                gc.freeze()
            try:
                await body()
            finally:
                if freeze:
                    gc.unfreeze()
        if finish is not None:
            finish()
        tg.cancel_scope.cancel()
