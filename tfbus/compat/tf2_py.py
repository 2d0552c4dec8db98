"""``tf2_py.BufferCore`` (Debian's tf2_py 0.7.6, ROS 1 geometry2) on tfbus.

``from tfbus.compat import tf2_py`` in place of ``import tf2_py``: the same class and
method names, argument order and return shapes, plus ROS 2 tf2_py's velocity methods.
Every method converts its arguments (:mod:`tfbus.compat._args`) and calls the
:class:`tfbus.BufferCore` method named in its docstring; results are tfbus types
(``TransformStamped`` with ``header.stamp`` a :class:`tfbus.Time`) with tf2's field
names. Exceptions are tfbus's, which are the classes exported here under tf2's names:
the six of ROS 2's ``tf2_py`` (``tf2_py/src/tf2_py.cpp`` registers TransformException,
ConnectivityException, LookupException, ExtrapolationException,
InvalidArgumentException, TimeoutException). ROS 2 tf2's extrapolation subclasses
(Forward-, Backward-, NoDataForExtrapolationException) have no tf2_py class, so they are
not exported here; tfbus raises them, and ``except ExtrapolationException`` catches them
(``tfbus.compat.tf2_ros`` exports them by name).
"""

from __future__ import annotations

from typing import Any

from tfbus.compat._args import to_duration, to_point, to_time, to_transform_stamped
from tfbus.compat._types import flavour_of, time_out
from tfbus.core import MAX_GRAPH_DEPTH
from tfbus.core import BufferCore as _Core
from tfbus.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TimeoutException,
    TransformException,
    extrapolation_exception,
)
from tfbus.messages import TransformStamped, VelocityStamped
from tfbus.time import Duration, Time

__all__ = [
    "BufferCore",
    "ConnectivityException",
    "ExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "TimeoutException",
    "TransformException",
    "chain",
]


