"""A bus, buffer, listener and broadcasters held open by a background task.

``async with Bus() as bus:`` ties the bus to the task that entered it: its task group and
cancel scopes must be left by that same task. A Jupyter notebook runs each cell in its own
task, an interactive console or a framework's start-up hook may too, so such a block cannot
be opened in one place and closed in another. :func:`open_session` opens the usual set
(:class:`~tfbus.bus.Bus`, :class:`~tfbus.buffer.Buffer`,
:class:`~tfbus.listener.TransformListener`, :class:`~tfbus.broadcaster.TransformBroadcaster`,
:class:`~tfbus.broadcaster.StaticTransformBroadcaster`) inside a task it starts, and returns a
:class:`TransformSession` whose :meth:`~TransformSession.aclose` works from any task of the
same event loop.

Where the owning task runs:

* asyncio: a :class:`asyncio.Task` on the running loop (``loop.create_task``);
* trio: a system task (``trio.lowlevel.spawn_system_task``), cancelled — and the bus closed —
  when the run's main task ends;
* either, with ``task_group=``: a task of that anyio task group, which then cannot end
  before the session is closed (the structured choice for servers).

See docs/recipes/jupyter.md for the notebook recipe, and the page "Using tfbus in your
application" for error handling, cancellation and shutdown.
"""

from __future__ import annotations

import asyncio
import contextlib
import weakref
from collections.abc import Awaitable, Callable
from types import TracebackType

import anyio
import anyio.abc
import sniffio

from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus, Transport
from tfbus.clock import Clock
from tfbus.listener import TransformListener
from tfbus.time import Duration

__all__ = ["TransformSession", "open_session"]

# Sessions opened with a name, per event loop: opening one again under the same name
# closes the previous one first (a re-run notebook cell does not leak a bus).
_named: weakref.WeakValueDictionary[tuple[int, str], TransformSession] = (
    weakref.WeakValueDictionary()
)


def _loop_key() -> int:
    """An identity of the running event loop (asyncio loop or trio run)."""
    if sniffio.current_async_library() == "trio":
        import trio

        return id(trio.lowlevel.current_root_task())
    return id(asyncio.get_running_loop())


