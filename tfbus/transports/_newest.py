"""A clock topic followed newest-only in a transport's receiving thread.

The ROS 1 and ROS 2 transports both keep ``rosgraph_msgs/Clock`` newest-only for a
:class:`~tfbus.clock.SimClock` (as rclpy subscribes to ``/clock`` keep-last 1,
``rclpy/time_source.py``): the thread that receives the samples (Cyclone's listener; the
ROS 1 clock connection's reader) decodes each one, keeps only the newest and queues it
for the event loop only when a follower needs it (:class:`NewestClock`); the follower
reads the newest stamp kept as its time (:class:`ClockFollower`). The Zenoh transport has
its own (:class:`tfbus.transports.zenoh.transport.NewestOnly`, which keeps wire bytes).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Final, Protocol

from tfbus.messages import Clock
from tfbus.transports._base import heard_beyond

NEWEST_MAX_DELAY: Final = 0.01
"""Longest wall time, seconds, a clock sample followed newest-only waits in the receiving
thread (every transport's: Zenoh's, Cyclone's, a ROS 1 clock connection's) while newer
ones arrive, when the bus has listeners on the clock topic besides its followers (a
subscriber of ``/clock`` beside a :class:`~tfbus.clock.SimClock`): they receive the
newest at least this often while ``/clock`` flows. The followers read the newest stamp
kept (:attr:`ClockFollower.newest_ns`) and need no such delivery."""
NEWEST_MAX_QUEUED: Final = 1024
"""Most clock samples followed newest-only that wait for the event loop at once (each
step back queues one, however fast a publisher steps back and however long the loop is
busy); beyond it the oldest are dropped and counted in ``coalesced``, as the Zenoh
transport bounds its inbound queue."""


def any_due(dues: tuple[Callable[[int], bool], ...], ns: int) -> bool:
    """Whether one of the followers' ``dues`` says the sample of stamp ``ns`` (int
    nanoseconds) must reach the event loop now (asked in order, the first yes ends it;
    a loop, not ``any()`` over a generator: this runs for every sample)."""
    for due in dues:  # noqa: SIM110  (no generator per sample)
        if due(ns):
            return True
    return False


class CoalescedCounter(Protocol):
    """The transport's counters, as :meth:`NewestClock.offer` counts into them."""

    coalesced: int


