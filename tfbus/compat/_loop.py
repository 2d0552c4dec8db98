"""The process-wide background event loop that carries synchronous tf2 code.

ROS 1 programs (and plain threaded ones) call ``tf2_ros.TransformListener(buffer)``,
``TransformBroadcaster()`` and blocking ``lookup_transform(..., timeout)`` from ordinary
threads; tfbus's bus, listener and waits are asynchronous. One daemon thread runs an
asyncio event loop (``anyio.run``) holding an :class:`anyio.from_thread.BlockingPortal`:
the compat classes enter their bus and listeners there and the calling threads submit
work through the portal (``portal.call``), blocking until it is done — a wait for a
transform is :meth:`tfbus.Buffer.wait_for_transform` in that loop, woken by the
arrival that answers it, never polled.

The thread starts with the first object that needs it and stops (its bus leaves the
ROS 1 graph, bounded) at interpreter exit (:func:`atexit.register`), at
``rospy.on_shutdown`` when rospy is initialised (asked there, so that it leaves the graph
while rospy's own node does; the exit waits for it), or on :func:`shutdown`. It is a
daemon thread: a program that ends (or is interrupted by SIGINT) never waits for it more
than :data:`STOP_TIMEOUT` seconds.
"""

from __future__ import annotations

import atexit
import contextlib
import itertools
import os
import sys
import threading
import weakref
from collections.abc import Awaitable, Callable
from contextlib import AbstractAsyncContextManager
from typing import Any, TypeVar

import anyio
import anyio.abc
from anyio.from_thread import BlockingPortal

from tfbus.errors import LoopThreadError

__all__ = ["STOP_TIMEOUT", "BackgroundLoop", "LoopThreadError", "background", "shutdown"]

_T = TypeVar("_T")

STOP_TIMEOUT = 0.8
"""Seconds :meth:`BackgroundLoop.stop` waits for the loop to close its bus and end."""


