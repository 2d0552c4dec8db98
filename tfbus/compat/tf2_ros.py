"""``tf2_ros`` (ROS 2 call shapes, ROS 1 names where they differ) on tfbus.

``from tfbus.compat import tf2_ros`` in place of ``import tf2_ros``:

* :class:`Buffer`: ``lookup_transform(target, source, time, timeout=...)``,
  ``lookup_transform_full``, ``can_transform(..., return_debug_tuple=)``,
  ``can_transform_full``, ``transform``, ``transform_full`` wait up to ``timeout`` in the
  calling thread (tf2's semantics), woken by the arrival that answers them in the
  process's background loop (:mod:`tfbus.compat._loop`); from an event loop's thread a
  wait that would be needed raises :class:`~tfbus.compat._loop.LoopThreadError` (use the
  awaitable methods there). ``set_transform(_static)``, ``clear``,
  ``get_latest_common_time``, ``all_frames_as_yaml`` / ``all_frames_as_string``; the awaitable
  ``wait_for_transform_async``, ``wait_for_transform_full_async``,
  ``lookup_transform_async``, ``lookup_transform_full_async`` wait, with a ``timeout=``
  that works (ros2/geometry2 #327, PR #797), on :class:`tfbus.Buffer`'s event-driven
  waits.
* :class:`TransformListener` ``(buffer, node=None, *, bus=None)``: an rclpy node's
  ``/tf`` and ``/tf_static`` subscriptions, or a tfbus bus (``async with``), or — no node
  and no bus, ROS 1's idiom — the ROS 1 graph at ``ROS_MASTER_URI`` through tfbus's own
  ROS 1 transport, carried by the background loop.
* :class:`TransformBroadcaster`, :class:`StaticTransformBroadcaster` (``sendTransform``)
  on an rclpy node, a tfbus bus, or (no argument) the ROS 1 graph as the listener.
* :class:`BufferClient` (ROS 1): tf2_ros's ``LookupTransform`` action client on the
  same ROS 1 node, answered by a ``buffer_server``.
* Results in the caller's types (:mod:`tfbus.compat._types`): a rospy ``Time`` given,
  rospy messages and times returned; an rclpy one, rclpy's; a tfbus one, tfbus's.
* tf2's exceptions, :class:`TransformRegistration`, :class:`ConvertRegistration`,
  :func:`convert`, :func:`Stamped`. With them ROS 2 tf2's extrapolation subclasses
  ``ForwardExtrapolationException``, ``BackwardExtrapolationException`` and
  ``NoDataForExtrapolationException`` (``tf2/exceptions.h``), the very classes tfbus
  raises: ROS 2's Python ``tf2_py`` (``tf2_py/src/tf2_py.cpp``, geometry2 up to 0.39.1)
  catches them as ``tf2::ExtrapolationException`` and registers no Python class for
  them, so ``tf2_ros`` exports them here only (subclasses of the
  ``ExtrapolationException`` exported here: ``except ExtrapolationException`` catches
  them as in ROS 2).

tf2_ros's submodule paths (``tf2_ros.buffer``, ``tf2_ros.buffer_interface``,
``tf2_ros.transform_listener``, ``tf2_ros.transform_broadcaster``,
``tf2_ros.static_transform_broadcaster``, ``tf2_ros.buffer_client``) are registered as
modules holding the same names, so ``from tfbus.compat.tf2_ros.buffer import Buffer``
works as ``from tf2_ros.buffer import Buffer`` does.
"""

from __future__ import annotations

import contextlib
import logging
import math
import sys
import time as _wallclock
import types
from collections.abc import Callable, Iterable
from functools import partial
from numbers import Real
from typing import Any, TypeVar, cast

import anyio

from tfbus.broadcaster import StaticTransformBroadcaster as _StaticBroadcaster
from tfbus.broadcaster import TransformBroadcaster as _Broadcaster
from tfbus.buffer import Buffer as _Buffer
from tfbus.bus import Bus
from tfbus.clock import Clock
from tfbus.codecs.cdr import decode_tf
from tfbus.compat import tf2_geometry_msgs as _geometry
from tfbus.compat import tf2_sensor_msgs as _sensor
from tfbus.compat._args import to_duration, to_stamped, to_time, to_transform_stamped
from tfbus.compat._loop import (
    LoopThreadError,
    background,
    in_event_loop,
    rclpy_sim_clock,
    rclpy_use_sim_time,
    ros1_bus,
    ros1_sim_clock,
    rospy_node_name,
    rospy_shutting_down,
    rospy_use_sim_time,
)
from tfbus.compat._types import flavour_of, ros_message, ros_out, time_out
from tfbus.convert import ConvertRegistration, TransformRegistration, convert
from tfbus.errors import (
    BackwardExtrapolationException,
    ConnectivityException,
    ExtrapolationException,
    ForwardExtrapolationException,
    InvalidArgumentException,
    LookupException,
    NoDataForExtrapolationException,
    TimeoutException,
    TransformException,
    WireDecodeError,
)
from tfbus.listener import TransformListener as _Listener
from tfbus.messages import (
    Header,
    PointStamped,
    PoseStamped,
    TFMessage,
    TransformStamped,
    Vector3Stamped,
    WrenchStamped,
)
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import Duration, Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.transports.ros1.action import ActionClient, action_client

_log = logging.getLogger("tfbus.compat")
_T = TypeVar("_T")
_malformed_log = CountLimitedLog(_log, 1, period=5.0, clock=_wallclock.monotonic)

__all__ = [
    "DEFAULT_STATIC_TF_TOPIC",
    "DEFAULT_TF_TOPIC",
    "BackwardExtrapolationException",
    "Buffer",
    "BufferClient",
    "BufferInterface",
    "ConnectivityException",
    "ConvertRegistration",
    "ExtrapolationException",
    "ForwardExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "LoopThreadError",
    "NoDataForExtrapolationException",
    "Stamped",
    "StaticTransformBroadcaster",
    "TimeoutException",
    "TransformBroadcaster",
    "TransformException",
    "TransformListener",
    "TransformRegistration",
    "TransformStamped",
    "TypeException",
    "convert",
]

