"""Message value types with ROS field names (geometry_msgs, std_msgs, tf2_msgs,
rosgraph_msgs).

All are immutable ``NamedTuple``s: cheap to create (a lookup returns one per call),
hashable, unpackable (``x, y, z = v``) and with readable ``repr``s. Units are metres for
translations and points; quaternions are (x, y, z, w), w last, as in ROS messages.

They are messages, not vectors: ``+`` and ``*`` (which on a plain tuple would
concatenate or repeat it, ``Vector3(1, 2, 3) + Vector3(1, 1, 1)`` giving a 6-tuple)
raise ``TypeError`` on every type here. For arithmetic, use numpy on the fields
(``np.add(v, w)``, ``np.asarray(v) * 2``) or :mod:`tfbus.geometry`.

Coming from tf2_ros, where messages are mutable (``t.header.frame_id = "map"``): here
you build a changed copy with ``_replace`` (``typing.NamedTuple``), nested for nested
fields::

    t2 = t._replace(child_frame_id="laser")
    t3 = t._replace(header=t.header._replace(frame_id="map", stamp=Time(5)))
    t4 = t._replace(
        transform=t.transform._replace(translation=Vector3(1.0, 0.0, 0.0))
    )

The original is unchanged, so a message can be shared between tasks, latched on a bus
or kept in a cache without copies.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from types import GenericAlias
from typing import TYPE_CHECKING, Any, Generic, NamedTuple, NoReturn, TypeVar

from tfbus.time import Time

__all__ = [
    "Clock",
    "Header",
    "JointState",
    "LookupTransformGoal",
    "LookupTransformResult",
    "Point",
    "Point32",
    "PointStamped",
    "Polygon",
    "PolygonStamped",
    "Pose",
    "PoseStamped",
    "PoseWithCovariance",
    "PoseWithCovarianceStamped",
    "Quaternion",
    "Stamped",
    "TFMessage",
    "Transform",
    "TransformStamped",
    "Twist",
    "TwistStamped",
    "Vector3",
    "Vector3Stamped",
    "VelocityStamped",
    "Wrench",
    "WrenchStamped",
]


def _refused(msg: tuple[object, ...], op: str) -> TypeError:
    """The TypeError for ``+``/``*`` on a message (tuple concatenation or repetition)."""
    return TypeError(
        f"unsupported operand for {op}: {type(msg).__name__} is an immutable message, "
        f"not a vector (on a tuple, {op} would concatenate or repeat the fields). "
        f"Compute on the fields (numpy, tfbus.geometry) and build a changed copy with "
        f"msg._replace(field=value)"
    )


class Vector3(NamedTuple):
    """geometry_msgs/Vector3: a direction or translation, metres."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Point(NamedTuple):
    """geometry_msgs/Point: a position, metres."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Quaternion(NamedTuple):
    """geometry_msgs/Quaternion in (x, y, z, w) order, w last; identity by default.

    tf2 does not normalise quaternions; neither does tfbus (see ``BufferCore``).
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


_ZERO_VECTOR = Vector3()
_IDENTITY_QUATERNION = Quaternion()


class Transform(NamedTuple):
    """geometry_msgs/Transform: ``translation`` (metres) then ``rotation`` (x, y, z, w).

    Maps a point p in the child frame to the parent frame: ``R(rotation) p + translation``.

    Besides a :class:`Vector3` and a :class:`Quaternion`, ``translation`` and ``rotation``
    accept any finite sequence or array of 3 and 4 numbers (a list, a tuple, a numpy
    array such as :func:`tfbus.geometry.quaternion_from_euler` returns), converted once
    here, in ``Transform(...)`` and ``_replace(...)`` (``_make`` does not convert).

    Raises:
        ValueError: ``translation`` or ``rotation`` is neither its type nor such a
            sequence (wrong length, not numbers, NaN or infinite); the message names the
            field and the value.
    """

    translation: Vector3 = _ZERO_VECTOR
    rotation: Quaternion = _IDENTITY_QUATERNION

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