class BufferCore:
    """tf2_py's ``BufferCore(cache_time=10 s)`` over a :class:`tfbus.BufferCore`
    (``.core``). ``cache_time``: a rospy / rclpy / tfbus Duration or seconds."""

    def __init__(self, cache_time: object = None) -> None:
        """Create the buffer; ``cache_time`` defaults to 10 s (tf2's default)."""
        self.core = _Core(10.0 if cache_time is None else to_duration(cache_time, "cache_time"))
        self._flavour: str | None = None

    def set_transform(self, transform: Any, authority: str) -> None:
        """tf2_py ``set_transform(msg, authority)``: :meth:`tfbus.BufferCore.set_transform`
        (returns None, as tf2_py)."""
        _note(self, transform)
        self.core.set_transform(to_transform_stamped(transform), authority)

    def set_transform_static(self, transform: Any, authority: str) -> None:
        """tf2_py ``set_transform_static(msg, authority)``:
        :meth:`tfbus.BufferCore.set_transform_static` (returns None)."""
        _note(self, transform)
        self.core.set_transform_static(to_transform_stamped(transform), authority)

    def clear(self) -> None:
        """tf2_py ``clear()``: :meth:`tfbus.BufferCore.clear`."""
        self.core.clear()

    def can_transform_core(
        self, target_frame: str, source_frame: str, time: object
    ) -> tuple[bool, str]:
        """tf2_py ``can_transform_core`` → ``(ok, error message)``:
        :meth:`tfbus.BufferCore.can_transform` with ``return_debug_tuple=True``."""
        out = self.core.can_transform(target_frame, source_frame, to_time(time), True)
        assert isinstance(out, tuple)
        return out

    def can_transform_full_core(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
    ) -> tuple[bool, str]:
        """tf2_py ``can_transform_full_core`` → ``(ok, error message)``:
        :meth:`tfbus.BufferCore.can_transform_full`."""
        out = self.core.can_transform_full(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame, True,
        )
        assert isinstance(out, tuple)
        return out

    def lookup_transform_core(
        self, target_frame: str, source_frame: str, time: object
    ) -> TransformStamped:
        """tf2_py ``lookup_transform_core``: :meth:`tfbus.BufferCore.lookup_transform`."""
        return self.core.lookup_transform(target_frame, source_frame, to_time(time))

    def lookup_transform_full_core(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
    ) -> TransformStamped:
        """tf2_py ``lookup_transform_full_core``:
        :meth:`tfbus.BufferCore.lookup_transform_full`."""
        return self.core.lookup_transform_full(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame,
        )

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Any:
        """tf2_py ``get_latest_common_time``:
        :meth:`tfbus.BufferCore.get_latest_common_time`, in the caller's time type: a
        rospy ``Time`` (``secs``, ``nsecs``) when the buffer was fed rospy messages, an
        rclpy ``Time`` for rclpy messages, else a tfbus Time
        (:mod:`tfbus.compat._types`)."""
        return time_out(self.core.get_latest_common_time(target_frame, source_frame),
                        self._flavour)

    def all_frames_as_string(self) -> str:
        """tf2_py ``all_frames_as_string``: :meth:`tfbus.BufferCore.all_frames_as_string`."""
        return self.core.all_frames_as_string()

    def all_frames_as_yaml(self, current_time: object = None) -> str:
        """tf2_py ``all_frames_as_yaml``: :meth:`tfbus.BufferCore.all_frames_as_yaml`."""
        when = None if current_time is None else to_time(current_time, "current_time")
        return self.core.all_frames_as_yaml(when)

    def _chain(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
    ) -> list[str]:
        """tf2_py ``_chain``: :func:`chain` on ``.core``."""
        return chain(
            self.core, target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame,
        )

    def _allFramesAsDot(self, time: object = None) -> str:
        """tf2_py ``_allFramesAsDot([time])``: :meth:`tfbus.BufferCore.all_frames_as_dot`."""
        return self.core.all_frames_as_dot(None if time is None else to_time(time))

    def _frameExists(self, frame_id: str) -> bool:
        """tf2_py ``_frameExists``: :meth:`tfbus.BufferCore.frame_exists`."""
        return self.core.frame_exists(frame_id)

    def _getFrameStrings(self) -> list[str]:
        """tf2_py ``_getFrameStrings``: :meth:`tfbus.BufferCore.get_frame_names`."""
        return self.core.get_frame_names()

    def lookupVelocityCore(
        self,
        tracking_frame: str,
        observation_frame: str,
        time: object,
        averaging_interval: object,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """ROS 2 tf2_py ``lookupVelocityCore`` → ``((vx, vy, vz), (wx, wy, wz))`` (m/s,
        rad/s; tf2_py's shape): :meth:`tfbus.BufferCore.lookup_velocity` (tf2's
        algorithm; ``averaging_interval`` a duration or seconds)."""
        return _pair(self.core.lookup_velocity(
            tracking_frame, observation_frame, to_time(time),
            _interval(averaging_interval),
        ))

    def lookupVelocityFullCore(
        self,
        tracking_frame: str,
        observation_frame: str,
        reference_frame: str,
        reference_point: Any,
        reference_point_frame: str,
        time: object,
        averaging_interval: object,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """ROS 2 tf2_py ``lookupVelocityFullCore`` → ``((vx, vy, vz), (wx, wy, wz))``:
        :meth:`tfbus.BufferCore.lookup_velocity_full` (``reference_point``: anything
        with x, y, z, or an (x, y, z) tuple, metres)."""
        point = (
            reference_point
            if isinstance(reference_point, tuple)
            else tuple(to_point(reference_point, "reference_point"))
        )
        return _pair(self.core.lookup_velocity_full(
            tracking_frame, observation_frame, reference_frame, point,  # type: ignore[arg-type]
            reference_point_frame, to_time(time), _interval(averaging_interval),
        ))


def _note(buffer: BufferCore, transform: Any) -> None:
    """Remember the caller's flavour (rospy / rclpy / tfbus) from a transform's stamp."""
    found = flavour_of(getattr(getattr(transform, "header", None), "stamp", None))
    if found is not None:
        buffer._flavour = found


def _pair(v: VelocityStamped) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    lin, ang = v.velocity
    return (lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z)


def _interval(value: object) -> Duration | float:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)  # validated (> 0, finite) by the velocity lookup
    return to_duration(value, "averaging_interval")


def chain(
    core: _Core,
    target_frame: str,
    target_time: Time,
    source_frame: str,
    source_time: Time,
    fixed_frame: str,
) -> list[str]:
    """The frames a time-travel lookup on ``core`` walks, in tf2_py 0.7.6 ``_chain``
    order (tf2 ``BufferCore::_chainAsVector``): the walk from ``source_frame`` to
    ``fixed_frame`` at ``source_time``, then from ``fixed_frame`` to ``target_frame``
    at ``target_time``, the shared frame between them once. E.g. on A→B→C, A→D,
    ``chain(core, "D", t, "C", t, "A") == ["C", "B", "A", "D"]``; ``[]`` when all three
    frames are one.

    Each walk is tf2 0.7.6 ``walkToTopParent``'s frame chain, quirks included: the
    source's ancestors up to the root, then the target's branch, with the pruning
    of the common part that keeps the root when the two branches meet one level
    below it (A→B→C, B→E: the walk from C to E is ``[C, B, A, E]``). tfbus's own code
    asks the core for a frame path (:func:`tfbus.core.frame_path`); this ordering is
    tf2_py's and lives here only.

    Raises:
        InvalidArgumentException, LookupException, ConnectivityException,
        ExtrapolationException: as :meth:`tfbus.BufferCore.lookup_transform` of either
            leg (fixed ← source at ``source_time``, then target ← fixed at
            ``target_time``). tf2_py raises the same classes, with an empty message
            for an unknown id at time 0 (a ConnectivityException at another time).
    """
    first = _walk_chain(core, fixed_frame, source_frame, source_time)
    second = _walk_chain(core, target_frame, fixed_frame, target_time)
    if first and second and first[-1] == second[0]:
        first.pop()
    return first + second


def _walk_chain(core: _Core, target: str, source: str, time: Time) -> list[str]:
    """tf2 0.7.6 ``walkToTopParent``'s ``frame_chain`` from ``source`` to ``target``
    (after the same walk's errors, raised by :meth:`tfbus.BufferCore.lookup_transform`)."""
    if target == source:
        return []
    known_target, known_source = core.frame_exists(target), core.frame_exists(source)
    if not (known_target and known_source):
        _unknown_in_chain(core, target, source, time, known_target, known_source)
        return []  # both unknown: tf2 sees frame 0 twice, an identity walk
    at = core.lookup_transform(target, source, time).header.stamp  # raises as tf2
    linked = {info.child for info in core.frame_info()}
    walk: list[str] = []
    frame: str | None = source
    top = source
    while frame is not None:
        walk.append(frame)
        if frame not in linked:
            top = frame
            break
        parent = core.get_parent(frame, at)
        if parent is None:  # no data at this time: the target walk must meet it
            top = frame
            break
        if frame == target:
            return walk
        top, frame = frame, parent
        if len(walk) > MAX_GRAPH_DEPTH + 1:
            break
    reverse: list[str] = []
    frame = target
    while frame is not None and frame != top:
        reverse.append(frame)
        if frame not in linked:
            break
        parent = core.get_parent(frame, at)
        if frame == source:  # source is an ancestor of target: this walk, reversed
            return reverse[::-1]
        frame = parent
        if len(reverse) > MAX_GRAPH_DEPTH + 1:
            break
    reverse.append(top)  # tf2 appends the top parent to ease the pruning
    m, n = len(reverse) - 1, len(walk) - 1
    while m >= 0 and n >= 0 and walk[n] == reverse[m]:
        m -= 1
        n -= 1
    if n > 0:
        del walk[n + 2 :]
    walk.extend(reverse[i] for i in range(m, -1, -1))
    return walk


def _unknown_in_chain(
    core: _Core, target: str, source: str, time: Time, known_target: bool, known_source: bool
) -> None:
    """What tf2 0.7.6 ``_chainAsVector`` does with an unknown id (frame number 0, no
    validation): nothing when both are unknown; at time 0 a LookupException with an
    empty message; otherwise the walk up from the known id ends in tf2's
    extrapolation error (a link without data at ``time``) or connectivity error,
    with ``NO_PARENT`` for the unknown id."""
    if not known_target and not known_source:
        return
    if time.ns == 0:
        raise LookupException("")
    known = source if known_source else target
    names = (source, "NO_PARENT") if known_source else ("NO_PARENT", target)
    frame = known
    for _ in range(MAX_GRAPH_DEPTH + 1):
        newest = core.get_parent(frame)
        if newest is None:
            break  # a root (or an emptied link)
        parent = core.get_parent(frame, time)
        if parent is None:  # no data at time: tf2 reports the extrapolation
            # frame as the *target* of a lookup: tf2's walk reports the target's
            # own link when it has no data (the source side only flags it)
            failure = core.try_lookup_transform(frame, newest, time)
            if isinstance(failure, ExtrapolationException):
                detail = str(failure).split(", when looking up transform from frame")[0]
                raise extrapolation_exception(
                    f"{detail}, when looking up transform from frame [{names[0]}] to "
                    f"frame [{names[1]}]"
                )
            break
        frame = parent
    raise ConnectivityException(
        f"Could not find a connection between '{names[1]}' and '{names[0]}' because "
        "they are not part of the same tree.Tf has two or more unconnected trees."
    )