_DEBIAN: dict[type, Any] = {
    PointStamped: _geometry.do_transform_point,
    Vector3Stamped: _geometry.do_transform_vector3,
    PoseStamped: _geometry.do_transform_pose,
    WrenchStamped: _geometry.do_transform_wrench,
}
"""The types Debian's tf2_geometry_msgs registers, transformed by its arithmetic."""

_BY_FIELDS: dict[str, Any] = {"PointCloud2": _sensor.do_transform_cloud}
"""ROS message types (by class name) that tfbus reads by their fields, as
tf2_sensor_msgs registers ``PointCloud2``: the result in the message's own class."""

DEFAULT_TF_TOPIC = TF_TOPIC
"""tf2_ros ``DEFAULT_TF_TOPIC`` (``"/tf"``)."""
DEFAULT_STATIC_TF_TOPIC = TF_STATIC_TOPIC
"""tf2_ros ``DEFAULT_STATIC_TF_TOPIC`` (``"/tf_static"``)."""

TypeException = TypeError
"""tf2_ros's ``TypeException`` (no registered function for a type): tfbus raises
TypeError, exported under tf2_ros's name."""


_TIMEOUT_FORMS = ("a duration (rclpy Duration, builtin_interfaces Duration, rospy "
                  "Duration, tfbus Duration) or seconds (int, float), or None")


def _timeout(value: object, name: str = "timeout") -> float | None:
    """A ``timeout=`` in seconds for tfbus (None: wait forever, as ``math.inf``); zero
    (tf2_ros's default ``Duration()``) and a negative duration do not wait (tf2_ros's
    ``can_transform`` loop, ``while now < start + timeout``, never runs).

    Raises:
        TypeError: not a duration nor seconds (a str, a bool, a Time ...), naming
            ``name``, the value and the accepted forms.
        ValueError: NaN seconds.
    """
    if value is None:
        return None
    if isinstance(value, (bool, Time)) or not (
        isinstance(value, Real) or hasattr(value, "nanoseconds")
        or hasattr(value, "nanosec") or hasattr(value, "nsecs")
        or isinstance(value, Duration)
    ):
        raise TypeError(f"{name} must be {_TIMEOUT_FORMS}, got {_describe(value)}")
    if isinstance(value, Real) and math.isnan(float(value)):
        raise ValueError(f"{name} must not be NaN, got {value!r} ({_TIMEOUT_FORMS})")
    try:
        return to_duration(value, name).to_sec()
    except InvalidArgumentException:
        raise TypeError(f"{name} must be {_TIMEOUT_FORMS}, got {_describe(value)}") from None


def Stamped(obj: Any, stamp: object, frame_id: str) -> Any:
    """tf2_ros ``Stamped(obj, stamp, frame_id)``: ``obj`` with ``header = Header(stamp,
    frame_id)`` — a copy for tfbus's immutable messages (``_replace``), the same object
    (its attribute set) for a mutable one, as tf2_ros does."""
    header = Header(to_time(stamp, "stamp"), frame_id)
    replace = getattr(obj, "_replace", None)
    if callable(replace):
        return replace(header=header)
    obj.header = header
    return obj