def _components(value: object, kind: type[Any], where: str, names: str) -> Any:
    """``value`` as a ``kind`` (Vector3, Point or Quaternion): itself if it is one, else
    a finite sequence or array of ``len(names)`` numbers converted once (what
    :func:`tfbus.geometry.quaternion_from_euler` and numpy return, a list, a tuple).

    Raises:
        ValueError: anything else (wrong length, not numbers, NaN or infinite, not a
            sequence), naming the field and the value.
    """
    if isinstance(value, kind):
        return value
    items: object = None
    if not isinstance(value, (str, bytes)):
        tolist = getattr(value, "tolist", None)  # numpy: Python floats, one call
        try:
            items = tolist() if callable(tolist) else list(value)  # type: ignore[call-overload]
        except TypeError:
            items = None
    if (
        isinstance(items, list)
        and len(items) == len(kind._fields)
        and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
            for c in items
        )
    ):
        return kind(*(float(c) for c in items))
    raise ValueError(
        f"{where} must be a {kind.__name__} or a sequence of {len(kind._fields)} finite "
        f"numbers ({names}), got {value!r}"
    )


_tuple_new = tuple.__new__


def _transform_new(
    cls: type[Transform],
    translation: Vector3 = _ZERO_VECTOR,
    rotation: Quaternion = _IDENTITY_QUATERNION,
) -> Transform:
    # The messages' own types go straight through (two type checks: the hot path).
    if translation.__class__ is not Vector3:
        translation = _components(translation, Vector3, "Transform.translation", "x, y, z")
    if rotation.__class__ is not Quaternion:
        rotation = _components(rotation, Quaternion, "Transform.rotation", "x, y, z, w")
    return _tuple_new(cls, (translation, rotation))


def _transform_replace(self: Transform, **fields: object) -> Transform:
    translation = fields.pop("translation", self[0])
    rotation = fields.pop("rotation", self[1])
    if fields:
        raise ValueError(f"Got unexpected field names: {list(fields)!r}")
    return _transform_new(type(self), translation, rotation)  # type: ignore[arg-type]


setattr(Transform, "__new__", _transform_new)  # noqa: B010  (NamedTuple forbids it in the body)
setattr(Transform, "_replace", _transform_replace)  # noqa: B010


class Pose(NamedTuple):
    """geometry_msgs/Pose: ``position`` (metres) and ``orientation`` (x, y, z, w)."""

    position: Point = Point()
    orientation: Quaternion = _IDENTITY_QUATERNION

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


_ZERO_TIME = Time(0)


class Header(NamedTuple):
    """std_msgs/Header: ``stamp`` (:class:`~tfbus.time.Time`) and ``frame_id``."""

    stamp: Time = _ZERO_TIME
    frame_id: str = ""

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


_EMPTY_HEADER = Header()


