"""Loading a bag into a :class:`~tfbus.core.BufferCore` for lookups."""

from __future__ import annotations

import gc
import logging
from collections import deque
from collections.abc import Callable, Collection, Iterable, Iterator
from os import PathLike
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from tfbus.bag.formats import DEFAULT_TOPICS, TF_STATIC_TOPIC, BagMessage
from tfbus.bag.reader import read_messages, read_window
from tfbus.errors import BagReadError
from tfbus.messages import TransformStamped
from tfbus.time import NSEC_PER_SEC, Duration, Time

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["Window", "iter_windows", "load_buffer"]

log = logging.getLogger(__name__)

def load_buffer(
    path: str | PathLike[str],
    *,
    cache_time: float | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
    errors: Literal["raise", "warn"] = "raise",
    start: Time | None = None,
    end: Time | None = None,
) -> BufferCore:
    """Load every ``/tf`` and ``/tf_static`` transform of a bag into a new BufferCore,
    or, with ``start`` / ``end``, a window of it.

    ``/tf_static`` transforms are stored with ``set_transform_static``, others with
    ``set_transform``; the authority is the publisher's caller id (ROS 1) or
    ``"Authority undetectable"`` (ROS 2).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        cache_time: cache length in seconds; default: the span of the recorded header
            stamps plus one second, so nothing is pruned and every sample can be looked up.
        topics: topics to read (default ``/tf`` and ``/tf_static``).
        errors: on a truncated / corrupt bag, ``"raise"`` raises :class:`BagReadError`
            whose ``partial`` holds the buffer with everything readable; ``"warn"`` logs a
            warning and returns that buffer.
        start, end: a window of bag time ``[start, end)``: only the ``/tf`` messages
            received in it are loaded, read through the format's index
            (:func:`~tfbus.bag.reader.read_window`: only that part of the file is read
            and held), plus every ``/tf_static`` transform of the whole file (statics
            recorded once at the start are still there for a window in the middle).
            ``None``: from the beginning / to the end. Bag time is receive time: a
            lookup at a header stamp near the window's edge needs a window a little
            wider than the stamps asked (a margin of the links' longest gap).

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
        BagReadError: truncated or corrupt bag (``errors="raise"``).
        ValueError: ``end`` is before ``start``.
    """
    from tfbus.core import BufferCore

    statics: list[tuple[TransformStamped, str]] = []
    dynamics: list[tuple[list[TransformStamped], str]] = []
    lo_ns = hi_ns = None
    problem: BagReadError | None = None
    # Millions of small immutable objects and no cycles: the cyclic GC would rescan the
    # growing heap again and again (it tripled the load time), so pause it meanwhile.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    if start is None and end is None:
        records: Iterable[BagMessage] = read_messages(path, topics=topics)
    else:
        records = read_window(path, start=start, end=end, topics=topics)
    try:
        for rec in records:
            ts_list = list(rec.message.transforms)
            if rec.topic == TF_STATIC_TOPIC:
                statics.extend((ts, rec.authority) for ts in ts_list)
            elif ts_list:
                dynamics.append((ts_list, rec.authority))
                for ts in ts_list:
                    ns = ts.header.stamp.ns
                    if lo_ns is None or ns < lo_ns:
                        lo_ns = ns
                    if hi_ns is None or ns > hi_ns:
                        hi_ns = ns
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    except BagReadError as err:
        problem = err
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    finally:
        if gc_was_enabled:
            gc.enable()
    if problem is not None:
        problem.partial = core
        if errors == "raise":
            raise problem
        log.warning("%s", problem)
    return core


def _fill(
    core: BufferCore,
    statics: list[tuple[TransformStamped, str]],
    dynamics: list[tuple[list[TransformStamped], str]],
) -> None:
    from tfbus.errors import TransformException

    set_static = core.set_transform_static
    set_dynamic = core.set_transform
    bad = 0
    for ts, auth in statics:
        try:
            set_static(ts, auth)
        except TransformException:
            bad += 1
    for ts_list, auth in dynamics:
        for ts in ts_list:
            try:
                set_dynamic(ts, auth)
            except TransformException:
                bad += 1
    if bad:
        log.warning("%d invalid transform(s) in the bag were skipped", bad)



class Window(NamedTuple):
    """One window of :func:`iter_windows`.

    Attributes:
        start: first bag time of the window (inclusive).
        end: bag time it ends at (exclusive).
        buffer: a BufferCore with every static transform of the file and the ``/tf``
            messages received in ``[start - margin, end + margin)``.
        messages: how many ``/tf`` messages were received in ``[start, end)``.
        last: the bag time of the last of them.
        stamps: the header stamps of their transforms, ``(M,) int64`` nanoseconds,
            sorted, each once, stamp 0 (no time) left out: the data's own clock
            (simulated time when the recording's is), which the bag (receive) time of
            ``start`` / ``end`` is not.
    """

    start: Time
    end: Time
    buffer: BufferCore
    messages: int
    last: Time
    stamps: npt.NDArray[np.int64]


