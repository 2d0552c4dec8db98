"""Arguments as tf2 code passes them, converted to tfbus values (no other logic).

Times and durations: a tfbus :class:`~tfbus.time.Time` / :class:`~tfbus.time.Duration`;
anything with ``nanoseconds`` (rclpy ``Time`` / ``Duration``); with ``sec`` and
``nanosec`` (builtin_interfaces ``Time`` / ``Duration`` messages); with ``secs`` and
``nsecs`` (rospy / genpy ``Time`` / ``Duration``); durations also as real seconds.
Messages are duck-typed on their ROS field names (rospy and rclpy geometry_msgs alike).
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

from tfbus.errors import InvalidArgumentException
from tfbus.messages import (
    Header,
    Point,
    Point32,
    PointStamped,
    Polygon,
    PolygonStamped,
    Pose,
    PoseStamped,
    PoseWithCovariance,
    PoseWithCovarianceStamped,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
    Wrench,
    WrenchStamped,
)
from tfbus.time import Duration, Time

__all__ = [
    "to_duration",
    "to_ns",
    "to_point",
    "to_quaternion",
    "to_stamped",
    "to_time",
    "to_transform_stamped",
    "to_vector3",
]

_NS = 1_000_000_000


def to_ns(value: object, name: str) -> int:
    """Integer nanoseconds of a time or duration in any of the module's forms.

    Raises:
        InvalidArgumentException: ``value`` is none of them (the message names ``name``).
    """
    if isinstance(value, (Time, Duration)):
        return value.ns
    ns = getattr(value, "nanoseconds", None)
    if isinstance(ns, int):
        return ns
    sec, nanosec = getattr(value, "sec", None), getattr(value, "nanosec", None)
    if isinstance(sec, int) and isinstance(nanosec, int):
        return sec * _NS + nanosec
    secs, nsecs = getattr(value, "secs", None), getattr(value, "nsecs", None)
    if isinstance(secs, int) and isinstance(nsecs, int):
        return secs * _NS + nsecs
    raise InvalidArgumentException(
        f"{name} must be a time (tfbus Time, rclpy Time, builtin_interfaces Time, rospy "
        f"Time), got {value!r}"
    )


def to_time(value: object, name: str = "time") -> Time:
    """A tfbus Time from any time form (see the module docs)."""
    if isinstance(value, Time):
        return value
    return Time.from_ns(to_ns(value, name))


def to_duration(value: object, name: str = "timeout") -> Duration:
    """A tfbus Duration from any duration form, or real seconds.

    Raises:
        InvalidArgumentException: NaN, or not a duration (the message names ``name``).
    """
    if isinstance(value, Duration):
        return value
    if isinstance(value, Real) and not isinstance(value, bool):
        seconds = float(value)
        if math.isnan(seconds):
            raise InvalidArgumentException(f"{name} must not be NaN, got {value!r}")
        if math.isinf(seconds):
            return Duration.from_ns(2**63 - 1 if seconds > 0 else 0)
        return Duration.from_sec(seconds)
    return Duration.from_ns(to_ns(value, name))


def _xyz(value: Any, name: str) -> tuple[float, float, float]:
    try:
        return (float(value.x), float(value.y), float(value.z))
    except (AttributeError, TypeError, ValueError):
        raise InvalidArgumentException(f"{name} must have x, y, z, got {value!r}") from None


def to_vector3(value: Any, name: str = "vector") -> Vector3:
    """A tfbus Vector3 from anything with ``x``, ``y``, ``z``."""
    return value if isinstance(value, Vector3) else Vector3(*_xyz(value, name))


def to_point(value: Any, name: str = "point") -> Point:
    """A tfbus Point from anything with ``x``, ``y``, ``z``."""
    return value if isinstance(value, Point) else Point(*_xyz(value, name))


def to_quaternion(value: Any, name: str = "rotation") -> Quaternion:
    """A tfbus Quaternion (x, y, z, w) from anything with ``x``, ``y``, ``z``, ``w``."""
    if isinstance(value, Quaternion):
        return value
    try:
        return Quaternion(float(value.x), float(value.y), float(value.z), float(value.w))
    except (AttributeError, TypeError, ValueError):
        raise InvalidArgumentException(f"{name} must have x, y, z, w, got {value!r}") from None


def _header(value: Any, name: str) -> Header:
    header = getattr(value, "header", None)
    frame_id = getattr(header, "frame_id", None)
    if not isinstance(frame_id, str):
        raise InvalidArgumentException(f"{name}.header.frame_id must be a str, got {header!r}")
    return Header(to_time(getattr(header, "stamp", None), f"{name}.header.stamp"), frame_id)


def to_transform_stamped(value: Any, name: str = "transform") -> TransformStamped:
    """A tfbus TransformStamped from a geometry_msgs TransformStamped of any flavour."""
    if isinstance(value, TransformStamped):
        return value
    header = _header(value, name)
    child = getattr(value, "child_frame_id", None)
    if not isinstance(child, str):
        raise InvalidArgumentException(f"{name}.child_frame_id must be a str, got {child!r}")
    tr = getattr(value, "transform", None)
    return TransformStamped(
        header,
        child,
        Transform(
            to_vector3(getattr(tr, "translation", None), f"{name}.transform.translation"),
            to_quaternion(getattr(tr, "rotation", None), f"{name}.transform.rotation"),
        ),
    )


def to_stamped(value: Any, name: str = "object_stamped") -> object:
    """A tfbus stamped message for a foreign PointStamped, PoseStamped,
    Vector3Stamped, WrenchStamped, PoseWithCovarianceStamped, PolygonStamped or
    TransformStamped (by its fields); other objects as they are
    (they are looked up in the transform registry by their own type)."""
    if isinstance(
        value,
        (
            PointStamped, PoseStamped, Vector3Stamped, TransformStamped,
            PoseWithCovarianceStamped, PolygonStamped, WrenchStamped,
        ),
    ):
        return value
    if hasattr(value, "child_frame_id") and hasattr(value, "transform"):
        return to_transform_stamped(value, name)
    if not hasattr(value, "header"):
        return value
    polygon = getattr(value, "polygon", None)
    if polygon is not None and hasattr(polygon, "points"):
        return PolygonStamped(
            _header(value, name),
            Polygon(tuple(Point32(*to_point(p, f"{name}.polygon.points")) for p in polygon.points)),
        )
    if hasattr(value, "point"):
        return PointStamped(_header(value, name), to_point(value.point, f"{name}.point"))
    if hasattr(value, "vector"):
        return Vector3Stamped(_header(value, name), to_vector3(value.vector, f"{name}.vector"))
    wrench = getattr(value, "wrench", None)
    if wrench is not None and hasattr(wrench, "force") and hasattr(wrench, "torque"):
        return WrenchStamped(_header(value, name), Wrench(
            to_vector3(wrench.force, f"{name}.wrench.force"),
            to_vector3(wrench.torque, f"{name}.wrench.torque")))
    pose = getattr(value, "pose", None)
    if pose is not None and hasattr(pose, "covariance") and hasattr(pose, "pose"):
        inner = pose.pose
        return PoseWithCovarianceStamped(
            _header(value, name),
            PoseWithCovariance(
                Pose(to_point(inner.position, f"{name}.pose.pose.position"),
                     to_quaternion(inner.orientation, f"{name}.pose.pose.orientation")),
                tuple(float(c) for c in pose.covariance),
            ),
        )
    if pose is not None and hasattr(pose, "position") and hasattr(pose, "orientation"):
        return PoseStamped(
            _header(value, name),
            Pose(to_point(pose.position, f"{name}.pose.position"),
                 to_quaternion(pose.orientation, f"{name}.pose.orientation")),
        )
    return value