class TransformStamped(NamedTuple):
    """geometry_msgs/TransformStamped: the pose of ``child_frame_id`` in ``header.frame_id``.

    ``header.frame_id`` is the parent frame, ``child_frame_id`` the child frame,
    ``header.stamp`` the time the transform is valid at.
    """

    header: Header = _EMPTY_HEADER
    child_frame_id: str = ""
    transform: Transform = Transform()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class PointStamped(NamedTuple):
    """geometry_msgs/PointStamped: a point (metres) in ``header.frame_id`` at ``header.stamp``."""

    header: Header = _EMPTY_HEADER
    point: Point = Point()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class PoseStamped(NamedTuple):
    """geometry_msgs/PoseStamped: a pose in ``header.frame_id`` at ``header.stamp``."""

    header: Header = _EMPTY_HEADER
    pose: Pose = Pose()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Vector3Stamped(NamedTuple):
    """geometry_msgs/Vector3Stamped: a direction in ``header.frame_id``.

    Transforming it rotates it only; translation does not apply (tf2_geometry_msgs).
    """

    header: Header = _EMPTY_HEADER
    vector: Vector3 = _ZERO_VECTOR

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class TFMessage(NamedTuple):
    """tf2_msgs/TFMessage: the message carried on ``/tf`` and ``/tf_static``."""

    transforms: Sequence[TransformStamped] = ()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Clock(NamedTuple):
    """rosgraph_msgs/Clock: the simulated time a simulator or a bag player publishes on
    ``/clock`` (:data:`tfbus.topics.CLOCK_TOPIC`); what nodes with ``use_sim_time``
    read as "now" (:class:`tfbus.clock.SimClock`). ``clock`` is a
    :class:`~tfbus.time.Time` (``time clock`` in ``Clock.msg``).
    """

    clock: Time = Time(0)

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class LookupTransformGoal(NamedTuple):
    """A goal of tf2_ros's ``tf2_msgs/LookupTransform`` action (``LookupTransform.action``,
    the request of ``buffer_server``), with the action's goal id.

    ``target_frame``, ``source_frame``, ``source_time``, ``timeout`` (seconds, a float;
    ``duration timeout`` on the wire), ``target_time``, ``fixed_frame`` and ``advanced``
    (the six-argument lookup when True) are the goal's fields; ``goal_id`` and
    ``goal_stamp`` are the action's ``GoalID`` (actionlib: ``id``, ``stamp``), the time the
    client sent it (also the ROS 1 ``ActionGoal`` header's stamp).
    """

    target_frame: str
    source_frame: str
    source_time: Time = Time(0)
    timeout: float = 0.0
    target_time: Time = Time(0)
    fixed_frame: str = ""
    advanced: bool = False
    goal_id: str = ""
    goal_stamp: Time = Time(0)


class LookupTransformResult(NamedTuple):
    """A result of tf2_ros's ``tf2_msgs/LookupTransform`` action, with the action's status.

    ``transform`` and the ``tf2_msgs/TF2Error`` (``error``: 0 NO_ERROR, 1 LOOKUP_ERROR,
    2 CONNECTIVITY_ERROR, 3 EXTRAPOLATION_ERROR, 4 INVALID_ARGUMENT_ERROR, 5 TIMEOUT_ERROR,
    6 TRANSFORM_ERROR; ``error_string``) are the result's fields; ``goal_id`` and
    ``goal_stamp`` name the goal answered, ``status`` and ``status_text`` are its
    ``actionlib_msgs/GoalStatus`` (3 SUCCEEDED, as ``buffer_server`` ends every lookup,
    the error in ``error``; 2 PREEMPTED, 5 REJECTED, 8 RECALLED otherwise) and ``stamp``
    the time the server sent it (the ROS 1 ``ActionResult`` header's stamp).
    """

    transform: TransformStamped
    error: int = 0
    error_string: str = ""
    goal_id: str = ""
    goal_stamp: Time = Time(0)
    status: int = 3
    status_text: str = ""
    stamp: Time = Time(0)


class JointState(NamedTuple):
    """sensor_msgs/JointState: the state of a set of named joints at ``header.stamp``.

    ``name[i]`` is described by ``position[i]`` (radians for revolute and continuous
    joints, metres for prismatic ones), ``velocity[i]`` (rad/s or m/s) and ``effort[i]``
    (N·m or N). As in sensor_msgs, any of the three arrays may be empty when that
    quantity is not reported; otherwise it has one entry per name. ``header.frame_id``
    is unused by robot_state_publisher.
    """

    header: Header = _EMPTY_HEADER
    name: Sequence[str] = ()
    position: Sequence[float] = ()
    velocity: Sequence[float] = ()
    effort: Sequence[float] = ()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Twist(NamedTuple):
    """geometry_msgs/Twist: ``linear`` velocity (m/s) and ``angular`` velocity (rad/s,
    about the axes of the frame it is expressed in)."""

    linear: Vector3 = _ZERO_VECTOR
    angular: Vector3 = _ZERO_VECTOR

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class VelocityStamped(NamedTuple):
    """geometry_msgs/VelocityStamped (ROS 2): the velocity of ``body_frame_id`` relative
    to ``reference_frame_id``, expressed in ``header.frame_id`` at ``header.stamp``.

    ``velocity.linear`` in m/s, ``velocity.angular`` in rad/s. What
    :meth:`tfbus.core.BufferCore.lookup_velocity` returns (``header.frame_id`` is its
    reference frame, ``reference_frame_id`` its observation frame).
    """

    header: Header = _EMPTY_HEADER
    body_frame_id: str = ""
    reference_frame_id: str = ""
    velocity: Twist = Twist()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Wrench(NamedTuple):
    """geometry_msgs/Wrench: ``force`` (N) and ``torque`` (N·m)."""

    force: Vector3 = _ZERO_VECTOR
    torque: Vector3 = _ZERO_VECTOR

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class WrenchStamped(NamedTuple):
    """geometry_msgs/WrenchStamped: a wrench in ``header.frame_id`` at ``header.stamp``."""

    header: Header = _EMPTY_HEADER
    wrench: Wrench = Wrench()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


