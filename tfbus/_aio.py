"""Every CPython-asyncio shortcut of tfbus, in one file to review per Python release.

anyio keeps its own in ``anyio/_backends/_asyncio.py``; tfbus's hot paths take a few more,
each measured to matter (``benchmarks/bench_bus.py``, ``bench_check.py``'s wake-up rows)
and each with its portable anyio fallback next to it in the caller:

* :func:`running_asyncio_loop` -- is the caller an asyncio task? (``sys.modules``, never
  an import of asyncio);
* :class:`ShieldedYield` -- ``cancel_shielded_checkpoint`` as one yield on a done future
  (``Future._asyncio_future_blocking``);
* :func:`timer_delay` -- the delay to arm a loop timer with so that it fires no earlier
  than asked on a loop whose timers count whole milliseconds (uvloop's);
* :class:`Wakeup` -- a one-shot wake-up: a bare future of the loop on asyncio, a parked
  task on trio (``trio.lowlevel``, looked up in ``sys.modules``), an ``anyio.Event``
  elsewhere;
* :func:`wait_all_tasks_blocked` -- anyio's ``wait_all_tasks_blocked`` without its 0.1 s
  wall-clock sleeps on asyncio (``Task._fut_waiter``);
* :func:`open_pumped_connection` -- a TCP connection read in the loop's read callback into
  one kept buffer (``asyncio.BufferedProtocol``), for the ROS 1 transport's TCPROS
  subscriber connections;
* :func:`asyncio_transport_of` -- the ``asyncio.Transport`` under an anyio socket stream
  (uvloop's own transport on uvloop), which the ROS 1 publisher writes a frame to from the
  publishing task.

and, portable on every backend, :func:`exit_task_group`: how every tfbus context manager
that owns a task group leaves it, so that the exception its body raised leaves it as
itself (not inside an ``ExceptionGroup``); and :func:`coroutine_method`, whose
:class:`Awaiting` names the missing ``await`` of a tf2_ros habit (a blocking call).

Nothing here imports tfbus: the bus, the clocks, the buffer and the ROS 1 transport import
it. ``asyncio`` itself is imported only inside the asyncio-only functions, so a trio
program never loads it through tfbus.
"""

from __future__ import annotations

import functools
import inspect
import math
import re
import sys
import warnings
from collections.abc import Awaitable, Callable, Coroutine, Generator
from typing import TYPE_CHECKING, Any, NoReturn, ParamSpec, TypeVar, cast

import anyio
import anyio.abc
import anyio.lowlevel

if TYPE_CHECKING:
    import asyncio
    from asyncio import AbstractEventLoop, Future, Transport
    from types import TracebackType

__all__ = [
    "MILLISECOND_TIMERS",
    "Awaiting",
    "ShieldedYield",
    "Wakeup",
    "asyncio_transport_of",
    "coroutine_method",
    "exit_task_group",
    "open_pumped_connection",
    "running_asyncio_loop",
    "timer_delay",
    "wait_all_tasks_blocked",
]


def running_asyncio_loop() -> AbstractEventLoop | None:
    """The running asyncio event loop when the caller runs in one of its tasks (anyio on
    asyncio), else None (trio, including trio in guest mode on an asyncio host, whose
    tasks are not asyncio tasks; no loop at all).

    ``asyncio`` is looked up in ``sys.modules`` (it is necessarily loaded when an asyncio
    loop is running), never imported by tfbus.
    """
    asyncio = sys.modules.get("asyncio")
    if asyncio is None:
        return None
    try:
        loop: AbstractEventLoop = asyncio.get_running_loop()
    except RuntimeError:  # no asyncio loop running in this thread
        return None
    if asyncio.current_task(loop) is None:
        return None  # a callback of the loop, not a task: e.g. trio in guest mode
    return loop


MILLISECOND_TIMERS: dict[type, bool] = {}
"""Per event loop class met so far: whether its timers count whole milliseconds
(uvloop's), filled by :func:`timer_delay`; a hot path reads it first (``.get(type(loop),
True)``) and calls :func:`timer_delay` only when it is not known to be False."""