class NewestClock:
    """A clock topic followed newest-only: the receiving thread offers each decoded
    sample (:meth:`offer`), which keeps only the newest and queues it for the event loop
    (waking it) when a follower says it is due, when it steps back (the one kept before
    it is queued first), or :data:`NEWEST_MAX_DELAY` after the last wake-up while
    :attr:`bus` has other listeners on :attr:`topic`
    (:func:`~tfbus.transports._base.heard_beyond`). :attr:`kept_ns` is the
    stamp the followers read as the time meanwhile. Every access but the followers' read
    of :attr:`kept_ns` holds ``lock``."""

    __slots__ = ("bus", "dues", "kept", "kept_ns", "last_ns", "lock", "queue", "taken",
                 "topic", "waked")

    def __init__(self) -> None:
        self.dues: tuple[Callable[[int], bool], ...] = ()
        self.lock = threading.Lock()
        self.kept: Clock | None = None  # the newest sample not queued yet
        self.last_ns = -1  # the stamp of the last sample, -1 before one
        self.waked = 0.0  # time.monotonic() of the last wake-up (or listeners check)
        self.queue: list[Clock] = []  # for the event loop, in order
        self.taken = 0  # samples received by the thread not yet counted by the loop
        self.bus: object = None
        """The bus the transport runs under (None when it does not run): whether it has
        listeners on :attr:`topic` besides the followers."""
        self.topic = ""
        """The clock topic, as the bus names it."""
        self.kept_ns = -1
        """The newest stamp (ns) of a sample kept because no follower needed it yet: a
        step forward from every sample before it, within every follower's bounds, so a
        follower may read it as the time; -1 before one and after a jump back the loop
        delivered (:meth:`ClockFollower.stepped_back`). Raised only here."""

    def offer(self, message: Clock, stats: CoalescedCounter) -> bool:
        """A decoded sample (``lock`` held): kept, or queued; True if the loop must wake.
        With no follower every sample is queued (and the loop woken)."""
        ns = message.clock._ns  # Time.ns, without the property's call
        pending, self.kept = self.kept, message  # stored before ``due`` reads
        now = time.monotonic()
        back = ns < self.last_ns
        self.last_ns = ns
        # any_due inline for the one follower a topic has but with several SimClocks
        dues = self.dues
        wake = back or not dues or (dues[0](ns) if len(dues) == 1 else any_due(dues, ns))
        if not wake and now - self.waked >= NEWEST_MAX_DELAY:
            self.waked = now  # the bus's listeners are counted at most this often
            wake = heard_beyond(self.bus, self.topic, len(self.dues))
        if wake:
            self.kept = None
            self.waked = now
            if pending is not None:
                if back:
                    self.queue.append(pending)
                else:
                    stats.coalesced += 1
            queue = self.queue
            queue.append(message)
            if len(queue) > NEWEST_MAX_QUEUED:  # the oldest go: memory stays bounded
                stats.coalesced += len(queue) - NEWEST_MAX_QUEUED
                del queue[: len(queue) - NEWEST_MAX_QUEUED]
            return True
        if ns > self.kept_ns:
            self.kept_ns = ns
        if pending is not None:
            stats.coalesced += 1
        return False

    def take_all(self) -> list[Clock]:
        """The queued samples and the one kept, in order, removed (``lock`` held)."""
        out, self.queue = self.queue, []
        if self.kept is not None:
            out.append(self.kept)
            self.kept = None
        return out

    def follow(self, due: Callable[[int], bool]) -> None:
        """Add a follower's ``due`` (a stamp kept for followers gone is no time of a
        first new one)."""
        with self.lock:
            if not self.dues:
                self.kept_ns = -1
            self.dues = (*self.dues, due)

    def unfollow(self, due: Callable[[int], bool]) -> None:
        """Remove a follower's ``due``."""
        with self.lock:
            dues = list(self.dues)
            if due in dues:
                dues.remove(due)
            self.dues = tuple(dues)


class ClockFollower:
    """One follower of a clock topic kept newest-only (what a transport's
    ``keep_newest`` returns; inert, with no :class:`NewestClock`, for a topic that is not
    the transport's clock topic).

    Args:
        newest: the topic's keeper, or None (inert).
        wake: wakes the event loop to deliver what the keeper holds (any thread).
        due: the follower's ``due(stamp_ns)``.
    """

    __slots__ = ("_due", "_newest", "_wake")

    def __init__(self, newest: NewestClock | None, wake: Callable[[], None],
                 due: Callable[[int], bool]) -> None:
        self._newest = newest
        self._wake = wake
        self._due = due

    @property
    def newest_ns(self) -> int:
        """The stamp (ns) of the newest clock sample the receiving thread kept for no
        follower's need yet: a time the follower may read as now; -1 when there is none
        (or once closed, or inert)."""
        newest = self._newest
        return -1 if newest is None else newest.kept_ns

    def stepped_back(self) -> None:
        """The follower took a jump back: the stamps kept before it are no longer the
        time."""
        if self._newest is not None:
            self._newest.kept_ns = -1

    def poke(self) -> None:
        """Deliver the sample kept, if any, at the event loop's next turn (call it when
        filing a deadline: a sample kept before the deadline existed may reach it)."""
        newest = self._newest
        if newest is not None and newest.kept is not None:
            self._wake()

    def close(self) -> None:
        """End this follower (idempotent); with none left the clock topic is delivered
        sample by sample again, the sample kept first."""
        newest, self._newest = self._newest, None
        if newest is not None:
            newest.unfollow(self._due)
            self._wake()
