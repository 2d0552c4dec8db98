"""``SimClock``: simulated time read from ``/clock`` on a bus (ROS ``use_sim_time``)."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Hashable
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import anyio

from tfbus.clock._base import JumpCallback
from tfbus.clock._manual import ManualClock
from tfbus.errors import SimTimeStalled
from tfbus.messages import Clock as ClockMessage
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import NSEC_PER_SEC, Duration, Time
from tfbus.topics import CLOCK_TOPIC

if TYPE_CHECKING:
    from tfbus.bus import Bus
    from tfbus.subscription import CallbackSubscription

_log = logging.getLogger("tfbus.clock")

MAX_FORWARD_STEP: float = 1e9
"""Default bound, in seconds, of how far one ``/clock`` may move a :class:`SimClock`
ahead of the time it reads (about 31.7 years); a message further ahead is dropped."""


class NewestFollow(Protocol):
    """What :meth:`KeepsNewest.keep_newest` returns."""

    @property
    def newest_ns(self) -> int:
        """The stamp (ns) of the newest sample the transport's thread kept because no
        follower needed it yet (a step forward, within the follower's bounds): the time
        now; -1 when there is none. Read from the event loop."""
        ...

    def stepped_back(self) -> None:
        """The follower delivered a jump back: the stamps kept before it are no longer
        the time (``newest_ns`` is -1 until the next sample kept)."""

    def poke(self) -> None:
        """Deliver the sample kept, if any, at the event loop's next turn."""

    def close(self) -> None:
        """End newest-only delivery for this follower."""


@runtime_checkable
class KeepsNewest(Protocol):
    """A transport that can deliver a topic newest-only, deciding in its receiving thread
    when the event loop must see a sample (the Zenoh transport:
    :meth:`tfbus.transports.zenoh.ZenohTransport.keep_newest`). A :class:`SimClock` asks
    ``isinstance(bus.transport, KeepsNewest)``."""

    def keep_newest(self, topic: str, due: Callable[[int], bool]) -> NewestFollow:
        """Deliver ``topic`` (``rosgraph_msgs/Clock``) newest-only; ``due(stamp_ns)``
        (the transport's thread) says when a sample must reach the event loop now."""
        ...


@dataclass(frozen=True, slots=True)
class SimClockStatistics:
    """Counters of a :class:`SimClock` (:meth:`SimClock.statistics`), monotonic since
    the clock was made.

    Attributes:
        received: messages delivered on the clock's topic, valid or not (over Zenoh,
            ROS 1 and ROS 2, where ``/clock`` is followed newest-only, the ones the
            event loop saw; the transport counts the skipped ones as ``coalesced``).
        accepted: valid ``/clock`` messages delivered that set the time (equal stamps
            included; over Zenoh, ROS 1 and ROS 2, the stamps ``now()`` read from the
            transport's thread in between are not counted).
        dropped: messages dropped: not a ``Clock`` of a :class:`~tfbus.time.Time`, or
            more than ``max_forward_step`` seconds ahead of ``now()``.
        jumps: backward jumps of simulated time (each ``/clock`` earlier than ``now()``).
        interleaved: backward jumps undone by a later ``/clock`` that leaps forward
            again, in one step of more than half the jump, to or past the time before
            it: the mark of two publishers of ``/clock`` whose stamps interleave (a
            simulator and a ``rosbag play --clock``, two bag players), or of a
            reordered message. A looping bag or a reset world jumps back and runs on
            from there in small steps, and is not counted. Logged (the first, then one
            in a thousand) as "several publishers on /clock".
    """

    received: int
    accepted: int
    dropped: int
    jumps: int
    interleaved: int


class _WallGuard:
    """An ``anyio.CancelScope`` on wall time around one wait of a :class:`SimClock`:
    its deadline is ``wall_timeout`` after the wait began or after the last valid
    ``/clock``, whichever is later; leaving the scope after it fired raises
    :class:`~tfbus.errors.SimTimeStalled`."""

    __slots__ = ("_clock", "_scope")

    def __init__(self, clock: SimClock) -> None:
        self._clock = clock
        self._scope = anyio.CancelScope()

    def refresh(self, deadline: float) -> None:
        self._scope.deadline = deadline

    def __enter__(self) -> _WallGuard:
        clock = self._clock
        assert clock._wall_timeout is not None
        self._scope.deadline = anyio.current_time() + clock._wall_timeout
        self._scope.__enter__()
        clock._guards.add(self)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool:
        self._clock._guards.discard(self)
        suppressed = bool(self._scope.__exit__(exc_type, exc, tb))
        if self._scope.cancelled_caught:
            clock = self._clock
            raise SimTimeStalled(
                f"no {clock.topic} message for {clock._wall_timeout:g} s of wall time "
                f"while waiting on simulated time (now {clock.now().to_sec():.9f} s)"
            )
        return suppressed


class SimClock:
    """Simulated time: the newest ``rosgraph_msgs/Clock`` heard on ``/clock`` of a bus,
    as a ROS node with ``use_sim_time`` reads it (rospy ``rospy.Time.now()``, rclpy
    ``Clock(clock_type=ROS_TIME)`` with ``use_sim_time``; ``rclpy/time_source.py``).

    ``async with SimClock(bus) as clock:`` subscribes to ``/clock`` on the open ``bus``
    (a :class:`~tfbus.messages.Clock` per message, from another process through any
    transport that carries the topic, or published in this one); leaving the block
    unsubscribes. It is a :class:`~tfbus.clock.Clock`, so a
    :class:`~tfbus.buffer.Buffer`, a :class:`~tfbus.listener.TransformListener`,
    :func:`~tfbus.clock.every` and every ``timeout=`` of tfbus can run on it.

    Semantics (as rospy and rclpy with ``use_sim_time``):

    * ``now()`` is ``Time(0)`` until the first ``/clock`` arrives, then the newest one.
    * ``sleep``, ``sleep_until``, ``move_on_after`` / ``fail_after`` deadlines,
      ``call_later`` and ``every()`` ticks are deadlines on simulated time: they advance
      only as ``/clock`` advances (a paused simulation pauses them) and are woken by the
      ``/clock`` message that reaches them, inside its delivery (nothing polls). The
      deadline machinery is a :class:`~tfbus.clock.ManualClock` that each message sets.
    * A ``/clock`` earlier than ``now()`` (a looping bag, a reset world) is a jump back:
      ``now()`` follows it, the :meth:`on_jump` callbacks get ``(old, new)`` (a
      :class:`~tfbus.listener.TransformListener` or :class:`~tfbus.buffer.Buffer` on this
      clock clears its buffer, as tf2_ros does), it is counted in :attr:`jumps` and
      logged (the first, then one in a thousand). Pending deadlines keep their absolute
      times.
    * Two publishers of ``/clock`` whose stamps interleave make one jump back per
      backward step, as in ROS (each clears a listener's buffer). A jump back that a
      later ``/clock`` undoes by leaping forward again to where time was is counted in
      :attr:`SimClockStatistics.interleaved` and logged as several publishers on the
      topic (the first, then one in a thousand); a looping bag, which runs on from its
      start, is not.
    * On a bus whose transport delivers a topic newest-only (:class:`KeepsNewest`: the
      Zenoh transport, and the ROS 1 and ROS 2 transports' ``clock_topic``), the clock
      asks for ``/clock`` newest-only: the transport's thread (Zenoh's, Cyclone's
      listener, the ROS 1 clock connection's reader) decodes each ``/clock`` and wakes
      the event loop only when it reaches the earliest deadline filed on this clock,
      steps back, is the first, is more than ``max_forward_step``
      ahead, or a ``wall_timeout`` wait is running (then at every ``/clock``); the
      samples in between are not delivered (counted by the transport as ``coalesced``,
      not here: a keep-last-1 ``/clock`` subscription of rclpy skips samples too), and
      ``now()`` reads the newest one the thread kept (``NewestFollow.newest_ns``), so it
      never lags the newest ``/clock`` heard. A ``/clock`` at 1 kHz then costs one
      event-loop wake-up per deadline, not per message. Other listeners of the topic on
      the same bus get it at least every 10 ms of wall time
      (:data:`~tfbus.transports.zenoh.transport.NEWEST_MAX_DELAY`).
    * A message that is not a ``Clock`` holding a :class:`~tfbus.time.Time` (a negative
      or non-integer stamp cannot be one), or one more than ``max_forward_step`` seconds
      ahead of ``now()`` once a first ``/clock`` was accepted, is dropped, counted in
      :attr:`dropped` and logged (the first of each kind, then one in a thousand); the
      valid messages around it are kept. The first ``/clock`` is accepted at any valid
      time (a bag recorded on wall time starts near 1.7e9 s).

    ``wall_timeout`` (seconds of wall time, ``None`` = no bound) guards every wait on
    simulated time against a simulation that died: a ``sleep``, ``sleep_until`` or
    ``move_on_after`` / ``fail_after`` block during which no valid ``/clock`` arrives for
    ``wall_timeout`` wall seconds raises :class:`~tfbus.errors.SimTimeStalled` (a
    ``TimeoutError``). A paused simulation that still publishes ``/clock`` is alive:
    its waits go on. With a ``wall_timeout``, :meth:`call_later` returns ``None``, so a
    :class:`~tfbus.buffer.Buffer`'s ``timeout=`` waits use the guarded
    :meth:`move_on_after` instead. Without a bound, a wait on a clock whose ``/clock``
    never advances lasts until cancelled, as in ROS.

    Use from the event loop of the bus.
    """

    def __init__(
        self,
        bus: Bus | None = None,
        *,
        topic: str = CLOCK_TOPIC,
        wall_timeout: float | None = None,
        max_forward_step: float = MAX_FORWARD_STEP,
    ) -> None:
        """Create a clock following ``topic`` (default ``/clock``) on ``bus`` (subscribed
        on entering ``async with``).

        Args:
            bus: the bus carrying ``/clock`` (open when the clock is entered); ``None``:
                given later with :meth:`attach`, before entering (for a
                :class:`~tfbus.buffer.Buffer` built on this clock before its bus exists).
            topic: the topic of ``rosgraph_msgs/Clock`` messages.
            wall_timeout: seconds of wall time without a valid ``/clock`` after which a
                wait on this clock raises :class:`~tfbus.errors.SimTimeStalled`;
                ``None`` (default): no bound.
            max_forward_step: seconds; a ``/clock`` further ahead of ``now()`` is dropped
                (default :data:`MAX_FORWARD_STEP`, 1e9 s).

        Raises:
            ValueError: ``wall_timeout`` is not a positive finite number, or
                ``max_forward_step`` is not a positive number (``inf`` allowed).
            TypeError: ``wall_timeout`` or ``max_forward_step`` is not a number.
        """
        if wall_timeout is not None:
            if isinstance(wall_timeout, bool) or not isinstance(wall_timeout, (int, float)):
                raise TypeError(f"wall_timeout must be a number of seconds, got {wall_timeout!r}")
            if not (0 < wall_timeout < math.inf):
                raise ValueError(
                    f"wall_timeout must be positive and finite seconds, got {wall_timeout!r}"
                )
        if isinstance(max_forward_step, bool) or not isinstance(max_forward_step, (int, float)):
            raise TypeError(
                f"max_forward_step must be a number of seconds, got {max_forward_step!r}"
            )
        if not max_forward_step > 0:
            raise ValueError(
                f"max_forward_step must be a positive number of seconds, got {max_forward_step!r}"
            )
        self._bus: Bus | None = bus
        self._topic = topic
        self._wall_timeout = None if wall_timeout is None else float(wall_timeout)
        self._max_step_ns = (
            None if math.isinf(max_forward_step) else int(max_forward_step * NSEC_PER_SEC)
        )
        self._core = ManualClock()
        self._guards: set[_WallGuard] = set()
        self._subscription: CallbackSubscription | None = None
        self._newest: NewestFollow | None = None
        self._entered = False
        self._received = 0
        self._accepted = 0
        self._dropped = 0
        self._jumps = 0
        self._interleaved = 0
        # (now() before the last jump back, its size), until time is back there: ns
        self._jumped: tuple[int, int] | None = None
        # in the delivery of a /clock: now() is its stamp for the deadlines it reaches
        self._delivering = False
        self._logs = CountLimitedLog(_log, 1000)

    # -- lifecycle --------------------------------------------------------------------

    def attach(self, bus: Bus) -> SimClock:
        """Set the bus whose ``/clock`` this clock follows, for a clock created without
        one (``SimClock()``); then enter it (``async with clock.attach(bus):``). Until
        it is entered ``now()`` is ``Time(0)`` and waits block, as before any ``/clock``.

        Returns:
            this clock.

        Raises:
            RuntimeError: the clock was already entered, or already has a bus.
        """
        if self._entered:
            raise RuntimeError("a SimClock that was entered cannot be attached to a bus")
        if self._bus is not None:
            raise RuntimeError("this SimClock already follows a bus")
        self._bus = bus
        return self

    async def __aenter__(self) -> SimClock:
        """Subscribe to the topic on the bus.

        Raises:
            RuntimeError: the clock was already entered, has no bus (created without one
                and not given one by :meth:`attach`), or the bus is not open.
            anyio.ClosedResourceError: the bus is closed.
        """
        if self._entered:
            raise RuntimeError("a SimClock can be entered only once")
        if self._bus is None:
            raise RuntimeError("this SimClock has no bus: SimClock(bus) or clock.attach(bus)")
        self._entered = True
        self._subscription = self._bus.subscribe_callback(self._topic, self._on_clock)
        transport = self._bus.transport
        if isinstance(transport, KeepsNewest):
            self._newest = transport.keep_newest(self._topic, self._due)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Unsubscribe; the body's exception, if any, leaves as itself. ``now()`` keeps
        the last time read."""
        if self._newest is not None:
            self._catch_up()  # now() keeps the newest time heard
            self._newest.close()
            self._newest = None
        if self._subscription is not None:
            self._subscription.close()
            self._subscription = None

    # -- statistics -------------------------------------------------------------------

    def statistics(self) -> SimClockStatistics:
        """A snapshot of the counters (see :class:`SimClockStatistics`)."""
        return SimClockStatistics(
            received=self._received,
            accepted=self._accepted,
            dropped=self._dropped,
            jumps=self._jumps,
            interleaved=self._interleaved,
        )

    @property
    def topic(self) -> str:
        """The topic followed (``/clock`` by default)."""
        return self._topic

    @property
    def received(self) -> int:
        """Messages delivered on the topic, valid or not."""
        return self._received

    @property
    def accepted(self) -> int:
        """Valid ``/clock`` messages delivered that set the time (equal stamps
        included; see :class:`SimClockStatistics`)."""
        return self._accepted

    @property
    def dropped(self) -> int:
        """Messages dropped: not a ``Clock`` of a ``Time``, or too far ahead."""
        return self._dropped

    @property
    def jumps(self) -> int:
        """Backward jumps of simulated time (each ``/clock`` earlier than ``now()``)."""
        return self._jumps

    # -- the topic --------------------------------------------------------------------

    def _on_clock(self, message: object) -> None:
        self._received += 1
        stamp = message.clock if isinstance(message, ClockMessage) else None
        if not isinstance(stamp, Time):
            self._dropped += 1
            self._logs.log(
                logging.WARNING,
                "dropping a %s on %s: expected a rosgraph_msgs/Clock of a Time",
                type(message).__name__,
                self._topic,
            )
            return
        # the time the event loop was given (jumps are seen from it), and now(), which
        # may be ahead of it by a newer stamp the transport kept (steps are bounded by it)
        now_ns = self._core.now_ns()
        new_ns = stamp.ns
        if (self._accepted and self._max_step_ns is not None
                and new_ns - self.now_ns() > self._max_step_ns):
            self._dropped += 1
            self._logs.log(
                logging.WARNING,
                "dropping a %s of %.9f s: more than %g s ahead of the simulated time %.9f s",
                self._topic,
                new_ns / 1e9,
                self._max_step_ns / 1e9,
                self.now_ns() / 1e9,
            )
            return
        self._accepted += 1
        if self._guards:
            deadline = anyio.current_time() + (self._wall_timeout or 0.0)
            for guard in list(self._guards):
                guard.refresh(deadline)
        if new_ns < now_ns:
            self._jumps += 1
            self._jumped = (now_ns, now_ns - new_ns)
            if self._newest is not None:
                self._newest.stepped_back()
            self._logs.log(
                logging.WARNING,
                "simulated time on %s jumped back from %.9f s to %.9f s",
                self._topic,
                now_ns / 1e9,
                new_ns / 1e9,
            )
        elif self._jumped is not None:
            jumped_from, size = self._jumped
            if new_ns >= jumped_from:
                self._jumped = None
                if 2 * (new_ns - now_ns) > size:  # a leap back, not time running on
                    self._interleaved += 1
                    self._logs.log(
                        logging.WARNING,
                        "several publishers on %s? simulated time jumped back from "
                        "%.9f s and returned to %.9f s in one step from %.9f s",
                        self._topic,
                        jumped_from / 1e9,
                        new_ns / 1e9,
                        now_ns / 1e9,
                    )
        # the deadlines this /clock reaches run in its delivery, reading it as now()
        self._delivering = True
        try:
            self._core.set_nowait(stamp)
        finally:
            self._delivering = False

    def _due(self, stamp_ns: int) -> bool:
        """Whether a ``/clock`` of ``stamp_ns`` the transport's thread holds must reach
        the event loop now (:class:`KeepsNewest`): it reaches the earliest deadline
        filed, or the clock needs every message (the first, a jump back being checked for
        interleaving, a wall-guarded wait), or it is to be dropped (logged at once).
        Called in the transport's thread: reads only."""
        if self._guards or self._jumped is not None or not self._accepted:
            return True
        core = self._core
        limit = self._max_step_ns
        # now() is at least the time the loop was given: checked against that first
        if limit is not None and stamp_ns - core._now_ns > limit \
                and stamp_ns - self.now_ns() > limit:
            return True
        # ManualClock._next_deadline_ns, inline (a call per /clock in this thread), and
        # with no exception raised when there is no deadline (the common case)
        sleepers = core._sleepers
        if not sleepers:
            return False
        try:
            return bool(stamp_ns >= sleepers[0][0])
        except IndexError:  # the loop took the last one meanwhile
            return False

    def _catch_up(self) -> None:
        """Give the deadline machinery the newest time the transport kept (deadlines
        are filed from it, and those it reaches are due); not inside the delivery of a
        ``/clock``, where ``now()`` is that ``/clock`` and deadlines are filed from it."""
        ns = self.now_ns()
        if ns > self._core.now_ns():
            self._core.set_nowait(Time.from_ns(ns))

    def _poke(self) -> None:
        """A deadline is being filed: it is filed from the newest time kept, and a
        ``/clock`` the transport holds may reach it."""
        newest = self._newest
        if newest is not None:
            self._catch_up()
            newest.poke()

    # -- Clock protocol ---------------------------------------------------------------

    def now(self) -> Time:
        """The simulated time: the newest accepted ``/clock``, ``Time(0)`` before any
        (on a newest-only transport, the newest one its thread kept, if newer than the
        last one the event loop was given; in the delivery of a ``/clock``, as in the
        callbacks of the deadlines it reaches, that ``/clock``)."""
        return Time.from_ns(self.now_ns())

    def now_ns(self) -> int:
        """:meth:`now` as int nanoseconds."""
        core_ns = self._core.now_ns()
        newest = self._newest
        if newest is not None and self._accepted and not self._delivering:
            kept = newest.newest_ns
            if kept > core_ns:
                return kept
        return core_ns

    async def sleep_until(self, t: Time) -> None:
        """Return once a ``/clock`` at ``t`` or later has arrived (after a checkpoint if
        ``now() >= t`` already).

        Raises:
            SimTimeStalled: ``wall_timeout`` passed with no valid ``/clock``.
            anyio.get_cancelled_exc_class(): the calling task was cancelled meanwhile.
        """
        self._poke()
        if self._wall_timeout is None:
            await self._core.sleep_until(t)
            return
        with _WallGuard(self):
            await self._core.sleep_until(t)

    async def sleep(self, seconds: float | Duration) -> None:
        """Sleep ``seconds`` (or a :class:`~tfbus.time.Duration`) of simulated time:
        until a ``/clock`` at ``now() + seconds`` or later arrives. ``<= 0``: a
        checkpoint; ``math.inf``: until cancelled (or ``wall_timeout``).

        Raises:
            SimTimeStalled: ``wall_timeout`` passed with no valid ``/clock``.
            anyio.get_cancelled_exc_class(): the calling task was cancelled meanwhile.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        self._poke()
        if self._wall_timeout is None:
            await self._core.sleep(seconds)
            return
        with _WallGuard(self):
            await self._core.sleep(seconds)

    def on_jump(
        self, callback: JumpCallback, *, key: Hashable | None = None
    ) -> Callable[[], None]:
        """Register ``callback(old, new)``, called when a ``/clock`` earlier than
        ``now()`` arrives (inside its delivery); ``key``: one shared callback per key
        (:meth:`tfbus.clock.Clock.on_jump`). Returns the function that unregisters
        it. Exceptions from callbacks are logged, never raised into the delivery."""
        return self._core.on_jump(callback, key=key)

    def move_on_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """A cancel scope cancelled when ``/clock`` reaches ``now() + seconds`` (see
        :meth:`ManualClock.move_on_after <tfbus.clock.ManualClock.move_on_after>`).

        Raises:
            SimTimeStalled: on leaving the block, if ``wall_timeout`` passed in it with
                no valid ``/clock``.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        self._poke()
        return self._guarded(self._core.move_on_after(seconds, shield=shield))

    def fail_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """As :meth:`move_on_after`, raising ``TimeoutError`` when the simulated-time
        deadline ends the block.

        Raises:
            TimeoutError: on leaving the block, if the deadline cancelled it.
            SimTimeStalled: on leaving the block, if ``wall_timeout`` passed in it with
                no valid ``/clock``.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        self._poke()
        return self._guarded(self._core.fail_after(seconds, shield=shield))

    def call_later(
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        """Call ``callback()`` in the delivery of the ``/clock`` that reaches ``now() +
        seconds`` (at once if ``seconds <= 0``; never for ``inf``). Returns the
        function that cancels it; ``None`` with a ``wall_timeout`` (the caller then uses
        the guarded :meth:`move_on_after`, as :meth:`Clock.call_later
        <tfbus.clock.Clock.call_later>` provides).

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        if self._wall_timeout is not None:
            return None
        self._poke()
        return self._core.call_later(seconds, callback)

    def _guarded(
        self, deadline: AbstractContextManager[anyio.CancelScope]
    ) -> AbstractContextManager[anyio.CancelScope]:
        if self._wall_timeout is None:
            return deadline
        return _GuardedDeadline(self, deadline)

    def __repr__(self) -> str:
        return (
            f"SimClock(topic={self._topic!r}, now={self.now()!r}, received={self._received}, "
            f"dropped={self._dropped}, jumps={self._jumps}, interleaved={self._interleaved})"
        )


class _GuardedDeadline:
    """A simulated-time deadline scope inside a :class:`_WallGuard`."""

    __slots__ = ("_clock", "_deadline", "_stack")

    def __init__(
        self, clock: SimClock, deadline: AbstractContextManager[anyio.CancelScope]
    ) -> None:
        self._clock = clock
        self._deadline = deadline
        self._stack = ExitStack()

    def __enter__(self) -> anyio.CancelScope:
        with ExitStack() as stack:
            stack.enter_context(_WallGuard(self._clock))
            scope = stack.enter_context(self._deadline)
            self._stack = stack.pop_all()
        return scope

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool:
        return bool(self._stack.__exit__(exc_type, exc, tb))