def timer_delay(loop: AbstractEventLoop, seconds: float) -> float:
    """The delay to give ``loop.call_later`` (or ``loop.call_at(loop.time() + delay)``)
    for a timer that must not fire before ``seconds`` (> 0) have passed.

    asyncio's own loop keeps a timer's time as a float and runs it once its time has
    come: ``seconds`` itself. uvloop's counts whole milliseconds of libuv's clock, which
    it reads truncated to the millisecond (``Loop.call_later``: ``round(delay * 1000)``
    milliseconds, and a delay that rounds to 0 runs at the loop's next turn; libuv
    ``uv_timer_start`` from ``uv_now``): a timer fires up to a millisecond early, and a
    deadline re-armed for what is left of it then runs at every turn of the loop until
    the deadline passes (a busy loop of up to half a millisecond a deadline). There the
    delay is rounded up to a whole millisecond, plus one: the timer fires once, never
    before ``seconds``, and less than 3 ms after (the rounding, and libuv's clock read in
    whole milliseconds when the timer is armed and when it is run) on an idle loop.
    """
    kind = type(loop)
    coarse = MILLISECOND_TIMERS.get(kind)
    if coarse is None:
        coarse = MILLISECOND_TIMERS[kind] = _module_root(loop) == "uvloop"
    if not coarse:
        return seconds
    return (math.ceil(seconds * 1000.0 - 1e-6) + 1) / 1000.0


class ShieldedYield:
    """``await shielded_yield()`` on asyncio: what anyio's ``cancel_shielded_checkpoint``
    does (let every other ready task run once, then resume; never raise anyio's
    cancellation), without entering and leaving a ``CancelScope(shield=True)``, which cost
    about as much as the rest of a bus publish.

    The task waits on a future that is already done (one per bus, done for good, so it
    serves every publish). asyncio resumes the task exactly as after ``sleep(0)`` (one
    ``call_soon``, behind every callback already ready), and anyio never cancels a task
    whose awaited future is done: a cancel scope cancelled meanwhile delivers its
    cancellation at the task's next checkpoint instead, as it does for a shielded one. (A
    native ``Task.cancel()`` still lands, as it does through anyio's shield.)
    ``tests/test_bus.py`` holds anyio to this.

    Args:
        loop: the asyncio loop whose tasks await it (:func:`running_asyncio_loop`).
    """

    __slots__ = ("_future",)

    def __init__(self, loop: AbstractEventLoop) -> None:
        future = loop.create_future()
        future.set_result(None)
        self._future = future

    def __call__(self) -> ShieldedYield:
        return self

    def __await__(self) -> Generator[Any, None, None]:
        future = self._future
        future._asyncio_future_blocking = True  # what Future.__await__ sets: "wait on me"
        yield future


def _running_trio() -> Any:
    """``trio.lowlevel`` when the caller runs in a trio task (``trio`` looked up in
    ``sys.modules``, never imported here), else None."""
    trio = sys.modules.get("trio")
    if trio is None:
        return None
    try:
        trio.lowlevel.current_task()
    except RuntimeError:  # not inside trio.run
        return None
    return trio.lowlevel


class Wakeup:
    """A one-shot wake-up for one waiting task: :meth:`wait` gives what it awaits (once),
    :meth:`wake` ends the wait (idempotent; harmless after the task was cancelled).

    On asyncio (``loop`` given) the task awaits a bare future of ``loop`` (what
    ``anyio.Event`` wraps twice: ``anyio.Event`` -> ``asyncio.Event`` -> a future per
    waiter). On trio the task parks itself (``trio.lowlevel.wait_task_rescheduled``) and
    :meth:`wake` reschedules it (what ``trio.Event`` does through its ``ParkingLot``,
    which ``anyio.Event`` wraps again); a cancellation aborts the park (trio's
    ``Abort.SUCCEEDED``), as it does ``trio.Event.wait``. Elsewhere an ``anyio.Event``.
    Each is cancelled like any anyio checkpoint.

    Args:
        loop: the running asyncio loop (:func:`running_asyncio_loop`), or None.
    """

    __slots__ = ("event", "future", "task", "woken")

    def __init__(self, loop: AbstractEventLoop | None) -> None:
        self.future: Future[None] | None = None
        self.event: anyio.Event | None = None
        self.task: Any = None  # trio: the parked task, while it is parked
        self.woken = False  # trio: wake() was called
        if loop is not None:
            self.future = loop.create_future()
        elif _running_trio() is None:
            self.event = anyio.Event()

    def wait(self) -> Awaitable[object]:
        """What the waiting task awaits (once, at once): a checkpoint even if already
        woken (a ``timeout=0`` poll must yield, as anyio's ``Event.wait`` does). On trio
        the calling task is the one parked: trio's own ``wait_task_rescheduled``, with no
        coroutine of tfbus around it."""
        future = self.future
        if future is not None:
            return anyio.lowlevel.checkpoint() if future.done() else future
        if self.event is not None:
            return self.event.wait()
        lowlevel = sys.modules["trio"].lowlevel
        if self.woken:
            return lowlevel.checkpoint()  # type: ignore[no-any-return]
        self.task = lowlevel.current_task()
        return lowlevel.wait_task_rescheduled(self._abort)  # type: ignore[no-any-return]

    def _abort(self, _raise_cancel: object) -> Any:
        """trio: the parked task is cancelled; a later :meth:`wake` is a no-op."""
        self.task = None
        return sys.modules["trio"].lowlevel.Abort.SUCCEEDED

    def wake(self) -> None:
        """End the wait (idempotent; harmless after the task was cancelled)."""
        future = self.future
        if future is not None:
            if not future.done():
                future.set_result(None)
        elif self.event is not None:
            self.event.set()
        else:
            self.woken = True
            task = self.task
            if task is not None:
                self.task = None
                sys.modules["trio"].lowlevel.reschedule(task)