class Buffer:
    """tf2_ros ``Buffer(cache_time=None, node=None)`` over a :class:`tfbus.Buffer`
    (``.buffer``; ``cache_time`` 10 s by default, a duration in any form). Time comes
    from ``clock``, a tfbus clock, by default the system clock; but simulated time, a
    :class:`~tfbus.clock.SimClock` following ``/clock``, as a node with ``use_sim_time``
    reads it: under an rclpy ``node`` (given here, or the first node of a
    :class:`TransformListener` on this buffer while it is still empty) whose
    ``use_sim_time`` parameter is true, ``/clock`` as that node hears it
    (``node.get_clock()``, rclpy's ``TimeSource``); in an initialised rospy node whose
    ``/use_sim_time`` parameter is true, ``/clock`` on the ROS 1 graph, as
    ``rospy.Time.now()``. On simulated time the buffer belongs to the background loop
    (the loop the clock's ``/clock`` arrives in).

    Thread use: once a background listener feeds it (or a blocking call had to wait),
    the buffer belongs to the process's background loop and every call from another
    thread runs there (``portal.call``), as tf2_ros's buffer takes its mutex."""

    registration = TransformRegistration()
    """The transform functions by type (tf2_ros ``BufferInterface.registration``)."""

    def __init__(
        self, cache_time: object = None, node: object = None, *, clock: Clock | None = None,
        debug: bool = True,
    ) -> None:
        """Create the buffer (see the class docs). ``debug`` (ROS 1's): in an initialised
        rospy node, offer the ``~tf2_frames`` service as ROS 1's Buffer does."""
        seconds = 10.0 if cache_time is None else to_duration(cache_time, "cache_time")
        self._seconds = seconds
        self._clock_chosen = clock is not None
        sim = False
        if clock is None and rclpy_use_sim_time(node):  # rclpy's simulated time: /clock
            clock, sim = rclpy_sim_clock(node), True
        elif clock is None and rospy_use_sim_time():  # rospy's simulated time: /clock
            clock, sim = ros1_sim_clock(), True
        self._clock_chosen = self._clock_chosen or sim
        self.buffer = _Buffer(seconds, clock=clock)
        self.node = node
        self._owned = sim  # the SimClock's loop runs this buffer's calls
        self._flavour: str | None = None
        self.frame_server: Any = None
        if debug and rospy_node_name() is not None:
            self._serve_frames()

    def _serve_frames(self) -> None:
        """ROS 1 tf2_ros ``Buffer(debug=True)``: the rospy service ``~tf2_frames``
        (``tf2_msgs/FrameGraph``, answered with :meth:`all_frames_as_yaml`) unless the
        node advertises one already (Debian's ``tf2_ros/buffer.py``); view_frames asks it."""
        import rosgraph.masterapi  # type: ignore[import-not-found]
        import rospy  # type: ignore[import-not-found]
        from tf2_msgs.srv import FrameGraph, FrameGraphResponse  # type: ignore[import-not-found]

        try:
            rosgraph.masterapi.Master(rospy.get_name()).lookupService("~tf2_frames")
        except (rosgraph.masterapi.Error, rosgraph.masterapi.Failure):
            self.frame_server = rospy.Service(
                "~tf2_frames", FrameGraph,
                lambda _request: FrameGraphResponse(self.all_frames_as_yaml()),
            )

    # ---------------------------------------------------------------- threads

    def _own(self) -> None:
        """From now on the background loop runs this buffer's calls."""
        self._owned = True

    def _follow_node_time(self, node: Any) -> bool:
        """Put this buffer on ``node``'s simulated time (rclpy ``use_sim_time``) when no
        clock was chosen for it and it holds nothing yet; True when it did."""
        if self._clock_chosen or not rclpy_use_sim_time(node):
            return False
        self._clock_chosen = True
        if self.buffer.get_frame_names():
            _log.warning("tf2_ros.Buffer: node %s has use_sim_time, but this buffer already "
                         "holds transforms on the system clock: it stays on it",
                         getattr(node, "get_name", lambda: "?")())
            return False
        self.buffer.close()
        self.buffer = _Buffer(self._seconds, clock=rclpy_sim_clock(node))
        self._owned = True
        return True

    def _run(self, fn: Any, *args: object) -> Any:
        if self._owned and not background.in_loop_thread():
            return background.call(fn, *args)
        return fn(*args)

    def _blocking(self, now: Any, wait: Any, timeout: object) -> Any:
        """``now()``; when it raises a TransformException and ``timeout`` is positive,
        ``wait(seconds)`` (a coroutine function) run in the background loop, this thread
        blocked until it ends (woken by the arrival that answers it). ``timeout`` is
        checked first (:func:`_timeout`), whether or not a wait is needed."""
        seconds = _timeout(timeout)
        try:
            return self._run(now)
        except TransformException:
            if seconds is not None and seconds <= 0.0:
                raise
            if seconds is None and timeout is None:
                raise  # tf2's default timeout: Duration(0), do not wait
            if background.in_loop_thread() or in_event_loop():
                raise LoopThreadError(
                    "a blocking tf2 call with a timeout cannot wait in an event loop's "
                    "own thread (it would block the loop that delivers the data): await "
                    "lookup_transform_async / wait_for_transform_async there"
                ) from None
            self._own()
            return background.call(wait, seconds)

    def _flavoured(self, *values: object) -> str | None:
        found = flavour_of(*values)
        if found is not None:
            self._flavour = found
        return found

    # ---------------------------------------------------------------- data

    def set_transform(self, transform: Any, authority: str) -> None:
        """tf2 ``set_transform`` (returns None, as ROS 2's):
        :meth:`tfbus.BufferCore.set_transform`."""
        ts = to_transform_stamped(transform)
        self._flavoured(getattr(getattr(transform, "header", None), "stamp", None))
        self._run(self.buffer.set_transform, ts, authority)

    def set_transform_static(self, transform: Any, authority: str) -> None:
        """tf2 ``set_transform_static`` (returns None):
        :meth:`tfbus.BufferCore.set_transform_static`."""
        ts = to_transform_stamped(transform)
        self._flavoured(getattr(getattr(transform, "header", None), "stamp", None))
        self._run(self.buffer.set_transform_static, ts, authority)

    def clear(self) -> None:
        """tf2 ``clear``: :meth:`tfbus.BufferCore.clear`."""
        self._run(self.buffer.clear)

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Any:
        """tf2 ``get_latest_common_time``: :meth:`tfbus.BufferCore.get_latest_common_time`,
        in the caller's time type (rospy / rclpy ``Time`` when the buffer was fed or
        queried with those, else a tfbus Time)."""
        t = self._run(self.buffer.get_latest_common_time, target_frame, source_frame)
        return time_out(t, self._flavour)

    def all_frames_as_yaml(self, current_time: object = None) -> str:
        """tf2 ``all_frames_as_yaml``: :meth:`tfbus.BufferCore.all_frames_as_yaml`."""
        when = None if current_time is None else to_time(current_time, "current_time")
        return str(self._run(self.buffer.all_frames_as_yaml, when))

    def all_frames_as_string(self) -> str:
        """tf2 ``all_frames_as_string``: :meth:`tfbus.BufferCore.all_frames_as_string`."""
        return str(self._run(self.buffer.all_frames_as_string))

    # ---------------------------------------------------------------- blocking

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: object, timeout: object = None
    ) -> Any:
        """tf2_ros ``lookup_transform``, waiting up to ``timeout`` (a duration of any
        flavour or seconds; None, zero or negative: answer now, as tf2_ros, whose wait
        loop ``while now < start + timeout`` never runs then) in the calling thread.

        Returns:
            the TransformStamped, a rospy / rclpy message when ``time`` is one of theirs.

        Raises:
            LookupException, ConnectivityException, ExtrapolationException: now, or
                when ``timeout`` passed without the data (tf2 raises the lookup's
                exception after its wait too).
            TypeError: ``timeout`` is not a duration nor seconds (a str, a bool ...);
                ValueError: NaN. Both name the value and are checked before the lookup
                (the same for every ``timeout`` of this class).
            LoopThreadError: a wait needed from an event loop's thread.
        """
        t = to_time(time)
        flavour = self._flavoured(time)
        out = self._blocking(
            partial(self.buffer.lookup_transform, target_frame, source_frame, t),
            partial(self._wait_lookup, target_frame, source_frame, t), timeout,
        )
        return ros_message(out, flavour, "TransformStamped")

    async def _wait_lookup(
        self, target: str, source: str, t: Time, seconds: float | None
    ) -> TransformStamped:
        try:
            return await self.buffer.lookup_transform_async(target, source, t, seconds)
        except TimeoutException:
            return self.buffer.lookup_transform(target, source, t)  # tf2's own exception

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
    ) -> Any:
        """tf2_ros ``lookup_transform_full``, waiting up to ``timeout`` as
        :meth:`lookup_transform`."""
        tt, st = to_time(target_time, "target_time"), to_time(source_time, "source_time")
        flavour = self._flavoured(target_time, source_time)
        args: tuple[str, Time, str, Time, str] = (
            target_frame, tt, source_frame, st, fixed_frame)
        out = self._blocking(partial(self.buffer.lookup_transform_full, *args),
                             partial(self._wait_full, args), timeout)
        return ros_message(out, flavour, "TransformStamped")

    async def _wait_full(
        self, args: tuple[str, Time, str, Time, str], seconds: float | None
    ) -> TransformStamped:
        try:
            return await self.buffer.lookup_transform_full_async(*args, seconds)
        except TimeoutException:
            return self.buffer.lookup_transform_full(*args)

    def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: object,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``can_transform``, waiting up to ``timeout`` for the data as
        :meth:`lookup_transform` (False, or ``(False, reason)``, when it passes)."""
        t = to_time(time)
        self._flavoured(time)
        with contextlib.suppress(TransformException):
            self._blocking(
                partial(self.buffer.lookup_transform, target_frame, source_frame, t),
                partial(self._wait_lookup, target_frame, source_frame, t), timeout,
            )
        return self._run(self.buffer.can_transform, target_frame, source_frame, t,  # type: ignore[no-any-return]
                         return_debug_tuple)

    def can_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``can_transform_full``, waiting up to ``timeout`` as
        :meth:`can_transform`."""
        tt, st = to_time(target_time, "target_time"), to_time(source_time, "source_time")
        self._flavoured(target_time, source_time)
        args = (target_frame, tt, source_frame, st, fixed_frame)
        with contextlib.suppress(TransformException):
            self._blocking(partial(self.buffer.lookup_transform_full, *args),
                           partial(self._wait_full, args), timeout)
        return self._run(self.buffer.can_transform_full, *args,  # type: ignore[no-any-return]
                         return_debug_tuple)

    def _apply(self, obj: Any, given: Any, ts: Any) -> Any:
        """``obj`` (tfbus's reading of ``given``) transformed by ``ts``: Debian's types and
        a ROS ``PointCloud2`` in the type of ``given``, the other registered types as
        their function returns (in the class of ``given`` when it is a rospy or rclpy
        message of the type returned)."""
        fn = _DEBIAN.get(type(obj))
        if fn is not None:
            return fn(given, ts)
        try:
            registered = self.registration.get(type(obj))
        except TypeError:
            # A ROS message of a type tfbus transforms by its fields (a rospy or rclpy
            # PointCloud2, which tf2_sensor_msgs registers): that function, unless the
            # program registered one for its class.
            by_fields = _BY_FIELDS.get(type(obj).__name__)
            if by_fields is None:
                raise
            return by_fields(given, ts)
        # A registered tfbus function's result in the class of a rospy / rclpy message
        # given (a PoseWithCovarianceStamped, PolygonStamped, TransformStamped...).
        return ros_out(registered(obj, to_transform_stamped(ts)), given)

    def transform(
        self,
        object_stamped: Any,
        target_frame: str,
        timeout: object = None,
        new_type: Any = None,
    ) -> Any:
        """tf2_ros ``transform``: :meth:`lookup_transform` ``(target_frame,
        header.frame_id, header.stamp, timeout)`` applied to the object — points,
        vectors, poses and wrenches by Debian's arithmetic
        (:mod:`tfbus.compat.tf2_geometry_msgs`, the result in the object's own type),
        other types by the registered function; converted to ``new_type`` by
        :func:`convert` when given."""
        obj = to_stamped(object_stamped)
        header = obj.header  # type: ignore[attr-defined]
        ts = self.lookup_transform(target_frame, header.frame_id, header.stamp, timeout)
        if new_type is not None:  # converted from the tfbus result, by the registries
            return convert(self._apply(obj, obj, ts), new_type)
        return self._apply(obj, object_stamped, ts)

    def transform_full(
        self,
        object_stamped: Any,
        target_frame: str,
        target_time: object,
        fixed_frame: str,
        timeout: object = None,
        new_type: Any = None,
    ) -> Any:
        """tf2_ros ``transform_full``: as :meth:`transform`, through ``fixed_frame``."""
        obj = to_stamped(object_stamped)
        header = obj.header  # type: ignore[attr-defined]
        ts = self.lookup_transform_full(
            target_frame, target_time, header.frame_id, header.stamp, fixed_frame, timeout
        )
        if new_type is not None:  # converted from the tfbus result, by the registries
            return convert(self._apply(obj, obj, ts), new_type)
        return self._apply(obj, object_stamped, ts)

    # ---------------------------------------------------------------- awaitable

    def _awaitable(self, coro: Any, flavour: str | None) -> Any:
        """``coro`` for an async caller (asyncio / trio: awaited in its own loop); for an
        rclpy caller (rclpy imported, no async library running in this thread) an
        ``rclpy.task.Future`` completed by the background loop, as ROS 2's tf2_ros
        returns — awaitable in rclpy coroutine callbacks; with ``Buffer(node=...)`` the
        node's executor is woken when it completes."""
        rclpy = sys.modules.get("rclpy")
        if rclpy is None or in_event_loop():
            return coro
        from rclpy.task import Future as RclpyFuture  # type: ignore[import-not-found]

        executor = getattr(self.node, "executor", None)
        future: Any = RclpyFuture(executor=executor)
        future.add_done_callback(lambda _f: None)  # a done callback wakes the executor
        self._own()

        async def run() -> None:
            try:
                value = await coro
            except BaseException as exc:  # handed to the future, as rclpy's tasks do
                future.set_exception(exc)
                if not isinstance(exc, Exception):
                    raise
            else:
                future.set_result(value if flavour is None else ros_message(
                    value, flavour, "TransformStamped") if isinstance(
                        value, TransformStamped) else value)

        background.portal().start_task_soon(run)
        return future

    def wait_for_transform_async(
        self, target_frame: str, source_frame: str, time: object, *, timeout: object = None
    ) -> Any:
        """ROS 2 ``wait_for_transform_async``: True once the transform is available
        (:meth:`tfbus.Buffer.wait_for_transform`) — an awaitable under asyncio / trio,
        an ``rclpy.task.Future`` under rclpy (see :meth:`_awaitable`).

        Raises (or sets on the future):
            TimeoutException: not within ``timeout`` (a duration or seconds; None:
                no limit).
        """
        t, seconds = to_time(time), _timeout(timeout)

        async def wait() -> bool:
            await self.buffer.wait_for_transform(target_frame, source_frame, t, seconds)
            return True

        return self._awaitable(wait(), None)

    def wait_for_transform_full_async(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        *,
        timeout: object = None,
    ) -> Any:
        """ROS 2 ``wait_for_transform_full_async``: True once both legs are available
        (:meth:`tfbus.Buffer.lookup_transform_full_async`); an awaitable or an rclpy
        Future as :meth:`wait_for_transform_async`."""
        tt, st = to_time(target_time, "target_time"), to_time(source_time, "source_time")
        seconds = _timeout(timeout)

        async def wait() -> bool:
            await self.buffer.lookup_transform_full_async(
                target_frame, tt, source_frame, st, fixed_frame, seconds)
            return True

        return self._awaitable(wait(), None)

    def lookup_transform_async(
        self, target_frame: str, source_frame: str, time: object, *, timeout: object = None
    ) -> Any:
        """ROS 2 ``lookup_transform_async``: :meth:`tfbus.Buffer.lookup_transform_async`
        — an awaitable under asyncio / trio (a tfbus TransformStamped), an rclpy Future
        under rclpy (an rclpy TransformStamped), with a ``timeout`` that works."""
        coro = self.buffer.lookup_transform_async(
            target_frame, source_frame, to_time(time), _timeout(timeout))
        return self._awaitable(coro, flavour_of(time))

    def lookup_transform_full_async(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        *,
        timeout: object = None,
    ) -> Any:
        """ROS 2 ``lookup_transform_full_async``:
        :meth:`tfbus.Buffer.lookup_transform_full_async`; an awaitable or an rclpy
        Future as :meth:`lookup_transform_async`."""
        coro = self.buffer.lookup_transform_full_async(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame, _timeout(timeout),
        )
        return self._awaitable(coro, flavour_of(target_time, source_time))


