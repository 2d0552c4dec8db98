"""Replaying a bag's tf messages onto a :class:`~tfbus.bus.Bus` at recorded timing.

Two clocks take part, as in ``rosbag play --clock``: the *pace* clock replay sleeps on to
keep the recorded spacing (wall time, :class:`~tfbus.clock.SystemClock`, by default;
tests pass a :class:`~tfbus.clock.ManualClock` and advance it), and an optional *bag-time*
``clock`` that replay moves to each message's bag time (the ``/clock`` topic's role), so
code awaiting on it sees the recording's time.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from os import PathLike
from typing import TYPE_CHECKING

from tfbus.bag.formats import DEFAULT_TOPICS, BagMessage
from tfbus.bag.reader import read_messages
from tfbus.time import Time

if TYPE_CHECKING:
    from tfbus.bus import Bus
    from tfbus.clock import Clock, ManualClock

__all__ = ["replay"]


async def replay(
    path: str | PathLike[str],
    bus: Bus,
    *,
    clock: ManualClock | None = None,
    rate: float | None = 1.0,
    start: Time | None = None,
    stop: Time | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
    on_message: Callable[[BagMessage], object] | None = None,
    pace_clock: Clock | None = None,
) -> int:
    """Publish a bag's tf messages on ``bus``, in order, at recorded timing times ``rate``.

    Before each message the bag-time ``clock`` (if given) is set to the message's bag
    time, so code awaiting on that clock (timers, ``Buffer`` timeouts) sees bag time, as
    ``rosbag play --clock`` does. Statics recorded before ``start`` are published first
    (latched).

    Pacing: the first message is published at once, at pace-clock time ``p0``; a message
    of bag time ``t`` is published when ``pace_clock.sleep_until`` reaches
    ``p0 + (t - t0) / rate``, where ``t0`` is ``start`` or else the first bag time
    (absolute deadlines, so delays do not accumulate; the schedule of ``rosbag play -r``).
    Statics latched from before ``start`` therefore go out at once.

    Args:
        path: the bag (see :func:`~tfbus.bag.read_messages`).
        bus: where to publish (``/tf`` and ``/tf_static`` carry TFMessage).
        clock: a ManualClock to drive to bag time; it must not be ahead of the first
            bag time (it is only ever moved forward).
        rate: speed factor (2.0 = twice as fast); ``None`` or ``0`` = as fast as possible
            (still yielding to other tasks after every message).
        start, stop: bag-time window (``start`` inclusive, ``stop`` exclusive).
        topics: topics to replay.
        on_message: called after each message is published (progress bars).
        pace_clock: the clock that paces the replay; default a new
            :class:`~tfbus.clock.SystemClock` (wall time). Unused when ``rate`` is
            ``None`` / ``0``.

    Returns:
        The number of messages published.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`~tfbus.bag.read_messages`.
        BagReadError: damaged bag, raised after everything readable was published.
        ValueError: a negative or non-finite ``rate``.
    """
    import anyio.lowlevel

    if rate is not None and not 0 <= rate < float("inf"):
        raise ValueError(f"rate must be a finite number >= 0, got {rate!r}")
    speed = rate or None
    pacer: Clock | None = None
    if speed is not None:
        if pace_clock is None:
            from tfbus.clock import SystemClock

            pace_clock = SystemClock()
        pacer = pace_clock
    t0_bag = t0_pace = 0
    n = 0
    for rec in read_messages(path, topics=topics, start=start, stop=stop):
        if pacer is not None and speed is not None:
            if n == 0:
                # Anchored at ``start``: statics latched from before it go out at once.
                t0_bag = rec.time.ns if start is None else max(rec.time.ns, start.ns)
                t0_pace = pacer.now().ns
            due = t0_pace + round((rec.time.ns - t0_bag) / speed)
            await pacer.sleep_until(Time.from_ns(max(due, 0)))
        if clock is not None and clock.now() < rec.time:
            await clock.set(rec.time)
        await bus.publish(rec.topic, rec.message)
        n += 1
        if on_message is not None:
            on_message(rec)
        if pacer is None:
            await anyio.lowlevel.checkpoint()
    return n