class TransformSession:
    """An open bus with its buffer, listener and broadcasters, owned by a background task.

    Made by :func:`open_session` (not directly). The attributes are the opened objects;
    they stay usable until :meth:`aclose` (or the owner's end: a transport failure, the
    loop's end on trio). The session is also an async context manager whose exit calls
    :meth:`aclose`.

    Attributes:
        bus: the open :class:`~tfbus.bus.Bus`.
        buffer: the :class:`~tfbus.buffer.Buffer` the listener stores into.
        listener: the entered :class:`~tfbus.listener.TransformListener`.
        broadcaster: a :class:`~tfbus.broadcaster.TransformBroadcaster` on ``bus``.
        static_broadcaster: a :class:`~tfbus.broadcaster.StaticTransformBroadcaster`.
        name: the name given to :func:`open_session`, or None.
    """

    def __init__(
        self, bus: Bus, buffer: Buffer, listener: TransformListener, name: str | None
    ) -> None:
        """Hold the objects; the owning task is started by :func:`open_session`."""
        self.bus = bus
        self.buffer = buffer
        self.listener = listener
        self.broadcaster = TransformBroadcaster(bus)
        self.static_broadcaster = StaticTransformBroadcaster(bus)
        self.name = name
        self._close_requested = anyio.Event()
        self._started = anyio.Event()
        self._ended = anyio.Event()
        self._error: BaseException | None = None
        self._error_reported = False
        self._key: tuple[int, str] | None = None

    @property
    def closed(self) -> bool:
        """Whether the owning task has ended (closed by :meth:`aclose` or by a failure)."""
        return self._ended.is_set()

    async def _own(
        self, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        """Enter the bus and the listener, wait for the close request, leave them."""
        try:
            async with self.bus, self.listener:
                self._started.set()
                task_status.started()
                await self._close_requested.wait()
        except BaseException as exc:  # recorded for open_session / aclose to raise
            self._error = exc
            if not self._started.is_set():
                raise  # to task_group.start, or dropped by _spawn's wrapper (recorded)
        finally:
            self._started.set()
            self._ended.set()

    async def aclose(self) -> None:
        """Close the listener and the bus and wait until they are closed.

        Works from any task of the loop the session was opened in; idempotent (a second
        call returns at once). Shielded from cancellation, so an interrupted caller
        still leaves nothing half-closed. Waits that were pending on the buffer end as
        :mod:`tfbus.buffer` documents for a closed bus.

        Raises:
            Exception: the error the owning task ended with (a transport failure, as
            ``async with Bus()`` would raise it), once.
        """
        self._close_requested.set()
        with anyio.CancelScope(shield=True):
            await self._ended.wait()
        if self._key is not None and _named.get(self._key) is self:
            del _named[self._key]
        if self._error is not None and not self._error_reported:
            self._error_reported = True
            if not isinstance(self._error, anyio.get_cancelled_exc_class()):
                raise self._error

    async def __aenter__(self) -> TransformSession:
        """Return the (already open) session."""
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """:meth:`aclose`."""
        await self.aclose()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<TransformSession name={self.name!r} {state}>"


async def open_session(
    transport: Transport | None = None,
    *,
    name: str | None = None,
    cache_time: float | Duration = 10.0,
    clock: Clock | None = None,
    queue_size: int = 100,
    task_group: anyio.abc.TaskGroup | None = None,
) -> TransformSession:
    """Open a bus, a buffer, a listener and broadcasters in a background task.

    ``session = await open_session(ZenohTransport(...), name="robot")`` in one notebook
    cell, ``await session.buffer.lookup_transform_async(...)`` in the next, and
    ``await session.aclose()`` in a later one: each may run in its own task.

    Args:
        transport: the bus's transport (None: in-process only).
        name: a session opened under a name already open on this event loop closes the
            old one first (a re-run set-up cell replaces its session, leaking nothing).
        cache_time: the buffer's cache time, seconds or a Duration (tf2's default 10 s).
        clock: the buffer's (and listener's) clock; default the system clock.
        queue_size: the bus's default subscription queue capacity.
        task_group: run the owning task in this anyio task group instead of a detached
            task (asyncio Task / trio system task).

    Returns:
        The open :class:`TransformSession`.

    Raises:
        Exception: whatever opening the bus raised (e.g. ``transport.run`` failing
            before it reports started), as ``async with Bus()`` raises it.
        RuntimeError: if not called from a running asyncio or trio event loop.
    """
    if name is not None:
        key = (_loop_key(), name)
        old = _named.get(key)
        if old is not None:
            with contextlib.suppress(Exception):
                await old.aclose()
    buffer = Buffer(cache_time, clock=clock)
    bus = Bus(transport, queue_size=queue_size)
    session = TransformSession(bus, buffer, TransformListener(buffer, bus), name)
    if task_group is not None:
        await task_group.start(session._own)
    else:
        _spawn(session._own)
        try:
            await session._started.wait()
        except BaseException:
            # The caller was interrupted while the bus opened: close what was opened.
            await session.aclose()
            raise
    if session._error is not None:
        session._error_reported = True
        raise session._error
    if name is not None:
        session._key = (_loop_key(), name)
        _named[session._key] = session
    return session


_background: set[asyncio.Task[None]] = set()  # strong references to the owners


def _spawn(run: Callable[[], Awaitable[None]]) -> None:
    """Start ``run`` detached from the calling task, on the running loop."""
    library = sniffio.current_async_library()
    if library == "trio":
        import trio

        async def system_task() -> None:
            with contextlib.suppress(Exception, trio.Cancelled):  # recorded by the session
                await run()

        trio.lowlevel.spawn_system_task(system_task, name="tfbus session")
        return
    if library != "asyncio":  # pragma: no cover - anyio supports only these two
        raise RuntimeError(f"open_session: unsupported event loop {library!r}")

    async def coroutine() -> None:
        with contextlib.suppress(Exception):  # recorded by the session
            await run()

    task = asyncio.get_running_loop().create_task(coroutine(), name="tfbus session")
    _background.add(task)
    task.add_done_callback(_background.discard)