def _is_bus(value: object) -> bool:
    return isinstance(value, Bus)


def _unless_rospy_ended(work: Callable[[], _T]) -> _T | None:
    """``work()`` (a call into the background loop that carries the ROS 1 graph), or
    None, nothing done, once rospy's shutdown has begun (:func:`rospy_shutting_down`),
    also when it began during the call and made it fail. A hook of rospy's shutdown stops
    the loop, which leaves the graph; a callback of rospy's threads still sending then
    neither fails nor starts the loop again, as rospy drops a publish to a topic its
    shutdown closed (``rospy/topics.py``, ``_PublisherImpl.publish``).

    Raises:
        whatever ``work`` raises outside rospy's shutdown.
    """
    if rospy_shutting_down():
        return None
    try:
        return work()
    except Exception:
        if rospy_shutting_down():
            return None
        raise


def _describe(value: object) -> str:
    """``value``'s type and a short repr, for an error message."""
    text = repr(value)
    return f"{type(value).__name__} {text[:60] + '...' if len(text) > 60 else text}"


def _check_node(who: str, node: object, method: str) -> None:
    """A TypeError naming ``node`` and its type unless it is a tfbus Bus or has an rclpy
    node's ``method`` (so a wrong argument is not reported as a missing rclpy)."""
    if not callable(getattr(node, method, None)):
        raise TypeError(f"{who}: node must be an rclpy Node or a tfbus.Bus, got "
                        f"{_describe(node)}")


