"""MessageFilter: hold stamped messages until they can be transformed (tf2_ros).

``MessageFilter(buffer, target_frames, source)`` reads messages with a ``header``
(``frame_id``, ``stamp``) from ``source`` — a bus :class:`~tfbus.bus.Subscription` or any
async iterable — and yields each one, under ``async for``, once the buffer can transform
its ``header.frame_id`` into every target frame at its stamp (and at ``stamp +
tolerance`` when a tolerance is set, as tf2_ros requests both). The semantics are
tf2_ros's ``MessageFilter`` (``tf2_ros/message_filter.h``, ROS 1 0.7.x / ROS 2):

* a message whose transforms are already available passes at once;
* otherwise it is queued and released the moment the missing transform arrives: the
  wait is event-driven, on :meth:`~tfbus.buffer.Buffer.wait_for_transform` (the buffer's
  waiter index), never polled; messages released by the same insert come out in the
  order they arrived;
* failures are counted in :meth:`MessageFilter.statistics` and reported to the optional
  ``on_failure(message, reason)`` callback with tf2_ros's reasons
  (:class:`FilterFailureReason`): an empty ``frame_id``; "out the back" — the stamp is
  older than the cache can ever answer (``stamp + cache_time`` before the latest common
  time of the frames, tf2's ``addTransformableRequest`` test), decided on arrival; a
  transform failure — a queued message whose time fell out of the cache window while
  it waited; a full queue — the oldest queued message is dropped to make room; and
  (tfbus's) a malformed message — no header, a frame id that is not a str, a stamp
  that is not a Time: one bad message never ends the filter.

Target frames can be changed while running (:meth:`MessageFilter.set_target_frames`):
new messages use the new frames and every queued message is re-evaluated against them.
Ready messages not yet taken by the consumer are held (at most ``queue_size`` of them;
the reader then stops reading ``source`` until there is room: back-pressure, so a bus
subscription's own bounded queue does the dropping).
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import AsyncIterable, AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Generic, Protocol, TypeVar

import anyio
import anyio.abc

from tfbus._aio import exit_task_group
from tfbus.buffer import Buffer
from tfbus.core.policy import Exact, LookupPolicy, policy_args
from tfbus.errors import BackwardExtrapolationException, TransformException
from tfbus.messages import Header
from tfbus.time import Duration, Time

__all__ = [
    "FilterFailureReason",
    "MessageFilter",
    "MessageFilterStatistics",
    "Stamped",
]


_NO_TOLERANCE = Duration(0)


class Stamped(Protocol):
    """Anything with a std_msgs ``header`` (frame_id, stamp)."""

    @property
    def header(self) -> Header: ...


M = TypeVar("M", bound=Stamped)


class FilterFailureReason(enum.Enum):
    """Why a message was dropped (tf2_ros ``filter_failure_reasons``; ROS 2's names).

    ``MALFORMED`` is tfbus's: a message whose header cannot be used (no ``header``, a
    ``frame_id`` that is not a str, a ``stamp`` that is not a Time, ``stamp + tolerance``
    beyond int64 nanoseconds) -- tf2_ros's typed messages cannot be built so. It is
    dropped and counted like the others; the filter goes on.
    """

    EMPTY_FRAME_ID = "empty frame id"
    OUT_THE_BACK = "out the back"
    TRANSFORM_FAILURE = "transform failure"
    QUEUE_FULL = "queue full"
    MALFORMED = "malformed message"


@dataclass(frozen=True)
class MessageFilterStatistics:
    """Counters of one MessageFilter (a snapshot).

    ``incoming == passed + dropped_total + queued + ready`` at all times.

    Attributes:
        incoming: messages read from the source.
        passed: messages yielded to the consumer.
        queued: messages waiting for a transform now.
        ready: messages transformable and not yet taken by the consumer.
        dropped: count per :class:`FilterFailureReason`.
    """

    incoming: int
    passed: int
    queued: int
    ready: int
    dropped: dict[FilterFailureReason, int]

    @property
    def dropped_total(self) -> int:
        """All dropped messages."""
        return sum(self.dropped.values())


class _Entry(Generic[M]):
    __slots__ = ("frame", "msg", "ready", "scope", "stamp")

    def __init__(self, msg: M, frame: str, stamp: Time) -> None:
        self.msg = msg
        self.frame = frame
        self.stamp = stamp
        self.ready = False
        self.scope: anyio.CancelScope | None = None


def _strip(frame: str) -> str:
    return frame[1:] if frame.startswith("/") else frame


class MessageFilter(Generic[M]):
    """Yield messages once they can be transformed (tf2_ros ``MessageFilter``).

    Args:
        buffer: the :class:`~tfbus.buffer.Buffer` transforms come from (fed by a
            TransformListener or by hand).
        target_frames: one frame id or several; a message passes once it can be
            transformed into all of them.
        source: async iterable of messages with ``header.frame_id`` and
            ``header.stamp`` (a bus Subscription, a memory stream, a generator).
        queue_size: how many messages may wait for transforms (0: unbounded); the
            oldest is dropped as QUEUE_FULL beyond it. Also bounds the ready messages
            held for the consumer. Default 10.
        tolerance: also require the transforms at ``stamp + tolerance`` (e.g. a scan's
            sweep time, so every beam can be transformed). Default 0.
        on_failure: called as ``on_failure(message, reason)`` for every dropped message.
        fail_fast: drop a message at once, not keep it queued, when a transform it needs
            can never come (:meth:`Buffer.wait_for_transform
            <tfbus.buffer.Buffer.wait_for_transform>`'s ``fail_fast``): its stamp is
            older than the oldest stamp a link of the path can still accept (its newest
            stamp minus ``cache_time``) — OUT_THE_BACK on arrival — or its frame and a
            target frame are known and in different trees — TRANSFORM_FAILURE; a queued
            message that becomes so is dropped as TRANSFORM_FAILURE by the insert that
            shows it. False (default) is tf2_ros's behaviour.
        policy: a lookup policy (:mod:`tfbus.core.policy`): a message passes once every
            transform it needs can be looked up under it (``Buffer.can_transform(...,
            policy=policy)``; its waits are ``wait_for_transform(..., policy=policy)``,
            a ``Window``'s bounded by ``future_wait``: a message whose wait ends without
            an answer is dropped as TRANSFORM_FAILURE). Look the transforms up with the
            same policy. None or ``Exact()`` (default): tf2's rule.

    Use as ``async with MessageFilter(...) as mf: async for msg in mf: ...``; leaving
    the ``async with`` stops reading the source and cancels every wait. Iteration ends
    when the source is exhausted and no message is left waiting or ready.

    Raises:
        ValueError: ``queue_size`` < 0, a negative tolerance, or no target frame.
        TypeError: ``policy`` is not a lookup policy.
    """

    def __init__(
        self,
        buffer: Buffer,
        target_frames: str | Sequence[str],
        source: AsyncIterable[M],
        *,
        queue_size: int = 10,
        tolerance: Duration = _NO_TOLERANCE,
        on_failure: Callable[[M, FilterFailureReason], None] | None = None,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> None:
        if policy is not None:
            policy_args(policy)  # a TypeError for anything else
        if queue_size < 0:
            raise ValueError(f"queue_size must be >= 0, got {queue_size}")
        if tolerance.ns < 0:
            raise ValueError(f"tolerance must be >= 0, got {tolerance!r}")
        self._buffer = buffer
        self._targets = self._check_targets(target_frames)
        self._source = source
        self._queue_size = queue_size
        self._tolerance = tolerance
        self._on_failure = on_failure
        self._fail_fast = fail_fast
        self._policy = policy if type(policy) is not Exact else None
        self._pending: deque[_Entry[M]] = deque()  # arrival order, waiting or ready
        self._n_waiting = 0
        self._n_ready = 0
        self._changed = anyio.Event()  # something became ready / the source ended
        self._room = anyio.Event()  # the consumer took a message
        self._source_done = False
        self._source_error: BaseException | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._incoming = 0
        self._passed = 0
        self._dropped = dict.fromkeys(FilterFailureReason, 0)

    @staticmethod
    def _check_targets(target_frames: str | Sequence[str]) -> tuple[str, ...]:
        frames = (target_frames,) if isinstance(target_frames, str) else tuple(target_frames)
        if not frames:
            raise ValueError("target_frames must name at least one frame")
        for f in frames:
            if not isinstance(f, str) or not _strip(f):
                raise ValueError(f"target frame ids must be non-empty strings, got {f!r}")
        return tuple(_strip(f) for f in frames)

    # ------------------------------------------------------------------ lifecycle

    async def __aenter__(self) -> MessageFilter[M]:
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        self._tg.start_soon(self._read)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        """Stop reading the source. What the ``async with`` body raised leaves as itself
        (:func:`tfbus._aio.exit_task_group`)."""
        assert self._tg is not None
        try:
            return await exit_task_group(self._tg, exc_type, exc, tb)
        finally:
            self._tg = None

    @property
    def target_frames(self) -> tuple[str, ...]:
        """The current target frames."""
        return self._targets

    def set_target_frames(self, target_frames: str | Sequence[str]) -> None:
        """Change the target frames (tf2_ros ``setTargetFrames``): new messages use them
        and every queued message is re-evaluated against them now.

        Raises:
            ValueError: no frame, or an empty frame id.
        """
        self._targets = self._check_targets(target_frames)
        for entry in list(self._pending):
            if not entry.ready:
                if entry.scope is not None:
                    entry.scope.cancel()
                    entry.scope = None
                self._n_waiting -= 1
                self._pending.remove(entry)
                self._admit(entry)

    def statistics(self) -> MessageFilterStatistics:
        """A snapshot of the counters."""
        return MessageFilterStatistics(
            incoming=self._incoming,
            passed=self._passed,
            queued=self._n_waiting,
            ready=self._n_ready,
            dropped=dict(self._dropped),
        )

    # ------------------------------------------------------------------ input side

    async def _read(self) -> None:
        try:
            async for msg in self._source:
                self.add(msg)
                while self._queue_size and self._n_ready >= self._queue_size:
                    self._room = anyio.Event()
                    await self._room.wait()
        except Exception as exc:  # surfaced to the consumer
            self._source_error = exc
        finally:
            self._source_done = True
            self._changed.set()

    def add(self, msg: M) -> None:
        """Offer one message (what the reader does for each message of ``source``; also
        usable directly, tf2_ros ``MessageFilter::add``)."""
        self._incoming += 1
        try:
            header = msg.header
            frame_id, stamp = header.frame_id, header.stamp
            if not (isinstance(frame_id, str) and isinstance(stamp, Time)):
                raise TypeError(frame_id, stamp)
            self._times(stamp)  # stamp + tolerance must be a Time too
        except (AttributeError, TypeError, ValueError, OverflowError):
            self._drop(msg, FilterFailureReason.MALFORMED)
            return
        frame = _strip(frame_id)
        if not frame:
            self._drop(msg, FilterFailureReason.EMPTY_FRAME_ID)
            return
        self._admit(_Entry(msg, frame, stamp))

    def _times(self, stamp: Time) -> tuple[Time, ...]:
        if self._tolerance.ns:
            return (stamp, stamp + self._tolerance)
        return (stamp,)

    def _admit(self, entry: _Entry[M]) -> None:
        buf = self._buffer
        ready = True
        for target in self._targets:
            for t in self._times(entry.stamp):
                if buf.can_transform(target, entry.frame, t, policy=self._policy):
                    continue
                if self._out_the_back(target, entry.frame, t):
                    self._drop(entry.msg, FilterFailureReason.OUT_THE_BACK)
                    return
                if self._fail_fast:
                    found = buf.check_transform(target, entry.frame, t, fail_fast=True)
                    if isinstance(found, TransformException):
                        self._drop(
                            entry.msg,
                            FilterFailureReason.OUT_THE_BACK
                            if isinstance(found, BackwardExtrapolationException)
                            else FilterFailureReason.TRANSFORM_FAILURE,
                        )
                        return
                ready = False
        entry.ready = ready
        if ready:
            self._n_ready += 1
            self._changed.set()
        else:
            if self._queue_size and self._n_waiting + 1 > self._queue_size:
                oldest = next(e for e in self._pending if not e.ready)
                self._pending.remove(oldest)
                self._n_waiting -= 1
                if oldest.scope is not None:
                    oldest.scope.cancel()
                    oldest.scope = None
                self._drop(oldest.msg, FilterFailureReason.QUEUE_FULL)
            self._n_waiting += 1
            if self._tg is None:
                raise RuntimeError("MessageFilter.add() needs the filter entered (async with)")
            entry.scope = anyio.CancelScope()
            self._tg.start_soon(self._wait, entry, entry.scope)
        self._pending.append(entry)

    def _out_the_back(self, target: str, source: str, t: Time) -> bool:
        """tf2 ``addTransformableRequest``: never transformable when ``t + cache_time``
        is before the latest common time of the two frames."""
        if t.ns == 0:
            return False
        try:
            latest = self._buffer.get_latest_common_time(target, source).ns
        except TransformException:
            return False
        return latest != 0 and t.ns + self._buffer.cache_time.ns < latest

    async def _wait(self, entry: _Entry[M], scope: anyio.CancelScope) -> None:
        with scope:
            try:
                for target in self._targets:
                    for t in self._times(entry.stamp):
                        await self._buffer.wait_for_transform(
                            target, entry.frame, t, fail_fast=self._fail_fast,
                            policy=self._policy,
                        )
            except TransformException:
                if entry.scope is scope and entry in self._pending:
                    self._pending.remove(entry)
                    self._n_waiting -= 1
                    self._drop(entry.msg, FilterFailureReason.TRANSFORM_FAILURE)
                return
            if entry.scope is not scope:  # dropped or re-admitted meanwhile
                return
            entry.ready = True
            entry.scope = None
            self._n_waiting -= 1
            self._n_ready += 1
            # The consumer takes ready messages in arrival order when it next runs: by
            # then every wait released by the same insert has been marked (on trio the
            # woken tasks of one batch run in any order).
            self._changed.set()

    def _pop_ready(self) -> M:
        pending = self._pending
        if pending[0].ready:
            entry = pending.popleft()
        else:
            entry = next(e for e in pending if e.ready)
            pending.remove(entry)
        self._n_ready -= 1
        return entry.msg

    def _drop(self, msg: M, reason: FilterFailureReason) -> None:
        self._dropped[reason] += 1
        if self._on_failure is not None:
            self._on_failure(msg, reason)

    # ------------------------------------------------------------------ output side

    def __aiter__(self) -> AsyncIterator[M]:
        return self

    async def __anext__(self) -> M:
        while True:
            if self._n_ready:
                msg = self._pop_ready()
                self._passed += 1
                self._room.set()
                return msg
            if self._source_done and not self._pending:
                if self._source_error is not None:
                    error, self._source_error = self._source_error, None
                    raise error
                raise StopAsyncIteration
            if self._tg is None:
                raise RuntimeError("iterate a MessageFilter inside its async with block")
            self._changed = anyio.Event()
            await self._changed.wait()

    def __repr__(self) -> str:
        s = self.statistics()
        return (
            f"<MessageFilter targets={list(self._targets)} queued={s.queued} "
            f"ready={s.ready} passed={s.passed} dropped={s.dropped_total}>"
        )