async def wait_all_tasks_blocked() -> None:
    """Let every other task run until it is blocked, without touching the wall clock.

    On trio this is ``trio.testing.wait_all_tasks_blocked`` via anyio, which is exact and
    instant. anyio's asyncio version sleeps 0.1 s of *wall time* each time it finds a
    runnable task, which would make every woken chain of tasks (timer -> bus ->
    subscriber) cost 100 ms; so on asyncio the same check is done with zero-length
    checkpoints: a task is blocked when it waits on a future that is not done
    (``Task._fut_waiter``).
    """
    loop = running_asyncio_loop()
    if loop is None:
        await anyio.wait_all_tasks_blocked()
        return
    asyncio = sys.modules["asyncio"]
    this_task = asyncio.current_task()
    await anyio.lowlevel.checkpoint()
    while True:
        for task in asyncio.all_tasks(loop):
            if task is this_task:
                continue
            waiter = getattr(task, "_fut_waiter", None)
            if waiter is None or waiter.done():
                break
        else:
            return
        await anyio.lowlevel.checkpoint()


# -- transports: a TCP connection read in the event loop's callback (ROS 1 TCPROS) ---------


_READ_SIZE = 65536
"""Bytes read per ``recv_into`` by a :class:`BufferedReadPump`."""



def _pump_class() -> type[Any]:
    """The :class:`BufferedReadPump` class, made on first use (it subclasses
    ``asyncio.BufferedProtocol``, and asyncio is loaded only for asyncio programs)."""
    global _PUMP
    if _PUMP is None:
        _PUMP = _make_pump_class()
    return _PUMP


_PUMP: type[Any] | None = None


def _make_pump_class() -> type[Any]:
    import asyncio

    class BufferedReadPump(asyncio.BufferedProtocol):
        """Feeds a connection's bytes to a :class:`FrameSplitter` from asyncio's read
        callback; the first error (or the end) is kept in ``error`` and sets ``events``.

        A buffered protocol: the loop reads into one buffer kept for the connection
        (``recv_into``), where a plain :class:`asyncio.Protocol` gets a new ``bytes`` per read
        that asyncio allocates at its ``max_size`` of 256 KiB and then shrinks (measured here:
        ~16 us more per read of a 4.6 kB message). Used by the ROS 1 transport's TCPROS
        subscriber connections (``tfbus/transports/ros1/transport.py``)."""

        def __init__(self, feed: Callable[[memoryview], None], *events: anyio.Event) -> None:
            self._feed = feed
            self._events = events
            self._buffer = memoryview(bytearray(_READ_SIZE))
            self._transport: asyncio.Transport | None = None
            self.error: BaseException | None = None

        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            self._transport = cast("asyncio.Transport", transport)

        def get_buffer(self, sizehint: int) -> memoryview:
            return self._buffer

        def buffer_updated(self, nbytes: int) -> None:
            if self.error is not None:
                return
            try:
                # A view, not a copy: the splitter reads it (and copies only an incomplete
                # frame) before the loop reads into the buffer again.
                self._feed(self._buffer[:nbytes])
            except Exception as exc:  # malformed input or a refusal: this connection only
                self._end(exc)
                if self._transport is not None:
                    self._transport.abort()

        def eof_received(self) -> bool:
            self._end(anyio.EndOfStream())
            return False

        def connection_lost(self, exc: Exception | None) -> None:
            self._end(exc if exc is not None else anyio.EndOfStream())

        def _end(self, exc: BaseException) -> None:
            if self.error is None:
                self.error = exc
            for event in self._events:
                event.set()

    return BufferedReadPump