_T = TypeVar("_T")


if TYPE_CHECKING or sys.version_info >= (3, 11):

    class Stamped(NamedTuple, Generic[_T]):
        """Any value with a stamp and a frame: tf2's ``Stamped<T>`` and tf2_ros's
        ``Stamped``. ``Stamped(header, data)``, e.g. ``Stamped[Point](Header(t, "laser"),
        Point(1, 0, 0))``. :meth:`tfbus.Buffer.transform` accepts one whose ``data`` is a
        Point, Vector3 (rotated only), Pose, Quaternion (rotated), Transform or Wrench
        (:func:`tfbus.convert.do_transform_stamped`)."""

        header: Header
        data: _T

        def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
        def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
        def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
        def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")

else:  # a generic NamedTuple needs Python 3.11: the same fields, Stamped[T] an alias

    class Stamped(NamedTuple):
        """Any value with a stamp and a frame (tf2's ``Stamped<T>``): ``Stamped(header,
        data)``; ``Stamped[Point]`` is a ``types.GenericAlias`` of this class."""

        header: Header
        data: Any

        def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
        def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
        def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
        def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")

        __class_getitem__ = classmethod(GenericAlias)


_ZERO_COVARIANCE: tuple[float, ...] = (0.0,) * 36


class PoseWithCovariance(NamedTuple):
    """geometry_msgs/PoseWithCovariance: a pose and its 6x6 covariance, row-major, 36
    numbers, in the order (x, y, z, rotation about x, about y, about z): m², rad²."""

    pose: Pose = Pose()
    covariance: Sequence[float] = _ZERO_COVARIANCE

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class PoseWithCovarianceStamped(NamedTuple):
    """geometry_msgs/PoseWithCovarianceStamped: a pose with covariance in
    ``header.frame_id`` at ``header.stamp``."""

    header: Header = _EMPTY_HEADER
    pose: PoseWithCovariance = PoseWithCovariance()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class TwistStamped(NamedTuple):
    """geometry_msgs/TwistStamped: a velocity (m/s, rad/s) in ``header.frame_id``."""

    header: Header = _EMPTY_HEADER
    twist: Twist = Twist()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Point32(NamedTuple):
    """geometry_msgs/Point32: a position, metres (float32 on the wire; Python floats
    here)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class Polygon(NamedTuple):
    """geometry_msgs/Polygon: its vertices (``points``, Point32) in order."""

    points: Sequence[Point32] = ()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")


class PolygonStamped(NamedTuple):
    """geometry_msgs/PolygonStamped: a polygon in ``header.frame_id``."""

    header: Header = _EMPTY_HEADER
    polygon: Polygon = Polygon()

    def __add__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __radd__(self, other: object) -> NoReturn: raise _refused(self, "+")
    def __mul__(self, other: object) -> NoReturn: raise _refused(self, "*")
    def __rmul__(self, other: object) -> NoReturn: raise _refused(self, "*")
