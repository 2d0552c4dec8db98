"""``tf2_geometry_msgs``'s ``do_transform_*`` on tfbus types (ROS 1 and ROS 2 forms).

Where ROS 1 and ROS 2 differ the form is chosen by the argument's type:
``do_transform_pose`` takes a ``PoseStamped`` (ROS 1: returns a PoseStamped) or a
``Pose`` (ROS 2: returns a Pose); ``do_transform_pose_stamped`` is ROS 2's stamped name.
Foreign messages are read by their fields (:mod:`tfbus.compat._args`); the arithmetic is
Debian's (PyKDL, bit for bit: :mod:`tfbus.compat._kdl`) for points,
vectors, poses and wrenches, :mod:`tfbus.convert`'s for the others. Results are in the
type of the message given (a ROS message in, the same ROS class out; a tfbus message in,
a tfbus message out).
"""

from __future__ import annotations

from typing import Any

from tfbus.compat import _kdl
from tfbus.compat._args import (
    to_point,
    to_quaternion,
    to_stamped,
    to_transform_stamped,
    to_vector3,
)
from tfbus.compat._types import _assign, message_class, ros_out, stamped_out
from tfbus.convert import do_transform_polygon as _polygon
from tfbus.convert import do_transform_pose_with_covariance as _pose_cov
from tfbus.convert import do_transform_transform as _transform
from tfbus.convert import do_transform_wrench as _wrench
from tfbus.convert import transform_covariance as _covariance
from tfbus.messages import (
    Header,
    Point,
    PolygonStamped,
    Pose,
    PoseWithCovarianceStamped,
    Quaternion,
    Vector3,
    Wrench,
)
from tfbus.messages import (
    PointStamped as _PointStamped,
)
from tfbus.messages import (
    PoseStamped as _PoseStamped,
)
from tfbus.messages import (
    TransformStamped as _TransformStamped,
)
from tfbus.messages import (
    Vector3Stamped as _Vector3Stamped,
)
from tfbus.messages import (
    WrenchStamped as _WrenchStamped,
)

__all__ = [
    "PointStamped",
    "PoseStamped",
    "TransformStamped",
    "Vector3Stamped",
    "WrenchStamped",
    "do_transform_point",
    "do_transform_polygon_stamped",
    "do_transform_pose",
    "do_transform_pose_stamped",
    "do_transform_pose_with_covariance_stamped",
    "do_transform_transform",
    "do_transform_vector3",
    "do_transform_wrench",
    "transform_covariance",
]


PointStamped = message_class("PointStamped")
"""geometry_msgs ``PointStamped`` (the ROS class when it imports, else mutable)."""
PoseStamped = message_class("PoseStamped")
"""geometry_msgs ``PoseStamped`` (the ROS class when it imports, else mutable)."""
Vector3Stamped = message_class("Vector3Stamped")
"""geometry_msgs ``Vector3Stamped`` (the ROS class when it imports, else mutable)."""
WrenchStamped = message_class("WrenchStamped")
"""geometry_msgs ``WrenchStamped`` (the ROS class when it imports, else mutable)."""
TransformStamped = message_class("TransformStamped")
"""geometry_msgs ``TransformStamped`` (the ROS class when it imports, else mutable)."""


def _stamped(value: Any, kind: type, name: str) -> Any:
    out = to_stamped(value, name)
    if not isinstance(out, kind):
        raise TypeError(f"{name} must be a {kind.__name__} (by its fields), got {value!r}")
    return out


def _frame(transform: _TransformStamped) -> _kdl.Frame:
    """KDL ``transform_to_kdl``: the transform as a KDL frame."""
    (tx, ty, tz), (qx, qy, qz, qw) = transform.transform
    return _kdl.rotation(qx, qy, qz, qw), (tx, ty, tz)


def _out(result: Any, given: Any) -> Any:
    """``result`` in the type of ``given`` (a mutable ROS or fallback message), or as
    it is for a tfbus message."""
    return stamped_out(result, given)


def do_transform_point(point: Any, transform: Any) -> Any:
    """Debian's ``do_transform_point(PointStamped, TransformStamped)``: KDL ``Frame *
    Vector`` (:mod:`tfbus.compat._kdl`, bit for bit); the result carries the
    transform's header, in the type of ``point``."""
    ts = to_transform_stamped(transform)
    p = _stamped(point, _PointStamped, "point").point
    return _out(_PointStamped(ts.header, Point(*_kdl.frame_vec(_frame(ts), (p.x, p.y, p.z)))),
                point)


def _rotate(ts: _TransformStamped, v: Vector3) -> Vector3:
    (qx, qy, qz, qw) = ts.transform.rotation
    return Vector3(*_kdl.frame_vec((_kdl.rotation(qx, qy, qz, qw), (0.0, 0.0, 0.0)),
                                  (v.x, v.y, v.z)))


def do_transform_vector3(vector3: Any, transform: Any) -> Any:
    """Debian's ``do_transform_vector3(Vector3Stamped, TransformStamped)``: the rotation
    only (translation zeroed, then KDL ``Frame * Vector``), in the type of ``vector3``."""
    ts = to_transform_stamped(transform)
    v = _stamped(vector3, _Vector3Stamped, "vector3").vector
    return _out(_Vector3Stamped(ts.header, _rotate(ts, v)), vector3)


