"""``tf2_geometry_msgs``'s ``do_transform_*`` on tfbus types (ROS 1 and ROS 2 forms).

Where ROS 1 and ROS 2 differ the form is chosen by the argument's type:
``do_transform_pose`` takes a ``PoseStamped`` (ROS 1: returns a PoseStamped) or a
``Pose`` (ROS 2: returns a Pose); ``do_transform_pose_stamped`` is ROS 2's stamped name.
Foreign messages are read by their fields (:mod:`tfbus.compat._args`); the arithmetic is
:mod:`tfbus.geometry`'s / :mod:`tfbus.convert`'s.
"""

from __future__ import annotations

from typing import Any

from tfbus.compat._args import (
    to_point,
    to_quaternion,
    to_stamped,
    to_transform_stamped,
    to_vector3,
)
from tfbus.convert import do_transform_polygon as _polygon
from tfbus.convert import do_transform_pose_with_covariance as _pose_cov
from tfbus.convert import do_transform_transform as _transform
from tfbus.convert import do_transform_wrench as _wrench
from tfbus.convert import transform_covariance as _covariance
from tfbus.geometry import do_transform_point as _point
from tfbus.geometry import do_transform_pose as _pose_stamped
from tfbus.geometry import do_transform_vector3 as _vector3
from tfbus.messages import (
    Header,
    PointStamped,
    PolygonStamped,
    Pose,
    PoseStamped,
    PoseWithCovarianceStamped,
    TransformStamped,
    Vector3Stamped,
    Wrench,
    WrenchStamped,
)

__all__ = [
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


def _stamped(value: Any, kind: type, name: str) -> Any:
    out = to_stamped(value, name)
    if not isinstance(out, kind):
        raise TypeError(f"{name} must be a {kind.__name__} (by its fields), got {value!r}")
    return out


def do_transform_point(point: Any, transform: Any) -> PointStamped:
    """``do_transform_point(PointStamped, TransformStamped)``:
    :func:`tfbus.geometry.do_transform_point`."""
    return _point(_stamped(point, PointStamped, "point"), to_transform_stamped(transform))


def do_transform_vector3(vector3: Any, transform: Any) -> Vector3Stamped:
    """``do_transform_vector3(Vector3Stamped, TransformStamped)`` (rotation only):
    :func:`tfbus.geometry.do_transform_vector3`."""
    return _vector3(_stamped(vector3, Vector3Stamped, "vector3"), to_transform_stamped(transform))


def do_transform_transform(transform_in: Any, transform: Any) -> TransformStamped:
    """``do_transform_transform``: :func:`tfbus.convert.do_transform_transform`."""
    return _transform(to_transform_stamped(transform_in, "transform_in"),
                      to_transform_stamped(transform))


def do_transform_wrench(wrench: Any, transform: Any, *, lever_arm: bool = False) -> WrenchStamped:
    """``do_transform_wrench(WrenchStamped, TransformStamped)`` (ROS 1 Python: force and
    torque rotated; ``lever_arm=True``: ROS 2 C++): :func:`tfbus.convert.do_transform_wrench`."""
    if isinstance(wrench, WrenchStamped):
        ours = wrench
    else:  # the input's header is not used: the result carries the transform's
        body = wrench.wrench
        ours = WrenchStamped(
            Header(),
            Wrench(
                to_vector3(body.force, "wrench.force"), to_vector3(body.torque, "wrench.torque")
            ),
        )
    return _wrench(ours, to_transform_stamped(transform), lever_arm=lever_arm)


def do_transform_pose(pose: Any, transform: Any) -> Pose | PoseStamped:
    """ROS 1 ``do_transform_pose(PoseStamped, t)`` → PoseStamped, or ROS 2
    ``do_transform_pose(Pose, t)`` → Pose (chosen by whether ``pose`` has a header):
    :func:`tfbus.geometry.do_transform_pose`."""
    ts = to_transform_stamped(transform)
    if hasattr(pose, "header"):
        return _pose_stamped(_stamped(pose, PoseStamped, "pose"), ts)
    plain = Pose(to_point(pose.position, "pose.position"),
                 to_quaternion(pose.orientation, "pose.orientation"))
    return _pose_stamped(PoseStamped(ts.header, plain), ts).pose


def do_transform_pose_stamped(pose: Any, transform: Any) -> PoseStamped:
    """ROS 2 ``do_transform_pose_stamped``: :func:`tfbus.geometry.do_transform_pose`."""
    return _pose_stamped(_stamped(pose, PoseStamped, "pose"), to_transform_stamped(transform))


def do_transform_pose_with_covariance_stamped(
    pose: Any, transform: Any
) -> PoseWithCovarianceStamped:
    """ROS 2 ``do_transform_pose_with_covariance_stamped``:
    :func:`tfbus.convert.do_transform_pose_with_covariance`."""
    return _pose_cov(_stamped(pose, PoseWithCovarianceStamped, "pose"),
                     to_transform_stamped(transform))


def transform_covariance(cov_in: Any, transform: Any) -> tuple[float, ...]:
    """ROS 2 ``transform_covariance(cov_in, transform)`` (the 36 rotated numbers):
    :func:`tfbus.convert.transform_covariance`."""
    return _covariance(cov_in, to_transform_stamped(transform))


def do_transform_polygon_stamped(polygon: Any, transform: Any) -> PolygonStamped:
    """ROS 2 ``do_transform_polygon_stamped``: :func:`tfbus.convert.do_transform_polygon`."""
    return _polygon(_stamped(polygon, PolygonStamped, "polygon"), to_transform_stamped(transform))
