"""Zenoh queryables and queries, bridged to the event loop by
:class:`~tfbus.transports._base.ThreadWakeup` -- the one home of tfbus's Zenoh queryables.

Zenoh calls a queryable's callback, and a query's reply callbacks, on its own threads.
Nothing here blocks those threads nor spends a worker thread per query:

* :class:`LoopQueryable` -- a queryable whose queries are handled on the event loop (the
  lookup server, :mod:`tfbus.transports.zenoh.lookups`): Zenoh's thread appends the query
  to a bounded queue and wakes the loop (one wake-up per burst); a loop task takes the
  queued queries in batches and hands each to the owner. A query that finds the queue
  full (``max_queued``) is refused at once, in Zenoh's thread, with the owner's error
  reply, and counted (:attr:`LoopQueryable.refused`); so are the queries still queued
  when the queryable ends. Other threads may queue notes for the loop beside the queries
  (:meth:`LoopQueryable.notify`; the lookup server's "this querier left").
* :func:`declare_answering_queryable` -- a queryable answered in Zenoh's thread from what
  the loop last stored (the transport's late-joiner latch: bytes published before; no
  loop involved, nothing to queue).
* :func:`get_replies` -- a Zenoh ``get`` whose replies come back through a
  :class:`~tfbus.transports._base.ThreadWakeup` of the calling task (Zenoh's reply and
  final callbacks, run in Zenoh's own thread by :func:`direct_callback`, append and
  wake; the task waits on a socket): no thread per pending query, cancellable (a
  cancelled task cancels the Zenoh query), bounded by the query's timeout.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections import deque
from collections.abc import Callable
from typing import Final, TypeVar

import anyio
import anyio.abc
import zenoh

from tfbus.errors import TransportError
from tfbus.transports._base import ThreadWakeup

__all__ = [
    "MAX_REPLIES",
    "LoopQueryable",
    "declare_answering_queryable",
    "direct_callback",
    "get_replies",
]

log = logging.getLogger("tfbus.transports.zenoh")

MAX_REPLIES: Final = 8
"""Most ok replies :func:`get_replies` keeps of one query (a ``BEST_MATCHING`` query is
answered by one queryable; more replies are counted out, never stored)."""
_GRACE: Final = 1.0
"""Wall seconds :func:`get_replies` waits past the query's timeout for Zenoh's final
callback before giving up on it."""

_T = TypeVar("_T")

Refuse = Callable[[zenoh.Query, str], None]
"""``refuse(query, message)``: the owner's error reply to a query it will not handle
(called in Zenoh's thread when the queue is full, on the loop when the queryable ends)."""


class LoopQueryable:
    """A Zenoh queryable on ``key`` whose queries ``handle(query)`` takes on the event
    loop (asyncio or trio), fed through one :class:`~tfbus.transports._base.ThreadWakeup`.

    ``handle`` owns the query it is given (it replies, now or from a task it starts, and
    finalizes it: ``with query:``); it must not raise. At most ``max_queued`` queries wait
    for the loop; a query that finds the queue full is answered at once, in Zenoh's
    thread, by ``refuse(query, message)`` and counted in :attr:`refused`. Notes queued by
    :meth:`notify` (at most ``max_queued``; when full the oldest is dropped) are given to
    ``noted(note)`` on the loop, in the order queued, after the queries queued before
    them.

    Run it as a task: ``await task_group.start(queryable.serve, session)``; cancelling
    that task undeclares the queryable and refuses the queries still queued
    (``"stopping"``).

    Args:
        key: the key expression answered.
        handle: called on the loop with each query.
        refuse: the error reply to a query not handled.
        max_queued: most queries (and notes) queued for the loop.
        noted: called on the loop with each note (None: notes are not expected).
        max_batch: most queries and notes taken per loop turn before other tasks run.

    Raises:
        ValueError: ``max_queued`` or ``max_batch`` below 1.
    """

    def __init__(
        self,
        key: str,
        handle: Callable[[zenoh.Query], None],
        refuse: Refuse,
        *,
        max_queued: int,
        noted: Callable[[str], None] | None = None,
        max_batch: int = 64,
    ) -> None:
        if max_queued < 1 or max_batch < 1:
            raise ValueError(
                f"max_queued and max_batch must be at least 1, got {max_queued!r}, {max_batch!r}"
            )
        self._key = key
        self._handle = handle
        self._refuse = refuse
        self._noted = noted
        self._max_queued = max_queued
        self._max_batch = max_batch
        self._lock = threading.Lock()  # Zenoh threads append, the loop takes
        self._queue: deque[zenoh.Query | str] = deque()
        self._queries = 0  # queries in the queue
        self._notes = 0  # notes in the queue
        self._open = False
        self._wakeup: ThreadWakeup | None = None
        self._received = 0
        self._refused = 0

    @property
    def key(self) -> str:
        """The key expression answered."""
        return self._key

    @property
    def received(self) -> int:
        """Queries Zenoh delivered so far (handled or refused)."""
        return self._received

    @property
    def refused(self) -> int:
        """Queries refused because the queue was full (``max_queued``)."""
        return self._refused

    @property
    def queued(self) -> int:
        """Queries waiting for the loop now."""
        return self._queries

    async def serve(
        self,
        session: zenoh.Session,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Declare the queryable on ``session``, report started, hand queries to
        ``handle`` until cancelled; then undeclare it and refuse what is still queued.

        Raises:
            RuntimeError: this queryable is already serving.
            TransportError: Zenoh refused the declaration (the ``ZError`` is the cause).
        """
        if self._wakeup is not None:
            raise RuntimeError(f"the queryable {self._key} is already serving")
        wakeup = self._wakeup = ThreadWakeup()
        self._open = True
        try:
            try:
                declared = session.declare_queryable(self._key, self._on_query)
            except zenoh.ZError as err:
                raise TransportError(f"cannot declare the queryable {self._key}: {err}") from err
            try:
                task_status.started()
                await wakeup.serve(self._drain)
            finally:
                with contextlib.suppress(Exception):  # the session may have closed
                    declared.undeclare()  # type: ignore[no-untyped-call]
        finally:
            with self._lock:
                self._open = False
                left = list(self._queue)
                self._queue.clear()
                self._queries = self._notes = 0
            for item in left:
                if not isinstance(item, str):
                    self._refuse_now(item, "stopping")
            self._wakeup = None
            wakeup.close()

    def notify(self, note: str) -> None:
        """Queue ``note`` for ``noted`` on the loop (any thread, never blocks; nothing
        while the queryable is not serving)."""
        with self._lock:
            if not self._open:
                return
            if self._notes >= self._max_queued:
                for i, item in enumerate(self._queue):  # the oldest note goes
                    if isinstance(item, str):
                        del self._queue[i]
                        self._notes -= 1
                        break
            self._queue.append(note)
            self._notes += 1
            wakeup = self._wakeup
        if wakeup is not None:
            wakeup.wake()

    # -- Zenoh threads --------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        with self._lock:
            self._received += 1
            refusal = (
                None if self._open and self._queries < self._max_queued
                else "stopping" if not self._open
                else f"{self._queries} queries queued (max_queued)"
            )
            if refusal is None:
                self._queue.append(query)
                self._queries += 1
                wakeup = self._wakeup
            elif self._open:
                self._refused += 1
        if refusal is not None:
            self._refuse_now(query, refusal)
            return
        if wakeup is not None:
            wakeup.wake()

    def _refuse_now(self, query: zenoh.Query, message: str) -> None:
        try:
            with query:
                self._refuse(query, message)
        except Exception as exc:  # a refusal never ends a Zenoh thread nor the loop
            log.debug("cannot refuse a query on %s: %r", self._key, exc)

    # -- event loop -----------------------------------------------------------------------

    def _drain(self, woken: bool) -> bool:
        """Hand up to ``max_batch`` queued queries and notes to their owner; True if
        more remain."""
        lock, queue = self._lock, self._queue
        for _ in range(self._max_batch):
            with lock:
                if not queue:
                    return False
                item = queue.popleft()
                if isinstance(item, str):
                    self._notes -= 1
                else:
                    self._queries -= 1
            if isinstance(item, str):
                if self._noted is not None:
                    self._noted(item)
            else:
                self._handle(item)
        return bool(queue)


def declare_answering_queryable(
    session: zenoh.Session,
    key: str,
    answer: Callable[[zenoh.Query], None],
    *,
    allowed_origin: zenoh.Locality = zenoh.Locality.ANY,
) -> zenoh.Queryable[None]:
    """Declare a queryable on ``key`` answered in Zenoh's thread by ``answer(query)``,
    which replies from data the loop stored before (one reference read: no lock, no
    wait) and must not block. The query is finalized after ``answer``; an error of
    ``answer`` is logged (debug) and the query finalized unanswered.

    Raises:
        zenoh.ZError: Zenoh refused the declaration.
    """

    def on_query(query: zenoh.Query) -> None:
        try:
            with query:
                answer(query)
        except Exception as exc:  # never end Zenoh's thread
            log.debug("cannot answer a query on %s: %r", key, exc)

    return session.declare_queryable(key, on_query, allowed_origin=allowed_origin)


def direct_callback(
    callback: Callable[[_T], None], drop: Callable[[], None] | None = None
) -> zenoh.handlers.Callback[_T]:
    """A Zenoh callback handler run in the Zenoh thread that received the item
    (``indirect=False``): zenoh-python otherwise runs each handler's callbacks in a
    Python thread of its own, one per pending query. ``callback`` and ``drop`` must be
    short and never block (append and wake). Falls back to the default handler on a
    zenoh-python without the (unstable) ``indirect`` flag."""
    handler: zenoh.handlers.Callback[_T]
    try:
        handler = zenoh.handlers.Callback(callback, drop, indirect=False)
    except TypeError:
        handler = zenoh.handlers.Callback(callback, drop)
    return handler


async def get_replies(
    session: zenoh.Session,
    key: str,
    payload: bytes,
    timeout: float,
    *,
    target: zenoh.QueryTarget = zenoh.QueryTarget.BEST_MATCHING,
    source_info: zenoh.SourceInfo | None = None,
    first: bool = True,
) -> list[bytes]:
    """A Zenoh ``get`` on ``key`` with ``payload``: the payloads of its ok replies (at
    most :data:`MAX_REPLIES`), waited for on the event loop through a
    :class:`~tfbus.transports._base.ThreadWakeup` (no worker thread).

    Returns at the first ok reply when ``first`` (a server answers once), else when
    Zenoh ends the query (every queryable answered, or ``timeout`` wall seconds passed);
    empty when nothing answered. A cancelled caller cancels the Zenoh query at once.

    Raises:
        TransportError: Zenoh refused the query (the ``ZError`` is the cause).
        ValueError: ``timeout`` is not positive finite seconds.
    """
    if not 0 < timeout < math.inf:
        raise ValueError(f"timeout must be positive finite seconds, got {timeout!r}")
    wakeup = ThreadWakeup()
    replies: list[bytes] = []
    done = threading.Event()
    cancel = zenoh.CancellationToken()

    def on_reply(reply: zenoh.Reply) -> None:  # a Zenoh thread
        sample = reply.ok
        if sample is not None and len(replies) < MAX_REPLIES:
            replies.append(sample.payload.to_bytes())
            if first:
                wakeup.wake()

    def on_done() -> None:  # a Zenoh thread, once the query has ended
        done.set()
        wakeup.wake()

    try:
        try:
            session.get(key, direct_callback(on_reply, on_done), payload=payload,
                        timeout=timeout, target=target, source_info=source_info,
                        cancellation_token=cancel)
        except zenoh.ZError as err:
            raise TransportError(f"query on {key} failed: {err}") from err
        with anyio.move_on_after(timeout + _GRACE):
            while not done.is_set() and not (first and replies):
                await wakeup.wait()
                wakeup.rearm()
        return list(replies)
    finally:
        with contextlib.suppress(Exception):  # ended already, or the session closed
            cancel.cancel()
        wakeup.close()
