"""Values in the caller's types: rospy (ROS 1), rclpy (ROS 2) or tfbus.

tf2 code reads what tf2 returns: a ROS 1 program reads ``stamp.secs`` / ``stamp.nsecs``
and assigns into returned messages, a ROS 2 one reads ``nanoseconds``. The caller's
flavour is taken from the values it passes (a rospy ``Time`` has ``secs`` and
``nsecs``; an rclpy ``Time`` has ``nanoseconds`` and ``clock_type``; a
``builtin_interfaces`` message has ``sec`` and ``nanosec``); results are then built in
that flavour. A tfbus value gives tfbus results (unchanged behaviour).

Message classes (:func:`message_class`): the real ``geometry_msgs.msg`` class when it
imports (rospy's under Debian's ROS 1, rclpy's in a ROS 2 environment), else a mutable
dataclass with ROS's field names and defaults (ROS 2's: ``Quaternion.w = 1.0``).
"""

from __future__ import annotations

import array
import sys
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

from tfbus.time import Time

__all__ = ["flavour_of", "is_ros_message", "message_class", "ros_out", "stamp_in", "stamped_out",
           "time_out"]

ROS1 = "ros1"
ROS2 = "ros2"


def flavour_of(*values: object) -> str | None:
    """``"ros1"``, ``"ros2"`` or None (tfbus) for the first value that says which."""
    for value in values:
        if value is None or isinstance(value, Time):
            continue
        if hasattr(value, "secs") and hasattr(value, "nsecs"):
            return ROS1
        if hasattr(value, "nanoseconds") or (hasattr(value, "sec") and hasattr(value, "nanosec")):
            return ROS2
    return None


def time_out(t: Time, flavour: str | None) -> Any:
    """``t`` as the caller's time: ``rospy.Time`` (genpy) for ROS 1, ``rclpy.time.Time``
    for ROS 2, else ``t``."""
    try:
        if flavour == ROS1:
            import genpy  # type: ignore[import-not-found]

            return genpy.Time(t.sec, t.nanosec)
        if flavour == ROS2:
            from rclpy.time import Time as RclpyTime  # type: ignore[import-not-found]

            return RclpyTime(nanoseconds=t.ns)
    except ImportError:  # the caller's library is not importable here: tfbus's Time
        return t
    return t


def stamp_in(t: Time, like: object) -> Any:
    """``t`` as a message stamp of the same type as ``like`` (a rospy Time, a
    builtin_interfaces Time, else a tfbus Time)."""
    if hasattr(like, "secs") and hasattr(like, "nsecs"):
        ros1: Any = type(like)
        return ros1(t.sec, t.nanosec)
    if hasattr(like, "sec") and hasattr(like, "nanosec") and not isinstance(like, Time):
        ros2: Any = type(like)
        return ros2(sec=t.sec, nanosec=t.nanosec)
    return t


def _field_names(value: Any) -> tuple[str, ...] | None:
    """The fields of a tfbus message (a NamedTuple or a dataclass), else None."""
    names = getattr(value, "_fields", None)
    if names is not None:
        return tuple(names)
    if is_dataclass(value) and not isinstance(value, type):
        return tuple(f.name for f in fields(value))
    return None


def _element_class(dst: Any, element: Any) -> Any:
    """The ROS message class for an ``element`` of a sequence field of the ROS message
    ``dst``: the class of ``element``'s name in ``dst``'s own package (``Point32`` beside
    ``geometry_msgs.msg.Polygon``, ``PointField`` beside ``sensor_msgs.msg.PointCloud2``),
    else ``std_msgs.msg`` / ``geometry_msgs.msg`` / ``sensor_msgs.msg``'s."""
    name = type(element).__name__
    package = type(dst).__module__.rsplit(".", 1)[0]  # geometry_msgs.msg._polygon
    for module in (package, "geometry_msgs.msg", "sensor_msgs.msg", "std_msgs.msg"):
        try:
            cls = getattr(sys.modules.get(module) or __import__(module, fromlist=[name]), name)
        except Exception:
            continue
        if isinstance(cls, type):
            return cls
    return None