def do_transform_transform(transform_in: Any, transform: Any) -> Any:
    """``do_transform_transform``: :func:`tfbus.convert.do_transform_transform`; a rospy
    or rclpy TransformStamped in, the same class out (a tfbus TransformStamped for
    anything else)."""
    return ros_out(_transform(to_transform_stamped(transform_in, "transform_in"),
                              to_transform_stamped(transform)), transform_in)


def do_transform_wrench(wrench: Any, transform: Any, *, lever_arm: bool = False) -> Any:
    """``do_transform_wrench(WrenchStamped, TransformStamped)``: Debian's (ROS 1 Python:
    force and torque rotated as :func:`do_transform_vector3`, bit for bit), or with
    ``lever_arm=True`` ROS 2 C++'s (:func:`tfbus.convert.do_transform_wrench`). The
    result is in the type of ``wrench``."""
    if isinstance(wrench, _WrenchStamped):
        ours = wrench
    else:  # the input's header is not used: the result carries the transform's
        body = wrench.wrench
        ours = _WrenchStamped(
            Header(),
            Wrench(
                to_vector3(body.force, "wrench.force"), to_vector3(body.torque, "wrench.torque")
            ),
        )
    ts = to_transform_stamped(transform)
    if lever_arm:
        out = _wrench(ours, ts, lever_arm=True)
    else:
        out = _WrenchStamped(ts.header, Wrench(_rotate(ts, ours.wrench.force),
                                              _rotate(ts, ours.wrench.torque)))
    return _out(out, wrench)


def _pose_kdl(ts: _TransformStamped, pose: Pose) -> Pose:
    (px, py, pz), (qx, qy, qz, qw) = pose
    m, p = _kdl.frame_mul(_frame(ts), (_kdl.rotation(qx, qy, qz, qw), (px, py, pz)))
    return Pose(Point(*p), Quaternion(*_kdl.get_quaternion(m)))


def do_transform_pose(pose: Any, transform: Any) -> Any:
    """Debian's ``do_transform_pose(PoseStamped, t)`` → PoseStamped, or ROS 2's
    ``do_transform_pose(Pose, t)`` → Pose (chosen by whether ``pose`` has a header):
    KDL ``Frame * Frame`` and ``Rotation::GetQuaternion`` (bit for bit, sign included:
    (x=1, w=0)∘(x=1, w=0) gives w = +1). The result is in the type of ``pose``."""
    ts = to_transform_stamped(transform)
    if hasattr(pose, "header"):
        ours = _stamped(pose, _PoseStamped, "pose")
        return _out(_PoseStamped(ts.header, _pose_kdl(ts, ours.pose)), pose)
    plain = Pose(to_point(pose.position, "pose.position"),
                 to_quaternion(pose.orientation, "pose.orientation"))
    out = _pose_kdl(ts, plain)
    if isinstance(pose, tuple):
        return out
    return _assign(type(pose)(), out)


def do_transform_pose_stamped(pose: Any, transform: Any) -> Any:
    """ROS 2 ``do_transform_pose_stamped``: as :func:`do_transform_pose`."""
    return do_transform_pose(_stamped(pose, _PoseStamped, "pose") if not hasattr(
        pose, "header") else pose, transform)


def do_transform_pose_with_covariance_stamped(pose: Any, transform: Any) -> Any:
    """ROS 2 ``do_transform_pose_with_covariance_stamped``: the pose through KDL as
    :func:`do_transform_pose` (ROS 2 goes through ``tf2::fromMsg`` to a KDL frame: bit
    for bit, w = +1 for (x=1, w=0)∘(x=1, w=0)), the covariance rotated by
    :func:`tfbus.convert.do_transform_pose_with_covariance`. A rospy or rclpy
    PoseWithCovarianceStamped in, the same class out (as ROS 2's builds a
    ``geometry_msgs.msg.PoseWithCovarianceStamped``); a tfbus value for anything else."""
    ts = to_transform_stamped(transform)
    ours = _stamped(pose, PoseWithCovarianceStamped, "pose")
    out = _pose_cov(ours, ts)
    return ros_out(out._replace(pose=out.pose._replace(pose=_pose_kdl(ts, ours.pose.pose))),
                   pose)


def transform_covariance(cov_in: Any, transform: Any) -> tuple[float, ...]:
    """ROS 2 ``transform_covariance(cov_in, transform)`` (the 36 rotated numbers):
    :func:`tfbus.convert.transform_covariance`."""
    return _covariance(cov_in, to_transform_stamped(transform))


def do_transform_polygon_stamped(polygon: Any, transform: Any) -> Any:
    """ROS 2 ``do_transform_polygon_stamped``: :func:`tfbus.convert.do_transform_polygon`;
    a rospy or rclpy PolygonStamped in, the same class out (its ``Point32`` points); a
    tfbus PolygonStamped for anything else."""
    return ros_out(_polygon(_stamped(polygon, PolygonStamped, "polygon"),
                            to_transform_stamped(transform)), polygon)