class TransformListener:
    """tf2_ros ``TransformListener(buffer, node)``: fills ``buffer`` (a compat
    :class:`Buffer` or a :class:`tfbus.Buffer`) from an rclpy node's ``/tf`` and
    ``/tf_static`` (subscribed here, as ROS 2 does, with the same QoS; messages taken
    serialized and decoded by tfbus's CDR codec), or,
    with ``bus=``, from a tfbus bus through :class:`tfbus.TransformListener` (enter it
    with ``async with``), or — ROS 1's ``TransformListener(buffer)``, no node — from the
    ROS 1 graph at ``ROS_MASTER_URI``: tfbus's own ROS 1 transport
    (:func:`tfbus.compat._loop.ros1_bus`, one node per process, named after the rospy
    node plus ``_tf2``) in the process's background loop, listening at once and until
    the program ends.

    Attributes:
        malformed: on an rclpy node, the TFMessages that could not be decoded (a
            truncated sample, a frame id that is not UTF-8, a stamp before 1970): each
            is counted, logged (at most one line per 5 s) and dropped; the node's other
            messages are stored as usual. Transforms that decode but are invalid (NaN,
            a zero quaternion, an empty frame id) are refused one by one by the buffer,
            as tf2's ``setTransform`` does.
    """

    def __init__(
        self, buffer: Buffer | _Buffer, node: object = None, *, bus: Bus | None = None,
        **_ros_options: object,
    ) -> None:
        """Attach to ``node`` (rclpy), ``bus``, or the ROS 1 graph; ``qos``,
        ``spin_thread``, ``queue_size``, ``buff_size``, ``tcp_nodelay`` and other ROS
        options are accepted and unused.

        Raises:
            RuntimeError: no node and no bus, and the ROS 1 graph could not be joined
                (the reason chained).
        """
        if isinstance(buffer, Buffer) and node is not None and not _is_bus(node):
            buffer._follow_node_time(node)  # an rclpy node with use_sim_time
        self.buffer = buffer.buffer if isinstance(buffer, Buffer) else buffer
        self._compat = buffer if isinstance(buffer, Buffer) else None
        self._inner: _Listener | None = None
        self._subscriptions: list[Any] = []
        self.group: Any = None  # rclpy: the subscriptions' ReentrantCallbackGroup
        self.malformed = 0  # rclpy: TFMessages dropped because they cannot be decoded
        if bus is not None or _is_bus(node):
            chosen = bus if bus is not None else node
            if not isinstance(chosen, Bus):
                raise TypeError("TransformListener: bus must be a tfbus.Bus, got "
                                f"{_describe(chosen)}")
            self._inner = _Listener(self.buffer, chosen)
        elif node is not None:
            _check_node("TransformListener", node, "create_subscription")
            self._attach_rclpy(node)
        else:  # ROS 1's TransformListener(buffer): the ROS 1 graph, in the background loop
            if isinstance(buffer, Buffer):
                buffer._own()
            self._inner = _Listener(self.buffer, ros1_bus())
            background.enter(self._inner)

    def _attach_rclpy(self, node: Any) -> None:
        """The two subscriptions of ROS 2's ``tf2_ros/transform_listener.py``: same QoS,
        and their own ``ReentrantCallbackGroup``, so that a callback of the node's
        default (mutually exclusive) group may block in ``lookup_transform(...,
        timeout)`` under a ``MultiThreadedExecutor`` while ``/tf`` is still delivered.

        Taken serialized (``raw=True``) and decoded by :func:`tfbus.codecs.cdr.decode_tf`
        in the callback, not by rclpy: rclpy builds a message object by running the
        message classes' Python code inside ``take_message``
        (``rclpy/src/rclpy/subscription.cpp``), so a SIGINT landing there becomes a
        ``RuntimeError`` ("Unable to convert call argument '0' to Python object") out of
        ``rclpy.spin`` instead of the ``KeyboardInterrupt`` a program catches to end.
        Taken as bytes, no Python code runs inside the take, and the interrupt arrives
        in Python code, as itself."""
        from rclpy.callback_groups import (  # type: ignore[import-not-found]
            ReentrantCallbackGroup,
        )
        from rclpy.qos import (  # type: ignore[import-not-found]
            DurabilityPolicy,
            HistoryPolicy,
            QoSProfile,
        )
        from tf2_msgs.msg import TFMessage as RosTFMessage  # type: ignore[import-not-found]

        dynamic = QoSProfile(depth=100)
        static = QoSProfile(
            depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
            history=HistoryPolicy.KEEP_LAST,
        )
        self.group = ReentrantCallbackGroup()
        self._subscriptions = [
            node.create_subscription(RosTFMessage, TF_TOPIC, self._on_tf, dynamic,
                                     callback_group=self.group, raw=True),
            node.create_subscription(RosTFMessage, TF_STATIC_TOPIC, self._on_static, static,
                                     callback_group=self.group, raw=True),
        ]

    def _set(self, data: bytes, static: bool) -> None:
        try:
            ours = decode_tf(data).transforms
        except WireDecodeError as exc:
            self.malformed += 1
            _malformed_log.log(logging.WARNING, "TransformListener: a TFMessage on %s that "
                               "cannot be decoded was dropped: %s",
                               TF_STATIC_TOPIC if static else TF_TOPIC, exc)
            return
        if self._compat is not None and self._compat._owned:  # the background loop's
            background.call(self.buffer.set_transforms, ours, "default_authority", static)
        else:
            self.buffer.set_transforms(ours, "default_authority", is_static=static)

    def _on_tf(self, data: bytes) -> None:
        self._set(data, False)

    def _on_static(self, data: bytes) -> None:
        self._set(data, True)

    async def __aenter__(self) -> TransformListener:
        """Start the bus listener (a node's subscriptions are live already)."""
        if self._inner is not None:
            await self._inner.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Stop the bus listener."""
        if self._inner is not None:
            await self._inner.__aexit__(*exc)  # type: ignore[arg-type]

    def unregister(self) -> None:
        """tf2_ros ``unregister``: drop an rclpy node's subscriptions (the bus listener
        stops when its ``async with`` ends)."""
        for sub in self._subscriptions:
            sub.destroy()
        self._subscriptions = []


_NO_NODE: Any = object()
"""The default of a broadcaster's ``node``: no argument given (ROS 1's idiom), told from
an explicit ``None``."""


class TransformBroadcaster:
    """tf2_ros ``TransformBroadcaster(node)``: ``sendTransform(t)`` publishes one
    transform or a list as one TFMessage on ``/tf`` — on an rclpy node (its own
    publisher; rclpy messages built from the fields) or a tfbus bus."""

    _topic = TF_TOPIC
    _static = False

    def __init__(self, node: object = _NO_NODE, qos: object = None,
                 **_ros_options: object) -> None:
        """Publish on ``node`` (rclpy), on a tfbus :class:`~tfbus.Bus`, or — no
        argument, ROS 1's ``TransformBroadcaster()`` — on the ROS 1 graph at
        ``ROS_MASTER_URI`` (tfbus's ROS 1 transport in the background loop, advertised
        now as tf2_ros does; ``queue_size`` and other rospy options accepted and unused).

        Raises:
            TypeError: ``node`` is given but is neither an rclpy Node nor a tfbus Bus
                (``None`` included: ROS 2's ``TransformBroadcaster(node)`` needs a node,
                most often a ``self.node`` not yet set); the message names the value and
                what is accepted.
        """
        self._bus_side: _Broadcaster | None = None
        self._publisher: Any = None
        self._background = False
        if node is None:
            raise TypeError(
                f"{type(self).__name__}: node must be an rclpy Node or a tfbus.Bus, got "
                f"None (for ROS 1's graph at ROS_MASTER_URI give no argument: "
                f"{type(self).__name__}())")
        if node is _NO_NODE:
            self._background = True  # None once rospy's shutdown began: nothing is sent
            kind = _StaticBroadcaster if self._static else _Broadcaster
            self._bus_side = _unless_rospy_ended(lambda: background.call(kind, ros1_bus()))
        elif isinstance(node, Bus):
            self._bus_side = _StaticBroadcaster(node) if self._static else _Broadcaster(node)
        else:
            _check_node(type(self).__name__, node, "create_publisher")
            from rclpy.qos import DurabilityPolicy, QoSProfile
            from tf2_msgs.msg import TFMessage as RosTFMessage

            profile = qos if qos is not None else QoSProfile(depth=100)
            if self._static and qos is None:
                profile = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._publisher = node.create_publisher(  # type: ignore[attr-defined]
                RosTFMessage, self._topic, profile
            )
        self._latched: dict[str, TransformStamped] = {}

    def sendTransform(self, transform: Any) -> None:
        """Publish ``transform`` (one, or an iterable of them, any flavour). On the ROS 1
        graph, once rospy's shutdown has begun (``rospy.signal_shutdown``, Ctrl-C),
        nothing is sent and nothing is raised, as rospy's own publishers do then.

        Raises:
            InvalidArgumentException: a transform without ROS's fields (named).
        """
        items = [transform] if not isinstance(transform, Iterable) or hasattr(
            transform, "child_frame_id"
        ) else list(transform)
        ours = [to_transform_stamped(t) for t in items]
        if self._static:  # tf2_ros keeps every static transform sent, by child frame
            self._latched.update((t.child_frame_id, t) for t in ours)
            ours = list(self._latched.values())
        if self._background:
            bus_side = self._bus_side
            if bus_side is not None:
                _unless_rospy_ended(
                    lambda: background.call(bus_side.send_transform_nowait, ours))
        elif self._bus_side is not None:
            self._bus_side.send_transform_nowait(ours)
        else:
            self._publisher.publish(_to_rclpy(TFMessage(ours)))


class StaticTransformBroadcaster(TransformBroadcaster):
    """tf2_ros ``StaticTransformBroadcaster(node)``: as :class:`TransformBroadcaster`
    on ``/tf_static`` (transient local); every transform sent so far is re-sent, one
    per child frame, as tf2_ros does."""

    _topic = TF_STATIC_TOPIC
    _static = True


def _to_rclpy(message: TFMessage) -> Any:
    """A ``tf2_msgs.msg.TFMessage`` (rclpy) with the fields of a tfbus TFMessage."""
    from builtin_interfaces.msg import Time as RosTime  # type: ignore[import-not-found]
    from geometry_msgs.msg import (  # type: ignore[import-not-found]
        TransformStamped as RosTransformStamped,
    )
    from tf2_msgs.msg import TFMessage as RosTFMessage

    out = []
    for t in message.transforms:
        m = RosTransformStamped()
        m.header.frame_id = t.header.frame_id
        m.header.stamp = RosTime(sec=t.header.stamp.sec, nanosec=t.header.stamp.nanosec)
        m.child_frame_id = t.child_frame_id
        tr, q = t.transform
        m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = tr
        (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
         m.transform.rotation.w) = q
        out.append(m)
    return RosTFMessage(transforms=out)


BufferInterface = Buffer
"""ROS 1 tf2_ros ``BufferInterface`` (the base of ``Buffer`` and ``BufferClient``):
here :class:`Buffer`, which has its whole interface (``transform``, ``lookup_transform``,
``can_transform`` and their ``_full`` forms, ``registration``)."""


class BufferClient(Buffer):
    """ROS 1 tf2_ros ``BufferClient(ns, check_frequency=None, timeout_padding=2 s)``
    (Debian's ``tf2_ros/buffer_client.py``): every lookup is a goal of tf2_ros's
    ``LookupTransform`` action (``tf2_msgs/LookupTransformAction``) sent to the buffer
    server at ``ns`` (a ``tf2_ros buffer_server`` node, or tfbus's
    :class:`tfbus.remote.BufferServer` on a ROS 1 bus), which waits up to the call's
    ``timeout`` for the transform and answers with it or with a ``TF2Error``.

    The action's topics (``{ns}/goal``, ``cancel``, ``result``, ``status``) are carried
    by the process's one ROS 1 node (:func:`tfbus.compat._loop.ros1_bus`, the node of
    the ROS 1 :class:`TransformListener` and broadcasters), no second node; the calls
    block their thread until the result comes (woken by it, through the background
    loop), as actionlib's ``wait_for_result`` does.

    Differences from tf2_ros's: a goal whose wait ends here unanswered is cancelled on
    the server (``{ns}/cancel``; tf2_ros's client leaves it there); a lookup sent
    before the server is connected waits for it within the same bound (actionlib drops
    a goal sent before the server's node subscribed). ``check_frequency`` is accepted
    and unused (deprecated in tf2_ros too). The local-buffer methods inherited from
    :class:`Buffer` (``set_transform``, ``all_frames_as_yaml``...) are not the server's:
    tf2_ros's BufferClient has none.
    """

    def __init__(self, ns: str = "tf2_buffer_server", check_frequency: object = None,
                 timeout_padding: object = None) -> None:
        """Join the ROS 1 graph (the process's node, in the background loop) and
        advertise the action's goal and cancel topics under ``ns``;
        ``timeout_padding`` (a duration of any flavour or seconds; default 2 s) is added
        to each call's ``timeout`` to bound its wait for the result.

        Raises:
            ValueError: ``ns`` is not a ROS graph name, or ``timeout_padding`` is
                negative or not finite (named).
            RuntimeError: the ROS 1 graph could not be joined (the reason chained).
        """
        super().__init__(debug=False)
        self.ns = ns
        padding = 2.0 if timeout_padding is None else _timeout(timeout_padding,
                                                               "timeout_padding")
        if padding is None or not 0.0 <= padding < math.inf:
            raise ValueError(f"timeout_padding must be finite seconds >= 0, got "
                             f"{timeout_padding!r}")
        self.timeout_padding = padding
        bus = ros1_bus()
        self.client: ActionClient = background.call(action_client, bus.transport, ns)

    def _not_in_loop(self) -> None:
        if background.in_loop_thread() or in_event_loop():
            raise LoopThreadError(
                "BufferClient's calls block until the server answers: they cannot run in "
                "an event loop's own thread (use tfbus.remote.BufferClient(bus) there)")

    def wait_for_server(self, timeout: object = None) -> bool:
        """tf2_ros ``wait_for_server``: block until the action server is connected
        (actionlib's condition, :meth:`ActionClient.ready`), at most ``timeout`` (a
        duration of any flavour or seconds; None or zero, actionlib's default
        ``Duration()``: no limit).

        Returns:
            True once the server is there; False when ``timeout`` passed first.

        Raises:
            LoopThreadError: called from an event loop's thread.
        """
        self._not_in_loop()
        seconds = _timeout(timeout)
        limit = math.inf if seconds is None or seconds <= 0.0 else seconds
        client = self.client

        async def wait() -> bool:
            with anyio.move_on_after(limit):
                await client.wait_ready()
                return True
            return False

        return bool(background.call(cast(Any, wait)))

    def _goal(self, target: str, source: str, source_time: Time, timeout: object,
              target_time: Time, fixed: str, advanced: bool) -> TransformStamped:
        seconds = _timeout(timeout)
        seconds = 0.0 if seconds is None else seconds
        if not 0.0 <= seconds < math.inf:
            raise ValueError(f"timeout must be finite seconds >= 0, got {timeout!r}")
        self._not_in_loop()
        lookup: Any = self.client.lookup
        out: TransformStamped = background.call(lookup, target, source, source_time, seconds,
                                                target_time, fixed, advanced,
                                                self.timeout_padding)
        return out

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: object, timeout: object = None
    ) -> Any:
        """tf2_ros ``BufferClient.lookup_transform``: the server's transform from
        ``source_frame`` to ``target_frame`` at ``time`` (0: the latest), the server
        waiting up to ``timeout`` (None or zero: not at all) for it.

        Returns:
            the TransformStamped, a rospy message when ``time`` is a rospy Time.

        Raises:
            LookupException, ConnectivityException, ExtrapolationException,
                InvalidArgumentException, TimeoutException, TransformException: the
                server's ``TF2Error`` (its message kept).
            TimeoutException: no result within ``timeout + timeout_padding`` (the goal is
                then cancelled on the server), or a result whose status is not
                SUCCEEDED.
            LoopThreadError: called from an event loop's thread.
        """
        flavour = self._flavoured(time)
        out = self._goal(target_frame, source_frame, to_time(time), timeout, Time(0), "",
                         False)
        return ros_message(out, flavour, "TransformStamped")

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
    ) -> Any:
        """tf2_ros ``BufferClient.lookup_transform_full`` (the goal's advanced form,
        through ``fixed_frame``). Returns and raises as :meth:`lookup_transform`."""
        flavour = self._flavoured(target_time, source_time)
        out = self._goal(target_frame, source_frame, to_time(source_time, "source_time"),
                         timeout, to_time(target_time, "target_time"), fixed_frame, True)
        return ros_message(out, flavour, "TransformStamped")

    def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: object,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``BufferClient.can_transform``: whether :meth:`lookup_transform`
        succeeds (any TransformException: False; with ``return_debug_tuple``,
        ``(False, its message)``)."""
        try:
            self.lookup_transform(target_frame, source_frame, time, timeout)
        except TransformException as exc:
            return (False, str(exc)) if return_debug_tuple else False
        return (True, "") if return_debug_tuple else True

    def can_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``BufferClient.can_transform_full``: whether
        :meth:`lookup_transform_full` succeeds, as :meth:`can_transform`."""
        try:
            self.lookup_transform_full(target_frame, target_time, source_frame, source_time,
                                       fixed_frame, timeout)
        except TransformException as exc:
            return (False, str(exc)) if return_debug_tuple else False
        return (True, "") if return_debug_tuple else True


def _submodule(name: str, names: list[str], doc: str) -> None:
    """Register ``tfbus.compat.tf2_ros.<name>`` holding ``names`` (tf2_ros's path)."""
    module = types.ModuleType(f"{__name__}.{name}", doc)
    here = sys.modules[__name__]
    for n in names:
        setattr(module, n, getattr(here, n))
    module.__all__ = names  # type: ignore[attr-defined]
    sys.modules[module.__name__] = module
    setattr(here, name, module)


_submodule("buffer", ["Buffer"], "tf2_ros.buffer: :class:`Buffer`.")
_submodule("buffer_interface", ["BufferInterface", "Stamped", "TransformRegistration",
                                "ConvertRegistration", "convert", "TypeException"],
           "tf2_ros.buffer_interface: the interface, registries and :func:`convert`.")
_submodule("buffer_client", ["BufferClient"], "tf2_ros.buffer_client: :class:`BufferClient`.")
_submodule("transform_listener", ["TransformListener"],
           "tf2_ros.transform_listener: :class:`TransformListener`.")
_submodule("transform_broadcaster", ["TransformBroadcaster"],
           "tf2_ros.transform_broadcaster: :class:`TransformBroadcaster`.")
_submodule("static_transform_broadcaster", ["StaticTransformBroadcaster"],
           "tf2_ros.static_transform_broadcaster: :class:`StaticTransformBroadcaster`.")
