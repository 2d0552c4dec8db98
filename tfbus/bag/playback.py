"""Replaying a bag's tf messages onto a :class:`~tfbus.bus.Bus` at recorded timing.

Two clocks take part, as in ``rosbag play --clock``: the *pace* clock replay sleeps on to
keep the recorded spacing (wall time, :class:`~tfbus.clock.SystemClock`, by default;
tests pass a :class:`~tfbus.clock.ManualClock` and advance it), and an optional *bag-time*
``clock`` that replay moves to each message's bag time (the ``/clock`` topic's role), so
code awaiting on it sees the recording's time. With ``publish_clock=HZ`` replay also
publishes that time as ``rosgraph_msgs/Clock`` on ``/clock`` at ``HZ`` per second of
pace time, so other processes' :class:`~tfbus.clock.SimClock` (or ROS nodes with
``use_sim_time``) follow the recording, as ``rosbag play --clock`` drives a ROS graph.
A :class:`ReplayControl` pauses and resumes a running replay (``rosbag play``'s space
key): while paused no message goes out and ``/clock`` repeats the paused time.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Collection
from os import PathLike
from typing import TYPE_CHECKING

import anyio

from tfbus.bag.formats import DEFAULT_TOPICS, BagMessage
from tfbus.bag.reader import read_messages
from tfbus.messages import Clock as ClockMessage
from tfbus.time import Time
from tfbus.topics import CLOCK_TOPIC, DEFAULT_CLOCK_HZ, MAX_CLOCK_HZ

if TYPE_CHECKING:
    from tfbus.bus import Bus
    from tfbus.clock import Clock, ManualClock

__all__ = ["DEFAULT_CLOCK_HZ", "MAX_CLOCK_HZ", "ReplayControl", "replay"]


class ReplayControl:
    """Pause and resume a running :func:`replay` (``replay(..., control=control)``), as
    ``rosbag play``'s space key does (ROS 1 ``rosbag/src/player.cpp``).

    While paused, no message is published and bag time stands still: with
    ``publish_clock`` the replay goes on publishing the paused time on ``/clock`` at its
    rate, as rosbag's ``TimePublisher::runStalledClock`` does, so nodes following
    ``/clock`` (a :class:`~tfbus.clock.SimClock` with a ``wall_timeout``) see a paused,
    live simulation. On resume the schedule shifts by the pause's length of pace time:
    the next message goes out as long after the resume as it was due after the pause.

    Call its methods from the event loop of the replay. One control may pause several
    replays in turn; it remembers its state between them.

    Args:
        paused: start paused (``rosbag play --pause``): nothing is published until
            :meth:`resume`.
    """

    __slots__ = ("_changed", "_offset_ns", "_pace", "_paused", "_paused_at_ns", "_scopes")

    def __init__(self, *, paused: bool = False) -> None:
        self._paused = bool(paused)
        self._pace: Clock | None = None
        self._offset_ns = 0  # pace time spent paused since the replay's anchor
        self._paused_at_ns = 0
        self._changed: anyio.Event | None = None
        self._scopes: set[anyio.CancelScope] = set()

    @property
    def paused(self) -> bool:
        """True while paused."""
        return self._paused

    def pause(self) -> None:
        """Pause the replay (nothing if paused already)."""
        if self._paused:
            return
        self._paused = True
        if self._pace is not None:
            self._paused_at_ns = self._pace.now_ns()
        for scope in self._scopes:  # the message waiting for its time waits again
            scope.cancel()
        self._notify()

    def resume(self) -> None:
        """Resume the replay (nothing if running)."""
        if not self._paused:
            return
        self._paused = False
        if self._pace is not None:
            self._offset_ns += self._pace.now_ns() - self._paused_at_ns
        self._notify()

    def toggle(self) -> bool:
        """Pause if running, resume if paused (the space key). Returns :attr:`paused`."""
        if self._paused:
            self.resume()
        else:
            self.pause()
        return self._paused

    # -- the replay's side -----------------------------------------------------------

    def _notify(self) -> None:
        changed, self._changed = self._changed, None
        if changed is not None:
            changed.set()

    def _anchor(self, pace: Clock | None) -> None:
        """Start counting paused pace time from now (the replay's first message)."""
        self._pace = pace
        self._offset_ns = 0
        if pace is not None:
            self._paused_at_ns = pace.now_ns()

    def _running_ns(self, now_ns: int) -> int:
        """Pace time ``now_ns`` less the pace time spent paused since the anchor: while
        paused, the pace time the pause began at, read once (the schedule stands still)."""
        if self._paused and self._pace is not None:
            return self._paused_at_ns - self._offset_ns
        return now_ns - self._offset_ns

    async def _wait_running(self) -> None:
        while self._paused:
            if self._changed is None:
                self._changed = anyio.Event()
            await self._changed.wait()

    async def _sleep_until(self, pace: Clock, due_ns: Callable[[], int]) -> None:
        """Sleep on ``pace`` until ``due_ns()`` (recomputed after each pause) while
        running."""
        while True:
            await self._wait_running()
            with anyio.CancelScope() as scope:
                self._scopes.add(scope)
                try:
                    await pace.sleep_until(Time.from_ns(max(due_ns(), 0)))
                finally:
                    self._scopes.discard(scope)
            if not scope.cancelled_caught and not self._paused:
                return


class _ClockSender:
    """Publishes bag time on ``/clock``, never backwards: through the bus (memory, Zenoh),
    or on a ROS 1 node as raw ``rosgraph_msgs/Clock`` bytes
    (:meth:`~tfbus.transports.ros1.Ros1Transport.advertise_raw`), since that transport
    carries only tf topics as messages."""

    def __init__(self, bus: Bus) -> None:
        self._bus = bus
        self._raw: Callable[[bytes], None] | None = None
        self.last_ns = -1
        self.sent = 0
        module = sys.modules.get("tfbus.transports.ros1.transport")
        transport = bus.transport
        if module is not None and isinstance(transport, module.Ros1Transport):
            from tfbus.codecs.ros1 import CLOCK_MD5SUM, CLOCK_TYPE

            transport.advertise_raw(CLOCK_TOPIC, CLOCK_TYPE, CLOCK_MD5SUM)
            self._raw = lambda payload: transport.send_raw_nowait(CLOCK_TOPIC, payload)

    def send(self, ns: int, *, again: bool = False) -> None:
        """Publish ``Clock(Time.from_ns(ns))`` unless it is before the last one sent, or
        equal to it and not ``again`` (a paused replay's repeats)."""
        if ns < self.last_ns or (ns == self.last_ns and not again) or ns < 0:
            return
        self.last_ns = ns
        message = ClockMessage(Time.from_ns(ns))
        if self._raw is not None:
            from tfbus.codecs.ros1 import encode_clock

            self._raw(encode_clock(message))
        else:
            self._bus.publish_nowait(CLOCK_TOPIC, message)
        self.sent += 1


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
    publish_clock: float | None = None,
    control: ReplayControl | None = None,
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
        publish_clock: Hz; publish bag time on ``/clock`` (:class:`~tfbus.messages.Clock`)
            this many times per second of pace time (:data:`DEFAULT_CLOCK_HZ`, 100, is
            ``rosbag play --clock``'s), as rosbag's ``TimePublisher`` does: the time
            advances with pace time times ``rate`` but never past the next message's bag
            time, which is published before that message, and never goes back (statics
            latched from before ``start`` do not move it); while paused (``control``)
            the paused time is published again at each tick. With ``rate`` ``None`` /
            ``0`` only the message times are published, one before each message.
            ``None`` (default): no ``/clock``. On a ROS 1 bus it is published as raw
            ``rosgraph_msgs/Clock``.
        control: a :class:`ReplayControl` that pauses and resumes this replay; paused
            pace time does not count in the schedule.

    Returns:
        The number of messages published.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`~tfbus.bag.read_messages`.
        BagReadError: damaged bag, raised after everything readable was published.
        ValueError: a negative or non-finite ``rate``; a ``publish_clock`` that is not a
            number in (0, :data:`MAX_CLOCK_HZ`].
    """
    import anyio.lowlevel

    if rate is not None and not 0 <= rate < float("inf"):
        raise ValueError(f"rate must be a finite number >= 0, got {rate!r}")
    if publish_clock is not None and (
        isinstance(publish_clock, bool)
        or not isinstance(publish_clock, (int, float))
        or not 0 < publish_clock <= MAX_CLOCK_HZ
    ):
        raise ValueError(
            f"publish_clock must be a rate in Hz in (0, {MAX_CLOCK_HZ:g}], got {publish_clock!r}"
        )
    speed = rate or None
    pacer: Clock | None = None
    if speed is not None:
        if pace_clock is None:
            from tfbus.clock import SystemClock

            pace_clock = SystemClock()
        pacer = pace_clock
    sender = _ClockSender(bus) if publish_clock is not None else None
    control = ReplayControl() if control is None else control
    # bag time (ns) of the pace schedule's origin, pace time of it, next message's bag time
    state = {"t0_bag": 0, "t0_pace": 0, "horizon": -1}

    async def tick_clock(hz: float, pace: Clock, speed: float, out: _ClockSender) -> None:
        """rosbag's TimePublisher: bag time following pace time, capped at the horizon."""
        from tfbus.clock import every

        async for _ in every(1.0 / hz, clock=pace):
            if state["horizon"] >= 0:
                elapsed = control._running_ns(pace.now_ns()) - state["t0_pace"]
                out.send(min(state["t0_bag"] + round(elapsed * speed), state["horizon"]),
                         again=control.paused)

    def due_ns(bag_ns: int, speed: float) -> Callable[[], int]:
        """The pace time a message of bag time ``bag_ns`` is due at, read after each
        pause (the paused pace time shifts it)."""
        return lambda: (state["t0_pace"] + control._offset_ns
                        + round((bag_ns - state["t0_bag"]) / speed))

    n = 0
    failure: Exception | None = None
    async with anyio.create_task_group() as tg:  # the /clock ticker's
        try:
            for rec in read_messages(path, topics=topics, start=start, stop=stop):
                if pacer is not None and speed is not None:
                    if n == 0:
                        # Anchored at ``start``: statics latched from before it go out at once.
                        state["t0_bag"] = rec.time.ns if start is None else max(rec.time.ns,
                                                                                 start.ns)
                        state["t0_pace"] = pacer.now().ns
                        control._anchor(pacer)
                        if sender is not None and publish_clock is not None:
                            sender.send(state["t0_bag"])
                            tg.start_soon(tick_clock, publish_clock, pacer, speed, sender)
                    state["horizon"] = max(rec.time.ns, state["horizon"])
                    await control._sleep_until(pacer, due_ns(rec.time.ns, speed))
                else:
                    await control._wait_running()
                if sender is not None:
                    sender.send(rec.time.ns)
                if clock is not None and clock.now() < rec.time:
                    await clock.set(rec.time)
                await bus.publish(rec.topic, rec.message)
                n += 1
                if on_message is not None:
                    on_message(rec)
                if pacer is None:
                    await anyio.lowlevel.checkpoint()
        except Exception as err:  # raised below, as itself, once the ticker has stopped
            failure = err
        tg.cancel_scope.cancel()
    if failure is not None:
        raise failure
    return n
