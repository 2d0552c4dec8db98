"""Time sources and periodic timers: ``SystemClock``, ``ManualClock``, ``SimClock``,
``every()``.

Every async component of tfbus takes a :class:`Clock`; nothing else in tfbus reads the
wall clock. :class:`SystemClock` follows wall time (``time.time_ns``), as ROS time does
without ``/clock``. :class:`ManualClock` is simulated time that tests and bag replay
drive by hand: ``await clock.advance(1.0)`` steps through every pending deadline in
order, letting woken tasks run until they block again before taking the next step, so a
100 Hz timer ticks exactly 100 times per simulated second, instantly and
deterministically (the role trio's ``MockClock(autojump_threshold=0)`` plays for trio).

:class:`SimClock` is ROS's ``use_sim_time``: its time is the newest ``/clock``
(``rosgraph_msgs/Clock``) heard on a bus, and its deadlines move only as ``/clock`` does::

    async with SimClock(bus) as clock:             # Time(0) until the first /clock
        await clock.sleep(1.0)                     # one simulated second

:func:`every` is the periodic timer (``ros::Rate`` / ``ros::Timer``)::

    async for tick in every(0.01, clock=clock):    # 100 Hz, absolute deadlines
        ...

Timer deadlines are ``first + index * period`` (no drift). A body that runs late does not
shift the schedule: the timer fires once for the most recent deadline that has passed
and skips older missed ones, counting them as overruns (as ``rcl_timer`` does; see
:class:`Tick`). A backward clock jump re-anchors the schedule at the new time (as
``ros::Rate::sleep`` does).

The package is small private modules re-exported here (anyio's layout): ``_base``
(the :class:`Clock` protocol, :func:`timeout_ns`, jump callbacks), ``_system``
(:class:`SystemClock`), ``_manual`` (:class:`ManualClock` and its deadline scopes),
``_sim`` (:class:`SimClock`, which sets a ManualClock from each ``/clock``) and
``_timer`` (:func:`every`, :class:`PeriodicTimer`, :class:`Tick`). Import from
``tfbus.clock``.

Deadlines and timeouts on a clock's time are cancel scopes: ``clock.move_on_after(s)``
and ``clock.fail_after(s)`` are ``anyio.move_on_after`` / ``anyio.fail_after`` on a
:class:`SystemClock`, and scopes that :meth:`ManualClock.advance` cancels when simulated
time reaches the deadline on a :class:`ManualClock`::

    with clock.move_on_after(2.0) as scope:     # 2 s of this clock's time
        await something()
    if scope.cancelled_caught:
        ...                                      # timed out

    with clock.fail_after(Duration(2)):         # TimeoutError when it expires
        await something()

``clock.call_later(s, callback)`` is the same deadline as a callback, with no cancel scope
(what a :class:`~tfbus.buffer.Buffer`'s ``timeout=`` uses): one loop timer (asyncio) or
one system task (trio) per :class:`SystemClock` serves all of them, and a
:class:`ManualClock` files them among its sleepers.

Timeouts (``timeout=`` arguments anywhere in tfbus, and these scopes) mean the same on
both clocks: ``None`` or ``math.inf`` = no deadline; a negative or zero timeout expires
at the first checkpoint; a deadline beyond the end of :class:`~tfbus.time.Time`
(``TIME_MAX_NS``, year 2262) never expires; ``nan`` is a ``ValueError``; a ``str`` or a
``bool`` is a ``TypeError`` (checked before any arithmetic).
"""

from tfbus.clock._base import Clock, JumpCallback, timeout_ns
from tfbus.clock._manual import ManualClock
from tfbus.clock._sim import SimClock, SimClockStatistics
from tfbus.clock._system import SystemClock
from tfbus.clock._timer import PeriodicTimer, Tick, every

__all__ = [
    "Clock",
    "JumpCallback",
    "ManualClock",
    "PeriodicTimer",
    "SimClock",
    "SimClockStatistics",
    "SystemClock",
    "Tick",
    "every",
    "timeout_ns",
]
