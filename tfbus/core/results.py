"""What :class:`~tfbus.core.BufferCore` returns for its inserts (:class:`SetResult`,
:class:`BatchResult`), and the checks and caps it applies to its arguments and messages
(tf2 0.7.6 ``tf2/src/buffer_core.cpp``)."""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Iterator
from collections.abc import Set as AbstractSet
from numbers import Real
from typing import Final, NamedTuple

from tfbus.time import TIME_MAX_NS, Duration, Time

__all__ = [
    "MAX_MESSAGE",
    "BatchResult",
    "BufferStatistics",
    "SetResult",
    "TouchedFrames",
    "cache_time_ns",
    "cap_message",
    "not_a_time",
]

MAX_MESSAGE: Final = 999
"""tf2 0.7.6 caps extrapolation messages (only those) at this many characters (measured
with tf2_py)."""


class SetResult(enum.Enum):
    """What ``BufferCore.insert_transform`` did with a transform."""

    STORED = "stored"
    OLD_DATA = "TF_OLD_DATA"
    """Refused: older than the link's newest stamp minus ``cache_time``."""
    REPEATED_DATA = "TF_REPEATED_DATA"
    """Refused: the link already has a sample with this stamp (the first one wins)."""


class TouchedFrames(AbstractSet[str]):
    """The (stripped) frame ids of the transforms a batch stored: a read-only set
    (``collections.abc.Set``: ``in``, ``len``, iteration, comparisons and set operators
    with any set).

    The insert only records each stored transform's child and parent id (repeats
    included); the set is built from them the first time it is asked for. A listener
    whose batches nobody inspects (no pending waits) therefore never hashes a frame id for
    it: ``set_transforms`` does less work than a loop of ``set_transform``.

    Args:
        ids: frame ids, repeats allowed.
    """

    __slots__ = ("_ids",)

    _ids: list[str] | frozenset[str]  # the recorded ids, then the set once built

    def __init__(self, ids: Iterable[str] = ()) -> None:
        self._ids = list(ids)

    def _frozen(self) -> frozenset[str]:
        ids = self._ids
        if type(ids) is frozenset:
            return ids
        built = self._ids = frozenset(ids)
        return built

    def __contains__(self, frame_id: object) -> bool:
        return frame_id in self._frozen()

    def __iter__(self) -> Iterator[str]:
        return iter(self._frozen())

    def __len__(self) -> int:
        return len(self._frozen())

    def __bool__(self) -> bool:
        return bool(self._ids)  # no set needed: empty exactly when nothing was recorded

    def __hash__(self) -> int:
        return hash(self._frozen())

    def __repr__(self) -> str:
        return f"TouchedFrames({sorted(self._frozen())!r})"


class BufferStatistics(NamedTuple):
    """A snapshot of a buffer's counters (:meth:`BufferCore.statistics
    <tfbus.core.BufferCore.statistics>`)."""

    frames: int
    """Frame ids known now (children and parents)."""
    links: int
    """Links (child frames with a transform) stored now, static ones included."""
    frames_expired: int
    """Links removed by ``cache_policy=expire_after(...)`` since construction."""


class BatchResult(NamedTuple):
    """What :meth:`BufferCore.set_transforms` did with a batch of transforms."""

    stored: int
    """How many were stored."""
    refused: int
    """How many the caches refused (TF_OLD_DATA, TF_REPEATED_DATA; logged)."""
    errors: list[tuple[int, Exception]]
    """``(index in the batch, exception)`` for each item that was not stored because it
    is invalid (:class:`~tfbus.errors.InvalidArgumentException`: a tf2 rule broken, or a
    field of the wrong type) or is not a :class:`~tfbus.messages.TransformStamped`
    (TypeError)."""
    touched: AbstractSet[str] = frozenset()
    """The (stripped) child and parent frame ids of every stored transform: the frames
    whose lookups may have changed (a :class:`TouchedFrames`, built on first use).
    ``tfbus.buffer.Buffer`` rechecks its waits from it."""
    relinked: bool = False
    """Whether a stored transform may have changed the tree's shape (a new link, a link
    emptied by ``clear()`` refilled, or a link given another parent): which frames a
    lookup depends on (:meth:`BufferCore.chain_frames`) may have changed."""


def cap_message(message: str) -> str:
    """tf2 0.7.6 truncates extrapolation messages (only those) to 999 characters."""
    return message[:MAX_MESSAGE]


def cache_time_ns(value: object) -> int:
    """``cache_time`` (seconds or a Duration) as int nanoseconds, checked before use."""
    if isinstance(value, Duration):
        ns = value.ns
    elif isinstance(value, Real) and not isinstance(value, bool):
        seconds = float(value)
        if not math.isfinite(seconds) or not 0.0 <= seconds <= TIME_MAX_NS / 1e9:
            raise ValueError(
                "cache_time must be finite seconds in [0, 9.2e9] (int64 nanoseconds), "
                f"got {value!r}"
            )
        ns = Duration.from_sec(seconds).ns  # exact: the one seconds -> ns conversion
    else:
        raise TypeError(
            f"cache_time must be seconds (a real number) or a Duration, got {value!r}"
        )
    if not 0 <= ns <= TIME_MAX_NS:
        raise ValueError(f"cache_time must be in [0, 2**63 - 1] ns, got {ns} ns")
    return ns


def not_a_time(time: object, err: AttributeError) -> Exception:
    """The error for a lookup whose ``time`` is not a :class:`~tfbus.time.Time` (the
    compiled query reads ``time._ns``): a TypeError naming the argument."""
    if isinstance(time, Time):
        return err
    return TypeError(f"time must be a tfbus.Time (Time(0) for the latest data), not "
                     f"{type(time).__name__} {time!r}")