class BackgroundLoop:
    """One event loop in one daemon thread, with a portal for other threads."""

    def __init__(self) -> None:
        """Create the loop (the thread starts on first use: :meth:`portal`)."""
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._portal: BlockingPortal | None = None
        self._held: list[tuple[anyio.Event, anyio.Event]] = []
        self._stop: anyio.Event | None = None
        self._ready = threading.Event()
        self._failed: BaseException | None = None
        self._shared: dict[str, Any] = {}

    @property
    def running(self) -> bool:
        """True while the loop's thread runs."""
        return self._thread is not None and self._thread.is_alive() and self._portal is not None

    def in_loop_thread(self) -> bool:
        """True when called from the loop's own thread."""
        return self._thread is not None and threading.current_thread() is self._thread

    def portal(self) -> BlockingPortal:
        """The portal into the loop, starting its thread on first use.

        Raises:
            RuntimeError: the loop could not start (the reason chained).
        """
        with self._lock:
            if not self.running:
                self._start()
            assert self._portal is not None
            return self._portal

    def _start(self) -> None:
        self._ready.clear()
        self._failed = None
        self._shared.clear()
        self._thread = threading.Thread(target=self._run, name="tfbus-compat-loop", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._failed is not None or self._portal is None:
            raise RuntimeError("tfbus.compat's background event loop did not start") \
                from self._failed
        _register_rospy_shutdown()

    def _run(self) -> None:
        try:
            anyio.run(self._main)
        except BaseException as exc:  # reported to the thread that started the loop
            self._failed = exc
            self._ready.set()

    async def _main(self) -> None:
        async with BlockingPortal() as portal:
            self._stop = anyio.Event()
            self._held.clear()
            self._portal = portal
            self._ready.set()
            await self._stop.wait()
            with anyio.move_on_after(STOP_TIMEOUT, shield=True):
                for release, done in reversed(self._held):  # last entered, first exited
                    release.set()
                    await done.wait()
            await portal.stop(cancel_remaining=True)  # pending waits end (cancelled)
        self._portal = None

    async def _hold(
        self, context: AbstractAsyncContextManager[Any], *,
        task_status: anyio.abc.TaskStatus[Any] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Enter ``context`` and keep it entered, in this one task, until released."""
        release, done = anyio.Event(), anyio.Event()
        try:
            async with context as value:
                self._held.append((release, done))
                task_status.started(value)
                await release.wait()
        finally:
            done.set()

    def call(self, fn: Callable[..., Awaitable[_T] | _T], *args: object) -> _T:
        """Run ``fn(*args)`` (a function or a coroutine function) in the loop and
        return its result in the calling thread; from the loop's thread, call it here.

        Raises:
            whatever ``fn`` raises, as itself.
        """
        if self.in_loop_thread():
            here = fn(*args)
            assert not isinstance(here, Awaitable)
            return here
        portal: Any = self.portal()
        result: _T = portal.call(fn, *args)
        return result

    def enter(self, context: AbstractAsyncContextManager[_T]) -> _T:
        """Enter ``context`` in the loop (in a task of its own that holds it); it is
        exited, last entered first, when the loop stops.

        Raises:
            whatever entering ``context`` raises.
        """
        _, value = self.portal().start_task(self._hold, context)
        return value  # type: ignore[no-any-return]

    def shared(self, key: str, make: Callable[[], AbstractAsyncContextManager[_T]]) -> _T:
        """The object entered once per loop under ``key`` (``make()`` entered on first
        use), e.g. the process's ROS 1 bus."""
        self.portal()
        with self._lock:
            if key not in self._shared:
                self._shared[key] = self.enter(make())
            return self._shared[key]  # type: ignore[no-any-return]

    def request_stop(self) -> None:
        """Ask the loop to exit everything entered and end, without waiting for it
        (rospy's shutdown hook: rospy's own shutdown runs meanwhile, and the
        interpreter's exit, :func:`shutdown`, waits for the rest)."""
        thread, portal, stop = self._thread, self._portal, self._stop
        if thread is None or portal is None or stop is None or not thread.is_alive():
            return
        if threading.current_thread() is thread:
            stop.set()
            return
        with contextlib.suppress(RuntimeError):  # the loop ended meanwhile
            portal.start_task_soon(_set, stop)

    def stop(self, timeout: float = STOP_TIMEOUT) -> None:
        """Exit everything entered (buses leave their graph), end the loop and wait for
        its thread up to ``timeout`` s (it is a daemon: the process never waits more)."""
        thread = self._thread
        if thread is None or not thread.is_alive():
            return
        self.request_stop()
        if threading.current_thread() is thread:
            return
        thread.join(timeout)
        with self._lock:
            self._thread = None
            self._shared.clear()


async def _set(event: anyio.Event) -> None:
    event.set()


background = BackgroundLoop()
"""The process's background loop."""


def shutdown() -> None:
    """Stop the process's background loop (:meth:`BackgroundLoop.stop`); it starts again
    when needed."""
    background.stop()


atexit.register(shutdown)

_rospy_hooked = False


def _register_rospy_shutdown() -> None:
    """``rospy.on_shutdown(shutdown)`` once, when rospy is imported and initialised."""
    global _rospy_hooked
    rospy = sys.modules.get("rospy")
    if _rospy_hooked or rospy is None:
        return
    with contextlib.suppress(Exception):
        if rospy.core.is_initialized():
            rospy.on_shutdown(background.request_stop)
            _rospy_hooked = True


def rospy_node_name() -> str | None:
    """The initialised rospy node's name (``rospy.get_name()``), else None."""
    rospy = sys.modules.get("rospy")
    if rospy is None:
        return None
    try:
        if rospy.core.is_initialized():
            return str(rospy.get_name())
    except Exception:
        return None
    return None


def rospy_shutting_down() -> bool:
    """Whether rospy is initialised and its shutdown has begun
    (``rospy.core.is_shutdown_requested()``: set before rospy runs its client hooks, one
    of which stops the background loop, and kept until the process ends); False without
    rospy or when it cannot say."""
    rospy = sys.modules.get("rospy")
    if rospy is None:
        return False
    try:
        return bool(rospy.core.is_initialized()
                    and (rospy.core.is_shutdown_requested() or rospy.core.is_shutdown()))
    except Exception:
        return False


def rospy_use_sim_time() -> bool:
    """Whether rospy is initialised and the ``/use_sim_time`` parameter is true: what
    makes ``rospy.Time.now()`` simulated time (``rospy/impl/simtime.py``,
    ``rospy.get_param('/use_sim_time')``); False without rospy or when it cannot say."""
    rospy = sys.modules.get("rospy")
    if rospy is None:
        return False
    try:
        if rospy.core.is_initialized():
            return bool(rospy.get_param("/use_sim_time", False))
    except Exception:
        return False
    return False


def ros1_bus() -> Any:
    """The process's bus on the ROS 1 graph at ``ROS_MASTER_URI`` (tfbus's own ROS 1
    transport, :class:`tfbus.transports.ros1.Ros1Transport`), entered in the background
    loop on first use. Its node name is the rospy node's name plus ``_tf2`` when rospy
    is initialised (a second node: the master would shut down a node that took the
    same name), else ``/tfbus_<pid>_<random>``. With rospy's ``/use_sim_time`` true
    (:func:`rospy_use_sim_time`) the node also subscribes to ``/clock``."""
    from tfbus.bus import Bus
    from tfbus.topics import CLOCK_TOPIC
    from tfbus.transports.ros1 import Ros1Transport

    def make() -> Bus:
        name = rospy_node_name()
        node = f"{name}_tf2" if name else None
        clock_topic = CLOCK_TOPIC if rospy_use_sim_time() else None
        return Bus(transport=Ros1Transport(node_name=node, clock_topic=clock_topic))

    _register_rospy_shutdown()
    return background.shared(f"ros1:{os.environ.get('ROS_MASTER_URI', '')}", make)


def ros1_sim_clock() -> Any:
    """The process's :class:`~tfbus.clock.SimClock` following ``/clock`` on
    :func:`ros1_bus` (entered in the background loop on first use): the time of a rospy
    node with ``/use_sim_time``, as ``rospy.Time.now()`` reads it."""
    from tfbus.clock import SimClock

    bus = ros1_bus()
    return background.shared(f"ros1-clock:{os.environ.get('ROS_MASTER_URI', '')}",
                             lambda: SimClock(bus))


def rclpy_use_sim_time(node: object) -> bool:
    """Whether ``node`` is an rclpy node whose ``use_sim_time`` parameter is true: what
    makes its clock (``node.get_clock()``) simulated time, following ``/clock``
    (``rclpy/time_source.py``); False for anything else or when it cannot say."""
    get = getattr(node, "get_parameter", None)
    if get is None:
        return False
    try:
        return getattr(get("use_sim_time"), "value", False) is True
    except Exception:  # no such parameter (undeclared), or not an rclpy node
        return False


# node -> its SimClock (the node holds the /clock subscription); a node that is gone
# takes its entry with it, so a new node never inherits a clock fed by a dead one
_RCLPY_CLOCKS: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()
_RCLPY_CLOCKS_LOCK = threading.Lock()
_RCLPY_CLOCK_KEYS = itertools.count()


def rclpy_sim_clock(node: Any) -> Any:
    """A :class:`~tfbus.clock.SimClock` following ``/clock`` as the rclpy ``node`` with
    ``use_sim_time`` hears it, one per node: the node subscribes to ``/clock``
    (``rosgraph_msgs/Clock``, best-effort depth 1, as rclpy's ``TimeSource`` does) and
    each message is published on an in-process bus of the background loop, where the
    clock follows it (until the program ends, as the node's own time source). A stamp
    that is not a valid time (negative seconds), or one more than ``max_forward_step``
    ahead, is counted and dropped by the clock (``statistics().dropped``)."""
    from rclpy.qos import (  # type: ignore[import-not-found]
        QoSProfile,
        ReliabilityPolicy,
    )
    from rosgraph_msgs.msg import Clock as RosClock  # type: ignore[import-not-found]

    from tfbus.bus import Bus
    from tfbus.clock import SimClock
    from tfbus.messages import Clock as ClockMessage
    from tfbus.time import Time
    from tfbus.topics import CLOCK_TOPIC

    with _RCLPY_CLOCKS_LOCK:
        clock = _RCLPY_CLOCKS.get(node)
        if clock is not None:
            return clock
        key = f"rclpy-clock:{next(_RCLPY_CLOCK_KEYS)}"
        bus: Bus = background.shared(f"{key}:bus", Bus)
        clock = background.shared(key, lambda: SimClock(bus))

        def on_clock(message: Any) -> None:
            stamp = getattr(message, "clock", None)
            try:
                value: object = Time(int(stamp.sec), int(stamp.nanosec))  # type: ignore[union-attr]
            except (AttributeError, TypeError, ValueError):
                value = stamp  # not a Time: the clock counts and drops it
            background.call(bus.publish_nowait, CLOCK_TOPIC, ClockMessage(value))  # type: ignore[arg-type]

        node.create_subscription(
            RosClock, CLOCK_TOPIC, on_clock,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
        )
        _RCLPY_CLOCKS[node] = clock
        return clock


def in_event_loop() -> bool:
    """True when the calling thread runs an async event loop (asyncio or trio)."""
    try:
        import sniffio

        sniffio.current_async_library()
    except Exception:
        return False
    return True