async def open_pumped_connection(
    loop: AbstractEventLoop,
    host: str,
    port: int,
    feed: Callable[[memoryview], None],
    *events: anyio.Event,
) -> tuple[asyncio.Transport, Any]:
    """Connect to ``host:port`` with a :class:`BufferedReadPump` feeding ``feed`` from the
    loop's read callback (``loop.create_connection``); ``events`` are set when the
    connection ends or ``feed`` raises.

    Raises:
        OSError: the connection is refused or fails.
    """
    transport, pump = await loop.create_connection(
        lambda: _pump_class()(feed, *events), host, port
    )
    return transport, pump


def asyncio_transport_of(stream: object) -> Transport | None:
    """The ``asyncio.Transport`` that anyio's asyncio ``SocketStream`` writes to (its
    ``_transport``: ``send`` is ``transport.write`` and a checkpoint), or None for any
    other stream (trio's, a test's fake). Writing to it directly is ``send`` without the
    checkpoint, for a caller that keeps the order of what it writes itself. On uvloop the
    transport is uvloop's own (``uvloop.loop.TCPTransport``, not an ``asyncio.Transport``
    subclass, with the same ``write``, ``get_write_buffer_size`` and ``is_closing``).
    """
    asyncio = sys.modules.get("asyncio")
    transport: object = getattr(stream, "_transport", None)
    if asyncio is None or transport is None:
        return None
    if not isinstance(transport, asyncio.Transport) and _module_root(transport) != "uvloop":
        return None
    return cast("Transport", transport)


def _module_root(obj: object) -> str:
    """The top-level package of ``obj``'s class (``"uvloop"`` for uvloop's loop and
    transports)."""
    return type(obj).__module__.partition(".")[0]


# -- context managers: the body's exception leaves as itself -------------------------------


if sys.version_info < (3, 11):  # pragma: no cover - anyio depends on the backport there
    from exceptiongroup import BaseExceptionGroup  # type: ignore[import-not-found,unused-ignore]


async def exit_task_group(
    tg: anyio.abc.TaskGroup,
    exc_type: type[BaseException] | None,
    exc: BaseException | None,
    tb: TracebackType | None,
) -> bool | None:
    """Leave ``tg`` (cancelling what still runs in it) from a context manager's
    ``__aexit__`` so that what the ``async with`` body raised leaves as itself.

    anyio's and trio's task groups put the body's exception into a ``BaseExceptionGroup``
    with the failures of the group's tasks (PEP 654 "strict" groups), so ``except
    TimeoutException:`` around ``async with Bus():`` would miss a timeout raised inside.
    Here:

    * the body raised ``exc`` and no background task failed (the group holds only ``exc``
      and cancellations): ``exc`` is raised as itself, its traceback kept. A cancellation
      of the backend (``anyio.get_cancelled_exc_class()``), ``KeyboardInterrupt`` and
      ``SystemExit`` are re-raised the same way, so an enclosing cancel scope still sees
      its own cancellation;
    * the body raised ``exc`` and a background task failed too: ``exc`` is raised as
      itself, and the background failures are attached as its ``__context__`` (shown in
      its traceback as "During handling of the above exception ...");
    * the body ended normally, or was cancelled because a background task failed (the
      task group cancels its body then): the task group's ``BaseExceptionGroup`` of
      those failures propagates as anyio raises it.

    Returns:
        What the task group's ``__aexit__`` returned (never swallows ``exc``).

    Raises:
        BaseException: ``exc`` itself, or the group of background failures.
    """
    tg.cancel_scope.cancel()
    try:
        return await tg.__aexit__(exc_type, exc, tb)
    except BaseExceptionGroup as group:
        if exc is None:
            raise
        background = _background_failures(group, exc)
        if background is not None and isinstance(exc, anyio.get_cancelled_exc_class()):
            raise  # the body was cancelled because a task failed: the failure is the news
    # Raised outside the ``except`` block, so Python does not chain the group itself.
    if background is not None:
        exc.__context__ = background
    raise exc


def _background_failures(
    group: BaseExceptionGroup[BaseException], exc: BaseException
) -> BaseExceptionGroup[BaseException] | None:
    """The failures of ``group`` other than ``exc`` and the backend's cancellations, or
    None when there are none."""
    cancelled = anyio.get_cancelled_exc_class()
    rest = group.split(lambda e: e is exc)[1]
    if rest is None:
        return None
    return rest.split(cancelled)[1]