def _assign(dst: Any, src: Any) -> Any:
    """Copy the tfbus message ``src``'s fields (a NamedTuple or dataclass) into the
    mutable message ``dst`` (recursively: nested messages, sequences of messages in the
    element class of ``dst``'s package, stamps in ``dst``'s time type, bytes into an
    rclpy ``array.array`` field); returns ``dst``."""
    for name in _field_names(src) or ():
        value = getattr(src, name)
        current = getattr(dst, name, None)
        if isinstance(value, Time):
            setattr(dst, name, stamp_in(value, current))
        elif _field_names(value) is not None and current is not None \
                and not isinstance(current, tuple):
            _assign(current, value)
        elif isinstance(value, (bytes, bytearray, memoryview)):
            if isinstance(current, array.array):  # rclpy uint8[]: no per-byte check
                setattr(dst, name, array.array(current.typecode, bytes(value)))
            else:
                setattr(dst, name, bytes(value))
        elif isinstance(value, (tuple, list)) and _field_names(value) is None:
            items = list(value)
            if items and _field_names(items[0]) is not None:
                cls = _element_class(dst, items[0])
                if cls is not None:
                    items = [_assign(cls(), item) for item in items]
            setattr(dst, name, type(current)(items) if isinstance(current, (tuple, list))
                    else items)
        else:
            setattr(dst, name, value)
    return dst


def is_ros_message(value: object) -> bool:
    """True for a rospy (genpy: ``_type`` and ``_md5sum`` on the class) or an rclpy
    message (``get_fields_and_field_types`` on the class), not for a look-alike."""
    cls = type(value)
    return (hasattr(cls, "_type") and hasattr(cls, "_md5sum")) or hasattr(
        cls, "get_fields_and_field_types")


def ros_out(result: Any, given: Any) -> Any:
    """``result`` (a tfbus message) in the class of ``given`` when ``given`` is a rospy or
    rclpy message of the same type name, as tf2_geometry_msgs builds its results in
    ``geometry_msgs.msg`` classes; else ``result`` as it is."""
    if is_ros_message(given) and type(given).__name__ == type(result).__name__:
        return stamped_out(result, given)
    return result


def stamped_out(result: Any, like: Any) -> Any:
    """The tfbus message ``result`` as an instance of ``type(like)`` (a mutable ROS or
    fallback message, filled field by field), or ``result`` when ``like`` is a tfbus
    message itself (a NamedTuple, or a dataclass of :mod:`tfbus.sensor_msgs`), as
    tf2_ros returns the caller's own message type."""
    if like is None or isinstance(like, tuple) or type(like).__module__ == "tfbus.sensor_msgs":
        return result
    try:
        out = type(like)()
    except TypeError:  # not default-constructible (not a ROS message): tfbus's result
        return result
    return _assign(out, result)


# ---------------------------------------------------------------- message classes


@dataclass
class Header:
    """std_msgs/Header (ROS field names; ``stamp`` a tfbus Time)."""

    seq: int = 0
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Vector3:
    """geometry_msgs/Vector3 (metres or any vector unit)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Point:
    """geometry_msgs/Point (metres)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Quaternion:
    """geometry_msgs/Quaternion (ROS 2's defaults: identity)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass
class Pose:
    """geometry_msgs/Pose."""

    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class Transform:
    """geometry_msgs/Transform."""

    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class Wrench:
    """geometry_msgs/Wrench (N, N·m)."""

    force: Vector3 = field(default_factory=Vector3)
    torque: Vector3 = field(default_factory=Vector3)


@dataclass
class PointStamped:
    """geometry_msgs/PointStamped."""

    header: Header = field(default_factory=Header)
    point: Point = field(default_factory=Point)


@dataclass
class Vector3Stamped:
    """geometry_msgs/Vector3Stamped."""

    header: Header = field(default_factory=Header)
    vector: Vector3 = field(default_factory=Vector3)


@dataclass
class PoseStamped:
    """geometry_msgs/PoseStamped."""

    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class WrenchStamped:
    """geometry_msgs/WrenchStamped."""

    header: Header = field(default_factory=Header)
    wrench: Wrench = field(default_factory=Wrench)


@dataclass
class TransformStamped:
    """geometry_msgs/TransformStamped."""

    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


_FALLBACK = {cls.__name__: cls for cls in (
    Header, Vector3, Point, Quaternion, Pose, Transform, Wrench, PointStamped,
    Vector3Stamped, PoseStamped, WrenchStamped, TransformStamped,
)}


def message_class(name: str) -> type:
    """``geometry_msgs.msg.<name>`` (``std_msgs.msg.Header``) when it imports, else
    this module's mutable dataclass of that name."""
    module = "std_msgs.msg" if name == "Header" else "geometry_msgs.msg"
    try:
        mod = sys.modules.get(module) or __import__(module, fromlist=[name])
        cls = getattr(mod, name)
    except Exception:
        return _FALLBACK[name]
    assert isinstance(cls, type)
    return cls


def ros_message(result: Any, flavour: str | None, name: str) -> Any:
    """``result`` (a tfbus message) as the ROS class ``name`` of the caller's flavour
    when that class imports, else ``result``."""
    if flavour is None:
        return result
    cls = message_class(name)
    if is_dataclass(cls):
        return result
    return _assign(cls(), result)


__all__ += ["ROS1", "ROS2", "ros_message"]