def iter_windows(
    path: str | PathLike[str],
    width: float | Duration,
    *,
    margin: float | Duration = 1.0,
    start: Time | None = None,
    end: Time | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
) -> Iterator[Window]:
    """Walk a bag window by window in one pass, each window a BufferCore of its own.

    Window k covers bag time ``[t0 + k * width, t0 + (k + 1) * width)`` (``t0``: ``start``,
    or the first ``/tf`` message's bag time). Its buffer holds every ``/tf_static``
    transform of the whole file and the ``/tf`` messages received from ``margin`` before
    the window to ``margin`` after it, so a lookup at a stamp inside the window can
    interpolate across its edges. The file is read once, in bag-time order; the messages
    of the overlap are carried over from one window to the next, not read again, and no
    more than one window plus two margins of messages is held. Windows in which no
    ``/tf`` message was received are skipped.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        width: window length, seconds (> 0) or a Duration.
        margin: how far each window's buffer reaches beyond it on both sides, seconds
            (>= 0) or a Duration: at least the links' longest gap between samples plus
            the largest header-stamp-to-receive delay, for lookups near the edges.
        start, end: bag times to walk from (inclusive) and to (exclusive).
        topics: topics to read (default ``/tf`` and ``/tf_static``).

    Yields:
        :class:`Window` (start, end, buffer, number of messages in the window).

    Raises:
        ValueError: ``width`` is not positive, ``margin`` is negative.
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
        BagReadError: a truncated or corrupt bag, after the windows of everything
            readable before the damage were yielded.
    """
    width_ns = _span_ns(width, "width")
    margin_ns = _span_ns(margin, "margin")
    if width_ns <= 0:
        raise ValueError(f"width must be > 0 s, got {width!r}")
    wanted = frozenset(topics)
    statics: list[tuple[TransformStamped, str]] = []
    problems: list[BagReadError] = []
    if TF_STATIC_TOPIC in wanted:
        try:
            for rec in read_messages(path, topics=(TF_STATIC_TOPIC,)):
                statics.extend((ts, rec.authority) for ts in rec.message.transforms)
        except BagReadError as err:
            problems.append(err)  # the statics before the damage are kept
    dynamic = wanted - {TF_STATIC_TOPIC}
    if not dynamic:
        if problems:
            raise problems[0]
        return
    lo = None if start is None else Time.from_ns(max(0, start.ns - margin_ns))
    hi = None if end is None else Time.from_ns(end.ns + margin_ns)
    source = iter(read_messages(path, topics=dynamic, start=lo, stop=hi, latched=False))

    def pull() -> tuple[int, list[TransformStamped], str] | None:
        try:
            rec = next(source, None)
        except BagReadError as err:
            # Damage: the windows read so far are still walked, then the error raised.
            problems.append(err)
            return None
        return None if rec is None else (rec.time.ns, list(rec.message.transforms),
                                         rec.authority)

    yield from _walk(pull, statics, width_ns, margin_ns, start, end)
    if problems:
        raise problems[-1]


def _walk(
    pull: Callable[[], tuple[int, list[TransformStamped], str] | None],
    statics: list[tuple[TransformStamped, str]],
    width_ns: int,
    margin_ns: int,
    start: Time | None,
    end: Time | None,
) -> Iterator[Window]:
    """:func:`iter_windows`' walk over the ``/tf`` messages ``pull`` returns in bag-time
    order (None at the end)."""
    from tfbus.core import BufferCore

    held: deque[tuple[int, list[TransformStamped], str]] = deque()
    ahead = pull()
    if ahead is None:
        return
    w0 = ahead[0] if start is None else start.ns
    while True:
        w1 = w0 + width_ns
        if end is not None and w0 >= end.ns:
            return
        while ahead is not None and ahead[0] < w1 + margin_ns:
            held.append(ahead)
            ahead = pull()
        while held and held[0][0] < w0 - margin_ns:
            held.popleft()
        own = [(ns, tss) for ns, tss, _ in held if w0 <= ns < w1]  # received in the window
        if own:
            stamps = [ts.header.stamp.ns for _, tss, _ in held for ts in tss]
            span = (max(stamps) - min(stamps)) / NSEC_PER_SEC if stamps else 0.0
            core = BufferCore(cache_time=max(10.0, span + 1.0))
            _fill(core, statics, [(tss, auth) for _, tss, auth in held])
            own_stamps = np.unique(np.fromiter(
                (ts.header.stamp.ns for _, tss in own for ts in tss), dtype=np.int64))
            yield Window(Time.from_ns(w0), Time.from_ns(w1), core, len(own),
                         Time.from_ns(max(ns for ns, _ in own)), own_stamps[own_stamps != 0])
        later = [ns for ns, _, _ in held if ns >= w1]
        following = min(later) if later else (None if ahead is None else ahead[0])
        if following is None:
            return
        # The next window that receives a message (empty windows are skipped).
        w0 = w1 + (following - w1) // width_ns * width_ns


def _span_ns(value: float | Duration, name: str) -> int:
    """Seconds or a Duration as int ns; ValueError naming ``name`` for a negative,
    infinite or non-numeric value."""
    if isinstance(value, Duration):
        ns = value.ns
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        if value != value or value in (float("inf"), float("-inf")):
            raise ValueError(f"{name} must be a finite number of seconds, got {value!r}")
        ns = round(value * NSEC_PER_SEC)
    else:
        raise ValueError(f"{name} must be seconds or a Duration, got {value!r}")
    if ns < 0:
        raise ValueError(f"{name} must be >= 0 s, got {value!r}")
    return int(ns)