_R = TypeVar("_R")
_P = ParamSpec("_P")


class Awaiting(Coroutine[Any, Any, _R]):
    """What a :func:`coroutine_method` returns: its coroutine, awaitable as itself
    (``await buffer.transform(...)``, ``asyncio.create_task``, trio's ``start_soon`` and
    anyio's all take it: it is a :class:`collections.abc.Coroutine`), that names the
    missing ``await`` when used as the result.

    A tf2_ros user writes ``p2 = buffer.transform(p, "map")`` (tf2_ros's call blocks).
    Without ``await``, reading an attribute of the result (``p2.point``), testing its truth
    (``if buffer.can_transform_async(...)``), indexing or iterating it raises TypeError (an
    AttributeError for attributes, so ``hasattr`` and ``getattr(x, name, default)`` keep
    working) saying ``await`` is missing; collected without ever being awaited, it warns
    with that text (RuntimeWarning) in place of Python's "coroutine ... was never awaited".

    The cost: one object around the coroutine, a Python-level ``__await__`` and
    ``__del__``, about 0.5 µs of CPU per call and await; the waiting lookups
    (:class:`~tfbus.buffer.Buffer`) answer data already there without setting up a wait,
    so an awaited cached ``lookup_transform_async`` costs what it did before (about
    1.3 µs of CPU on the reference machine, asyncio and trio alike).
    """

    __slots__ = ("_awaited", "_call", "_coro")

    def __init__(self, coro: Coroutine[Any, Any, _R], call: str) -> None:
        self._coro = coro
        self._call = call
        self._awaited = False

    def _mistake(self, what: str) -> str:
        call = self._call
        owner, _, method = call.rpartition(".")
        name = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", owner).lower() or "obj"
        return (
            f"{call}(...) is a coroutine: write `await {name}.{method}(...)` ({what}); "
            "tf2_ros's blocking calls are tfbus.compat.tf2_ros's"
        )

    def __await__(self) -> Generator[Any, None, _R]:
        self._awaited = True
        return self._coro.__await__()

    def send(self, value: Any) -> Any:
        """:meth:`coroutine.send` (an event loop running this as a task)."""
        self._awaited = True
        return self._coro.send(value)

    def throw(self, *args: Any) -> Any:
        """:meth:`coroutine.throw`."""
        self._awaited = True
        return self._coro.throw(*args)

    def close(self) -> None:
        """:meth:`coroutine.close`: the call is dropped without a warning."""
        self._awaited = True
        self._coro.close()

    def __getattr__(self, name: str) -> NoReturn:
        raise AttributeError(
            self._mistake(f"the un-awaited call has no attribute {name!r}"), name=name, obj=self
        )

    def __bool__(self) -> NoReturn:
        raise TypeError(self._mistake("the un-awaited call has no truth value"))

    def __getitem__(self, key: object) -> NoReturn:
        raise TypeError(self._mistake("the un-awaited call cannot be indexed"))

    def __iter__(self) -> NoReturn:
        raise TypeError(self._mistake("the un-awaited call cannot be iterated"))

    def __repr__(self) -> str:
        state = "awaited" if self._awaited else "not awaited"
        return f"<Awaiting {self._call}(...), {state}>"

    def __del__(self) -> None:
        if not self._awaited:
            self._coro.close()  # no second warning, Python's, from the coroutine itself
            warnings.warn(self._mistake("it was never awaited"), RuntimeWarning, stacklevel=2)


def coroutine_method(
    fn: Callable[_P, Coroutine[Any, Any, _R]],
) -> Callable[_P, Awaiting[_R]]:
    """Decorate an ``async def`` method so that a call returns an :class:`Awaiting`
    named ``Class.method`` (the function's ``__qualname__``): awaited as before, and a
    clear TypeError or warning for the call that was not awaited. The signature and
    docstring are the function's (:func:`functools.wraps`); on Python 3.12+
    :func:`inspect.iscoroutinefunction` is True of it, as of the ``async def``."""
    call = fn.__qualname__

    @functools.wraps(fn)
    def method(*args: _P.args, **kwargs: _P.kwargs) -> Awaiting[_R]:
        return Awaiting(fn(*args, **kwargs), call)

    mark = getattr(inspect, "markcoroutinefunction", None)  # Python 3.12+
    return mark(method) if mark is not None else method
