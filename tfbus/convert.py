"""Which function transforms which stamped type: tf2_ros's ``TransformRegistration``.

:meth:`Buffer.transform <tfbus.buffer.Buffer.transform>` and
:meth:`~tfbus.buffer.Buffer.transform_full` look up the type of the object they are
given here and call the registered function with the object and the transform that
:meth:`~tfbus.core.BufferCore.lookup_transform` found, exactly as tf2_ros's
``BufferInterface.transform`` calls ``self.registration.get(type(obj))(obj, transform)``
(``tf2_ros/buffer_interface.py``)::

    from tfbus.convert import register_transform

    def do_transform_cloud(cloud: MyCloudStamped, transform: TransformStamped) -> MyCloudStamped:
        points = tfbus.geometry.transform_points(transform, cloud.points)   # (N, 3)
        return MyCloudStamped(transform.header, points)

    register_transform(MyCloudStamped, do_transform_cloud)
    cloud_in_map = await buffer.transform(cloud, "map", timeout=1.0)

The function takes ``(obj, transform)`` in tf2_ros's order, where ``transform`` maps
``obj.header.frame_id`` into the target frame, and returns the transformed object,
whose header should be ``transform.header`` (the target frame and the stamp used), as
tf2_geometry_msgs' ``do_transform_*`` do. The object only has to carry
``header.frame_id`` (a ``str``) and ``header.stamp`` (a :class:`~tfbus.time.Time`).

Preregistered (tf2_geometry_msgs): :class:`~tfbus.messages.PointStamped`,
:class:`~tfbus.messages.PoseStamped`, :class:`~tfbus.messages.Vector3Stamped` (rotated
only), :class:`~tfbus.messages.TransformStamped` (:func:`do_transform_transform`),
:class:`~tfbus.messages.WrenchStamped` (:func:`do_transform_wrench`), and
(tf2_sensor_msgs) :class:`~tfbus.sensor_msgs.PointCloud2` (:func:`do_transform_cloud`);
and :class:`~tfbus.messages.Stamped` (:func:`do_transform_stamped`).

Lookup is by the object's exact type first, then by its base classes in method
resolution order (a subclass of ``PointStamped`` is transformed as one); tf2_ros looks
up the exact type only. There is one table per process, shared by every
:class:`TransformRegistration` and every Buffer, as in tf2_ros (its map is a class
attribute).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any, ClassVar, TypeVar

import numpy as np

from tfbus.core import kernels as _core
from tfbus.errors import InvalidArgumentException
from tfbus.geometry import _rotation_matrix, transform_to_arrays
from tfbus.messages import (
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
    Stamped,
    Transform,
    TransformStamped,
    Twist,
    TwistStamped,
    Vector3,
    Vector3Stamped,
    VelocityStamped,
    Wrench,
    WrenchStamped,
)
from tfbus.sensor_msgs import PointCloud2, PointField, dtype_from_fields

__all__ = [
    "ConvertRegistration",
    "TransformFunction",
    "TransformRegistration",
    "convert",
    "do_transform_cloud",
    "do_transform_point",
    "do_transform_polygon",
    "do_transform_pose",
    "do_transform_pose_with_covariance",
    "do_transform_stamped",
    "do_transform_transform",
    "do_transform_twist",
    "do_transform_vector3",
    "do_transform_velocity",
    "do_transform_wrench",
    "get_transform_function",
    "register_transform",
    "registered_types",
    "transform_covariance",
]

_M = TypeVar("_M")

TransformFunction = Callable[[Any, TransformStamped], Any]
"""``(obj, transform) -> transformed obj``: tf2_ros's registered ``do_transform``."""


class TransformRegistration:
    """The registry of transform functions by type, with tf2_ros's method names.

    ``TransformRegistration().add(MyStamped, fn)`` / ``.get(MyStamped)``; every
    instance shares one table (tf2_ros ``TransformRegistration`` keeps its map on the
    class). :func:`register_transform` and :func:`get_transform_function` are the same
    operations as functions.
    """

    _table: ClassVar[dict[type, TransformFunction]] = {}

    def add(self, key: type[_M], callback: Callable[[_M, TransformStamped], _M]) -> None:
        """Register ``callback(obj, transform) -> obj`` for objects of type ``key``.

        A later registration for the same type replaces the earlier one.

        Raises:
            TypeError: ``key`` is not a class, or ``callback`` is not callable.
        """
        if not isinstance(key, type):
            raise TypeError(f"key must be a class, got {key!r}")
        if not callable(callback):
            raise TypeError(f"callback for {key.__name__} must be callable, got {callback!r}")
        TransformRegistration._table[key] = callback

    def get(self, key: type) -> TransformFunction:
        """The function registered for ``key`` (or for its nearest registered base class).

        Raises:
            TypeError: nothing is registered for ``key`` nor its bases; the message
                lists the registered types and says how to register one.
        """
        table = TransformRegistration._table
        fn = table.get(key)
        if fn is not None:
            return fn
        for base in getattr(key, "__mro__", ())[1:]:
            fn = table.get(base)
            if fn is not None:
                return fn
        known = ", ".join(sorted(t.__name__ for t in table))
        name = getattr(key, "__name__", repr(key))
        raise TypeError(
            f"no transform function registered for type {name} (registered: {known}); "
            f"register one with tfbus.convert.register_transform({name}, fn) where "
            f"fn(obj, transform: TransformStamped) returns the transformed object"
        )

    def types(self) -> tuple[type, ...]:
        """The registered types, in registration order."""
        return tuple(TransformRegistration._table)


def register_transform(key: type[_M], callback: Callable[[_M, TransformStamped], _M]) -> None:
    """Register ``callback(obj, transform) -> obj`` for ``key`` (see the module docs).

    Raises:
        TypeError: ``key`` is not a class, or ``callback`` is not callable.
    """
    TransformRegistration().add(key, callback)


def get_transform_function(key: type) -> TransformFunction:
    """The function :meth:`Buffer.transform <tfbus.buffer.Buffer.transform>` uses for
    objects of type ``key``.

    Raises:
        TypeError: no function is registered for ``key`` nor its bases.
    """
    return TransformRegistration().get(key)


def registered_types() -> tuple[type, ...]:
    """Every type with a registered transform function."""
    return TransformRegistration().types()


def _point_through(
    ts: TransformStamped, x: float, y: float, z: float
) -> tuple[float, float, float]:
    tr = ts.transform.translation
    q = ts.transform.rotation
    rx, ry, rz = _core.quat_rotate(q.x, q.y, q.z, q.w, x, y, z)
    return rx + tr.x, ry + tr.y, rz + tr.z


def do_transform_point(point: PointStamped, transform: TransformStamped) -> PointStamped:
    """Transform a stamped point, as tf2_geometry_msgs' ``do_transform_point``.

    Args:
        point: a point (metres) in ``transform.child_frame_id``.
        transform: e.g. ``lookup_transform(target, point.header.frame_id, t)``.

    Returns:
        The point in the transform's parent frame. Its header is ``transform.header``
        (stamp and ``frame_id`` of the transform), as in tf2_geometry_msgs; the point's
        own header is not checked nor kept. Numbers are bit-for-bit those of
        :func:`tfbus.geometry.apply_transform` on one point.

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).

    Source: ``tf2_geometry_msgs/tf2_geometry_msgs.h`` ``doTransform(PointStamped)``.
    """
    x, y, z = _point_through(transform, *point.point)
    return PointStamped(transform.header, Point(x, y, z))


def do_transform_vector3(vector: Vector3Stamped, transform: TransformStamped) -> Vector3Stamped:
    """Rotate a stamped vector, as tf2_geometry_msgs' ``do_transform_vector3``.

    Only the rotation applies (a direction has no position). The result header is
    ``transform.header``. A non-unit quaternion scales the vector by ``|q|²``, as tf2's
    KDL ``Rotation::Quaternion`` does.

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).

    Source: ``tf2_geometry_msgs/tf2_geometry_msgs.h`` ``doTransform(Vector3Stamped)``.
    """
    q = transform.transform.rotation
    x, y, z = _core.quat_rotate(q.x, q.y, q.z, q.w, *vector.vector)
    return Vector3Stamped(transform.header, Vector3(x, y, z))


def do_transform_pose(pose: PoseStamped, transform: TransformStamped) -> PoseStamped:
    """Transform a stamped pose, as tf2_geometry_msgs' ``do_transform_pose``.

    Position: ``q p q* + t``; orientation: ``q ⊗ q_pose`` (tf2's compose). The result
    header is ``transform.header``. tf2_geometry_msgs goes through a KDL rotation matrix
    and may return the negated, equivalent quaternion; tfbus keeps the product's sign and
    does not normalise it.

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).

    Source: ``tf2_geometry_msgs/tf2_geometry_msgs.h`` ``doTransform(PoseStamped)``.
    """
    p = pose.pose
    x, y, z = _point_through(transform, *p.position)
    q = transform.transform.rotation
    o = p.orientation
    qx, qy, qz, qw = _core.quat_multiply(q.x, q.y, q.z, q.w, o.x, o.y, o.z, o.w)
    return PoseStamped(transform.header, Pose(Point(x, y, z), Quaternion(qx, qy, qz, qw)))


def do_transform_transform(
    transform_in: TransformStamped, transform: TransformStamped
) -> TransformStamped:
    """Re-express a stamped transform in the transform's parent frame.

    ``transform_in`` places ``transform_in.child_frame_id`` in
    ``transform_in.header.frame_id``; ``transform`` maps that frame into a target frame.
    The result places the same child in the target frame: translation ``q t q* + T``,
    rotation ``q ⊗ r`` (tf2's ``Transform`` product ``transform * transform_in``), header
    ``transform.header``, ``child_frame_id`` kept. Translations in metres, quaternions
    (x, y, z, w), not normalised (tf2 goes through a rotation matrix and normalises: for
    unit quaternions the two agree up to sign and rounding).

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).

    Source: ``tf2_geometry_msgs/tf2_geometry_msgs.h``
    ``doTransform(TransformStamped, TransformStamped, TransformStamped)``; the
    arithmetic is :func:`do_transform_pose`'s.
    """
    tr, rot = transform_in.transform
    moved = do_transform_pose(PoseStamped(transform_in.header, Pose(Point(*tr), rot)), transform)
    pose = moved.pose
    return TransformStamped(
        transform.header,
        transform_in.child_frame_id,
        Transform(Vector3(*pose.position), pose.orientation),
    )


def _rotate(v: Vector3, transform: TransformStamped) -> Vector3:
    return do_transform_vector3(Vector3Stamped(transform.header, v), transform).vector


def do_transform_wrench(
    wrench: WrenchStamped, transform: TransformStamped, *, lever_arm: bool = False
) -> WrenchStamped:
    """Re-express a stamped wrench in the transform's parent frame.

    Default, as ROS 1 tf2_geometry_msgs (Python ``do_transform_wrench``): force and
    torque are both rotated (N, N·m), the translation ignored. ``lever_arm=True`` is ROS
    2's C++ form (ros2/geometry2 #538): the torque about the new origin,
    ``R τ + t x (R f)`` (x: cross product). The result header is ``transform.header``.

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).
    """
    force = _rotate(wrench.wrench.force, transform)
    torque = _rotate(wrench.wrench.torque, transform)
    if lever_arm:
        t = transform.transform.translation
        torque = Vector3(
            torque.x + t.y * force.z - t.z * force.y,
            torque.y + t.z * force.x - t.x * force.z,
            torque.z + t.x * force.y - t.y * force.x,
        )
    return WrenchStamped(transform.header, Wrench(force, torque))


_XYZ = ("x", "y", "z")


# Points per block of the in-place cloud transform: its two (3, block) float64 arrays
# (120 KiB each) come from the heap, under glibc's 128 KiB mmap threshold (larger ones are
# mapped and page-faulted in on every call), and stay in the L2 cache.
_CLOUD_BLOCK = 5120


def _transform_xyz_in_place(points: np.ndarray[Any, Any], rotation: Any, t: Any) -> None:
    """Map the ``x``, ``y``, ``z`` fields of a 1-D structured array through ``R p + t``,
    in place, block by block: the fields of a block are read into one preallocated
    ``(3, block)`` float64 array, multiplied by R into another and written back in their
    own type, so the cost is two passes over the cloud and no temporary of its size.
    (Row-wise ``(block, 3)`` blocks are slower: numpy casts the strided float32 triplets
    element by element; field by field it runs its contiguous loops.)"""
    cols = [points[name] for name in _XYZ]
    n = points.shape[0]
    size = min(n, _CLOUD_BLOCK)
    src = np.empty((3, size))
    dst = np.empty((3, size))
    offset = t.reshape(3, 1)
    for start in range(0, n, size):
        stop = min(n, start + size)
        a, b = src[:, : stop - start], dst[:, : stop - start]
        for k in range(3):
            a[k] = cols[k][start:stop]
        np.matmul(rotation, a, out=b)
        b += offset
        for k in range(3):
            cols[k][start:stop] = b[k]


def do_transform_cloud(cloud: PointCloud2, transform: TransformStamped) -> PointCloud2:
    """Transform every point of a PointCloud2 (tf2_sensor_msgs ``do_transform_cloud``),
    vectorised with numpy, block by block in a copy of ``data`` (no temporaries the size
    of the cloud: ``benchmarks/bench_sensors.py`` compares it with bare numpy).

    The ``x``, ``y``, ``z`` fields (float32 or float64, metres) are mapped through the
    transform (computed in float64, stored back in each field's type); every other field,
    the layout (height, width, point_step, row_step, padding, byte order) and
    ``is_dense`` are kept. The result header is ``transform.header``.

    Raises:
        InvalidArgumentException: the cloud has no x, y or z field, or one of them is
            not float32/float64 or has a count other than 1 (the field is named).
        ValueError: ``data`` does not fit the layout.
    """
    fields = {f.name: f for f in cloud.fields}
    for name in _XYZ:
        f = fields.get(name)
        if f is None:
            raise InvalidArgumentException(
                f"PointCloud2 has no field {name!r} (fields: {sorted(fields)})"
            )
        if f.datatype not in (PointField.FLOAT32, PointField.FLOAT64) or f.count != 1:
            raise InvalidArgumentException(
                f"PointCloud2 field {name!r} must be one float32 or float64, got datatype "
                f"{f.datatype}, count {f.count}"
            )
    n = cloud.height * cloud.width
    if n == 0:
        return PointCloud2(
            transform.header, cloud.height, cloud.width, list(cloud.fields),
            cloud.is_bigendian, cloud.point_step, cloud.row_step, cloud.data, cloud.is_dense,
        )  # fmt: skip
    dtype = dtype_from_fields(cloud.fields, cloud.point_step, cloud.is_bigendian)
    need = (cloud.height - 1) * cloud.row_step + cloud.width * cloud.point_step
    if cloud.row_step < cloud.width * cloud.point_step or len(cloud.data) < need:
        raise ValueError(
            f"PointCloud2 data has {len(cloud.data)} bytes; height {cloud.height}, width "
            f"{cloud.width}, row_step {cloud.row_step}, point_step {cloud.point_step}"
        )
    buf = bytearray(cloud.data)
    rows = np.ndarray(
        (cloud.height, cloud.width), dtype=dtype, buffer=buf,
        strides=(cloud.row_step, cloud.point_step),
    )  # fmt: skip
    t, q = transform_to_arrays(transform)
    rotation = _rotation_matrix(q)
    if cloud.height == 1 or cloud.row_step == cloud.width * cloud.point_step:
        _transform_xyz_in_place(rows.reshape(-1), rotation, t)  # one run of points
    else:  # padded rows: one run per row
        for row in rows:
            _transform_xyz_in_place(row, rotation, t)
    return PointCloud2(
        transform.header, cloud.height, cloud.width, list(cloud.fields), cloud.is_bigendian,
        cloud.point_step, cloud.row_step, bytes(buf), cloud.is_dense,
    )  # fmt: skip


def transform_covariance(covariance: Any, transform: TransformStamped) -> tuple[float, ...]:
    """Rotate a 6x6 pose covariance (36 numbers, row-major, x y z then rotations) into
    the transform's parent frame: each 3x3 block ``B`` becomes ``R B Rᵀ`` with ``R`` the
    transform's rotation (ROS 2 tf2_geometry_msgs ``transform_covariance``,
    ros2/geometry2 #430); the translation does not enter.

    Raises:
        InvalidArgumentException: ``covariance`` is not 36 finite numbers.
    """
    try:
        cov = np.asarray(covariance, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidArgumentException(
            f"covariance must be 36 finite numbers, got {covariance!r}"
        ) from None
    if cov.shape != (36,) or not np.isfinite(cov).all():
        raise InvalidArgumentException(
            f"covariance must be 36 finite numbers, got shape {cov.shape}: {covariance!r}"
        )
    cols = [_rotate(Vector3(*e), transform) for e in ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0))]
    rot = np.array([[c.x, c.y, c.z] for c in cols]).T  # columns: the rotated axes
    jac = np.kron(np.eye(2), rot)
    out = jac @ cov.reshape(6, 6) @ jac.T
    return tuple(float(v) for v in out.ravel())


def do_transform_pose_with_covariance(
    pose: PoseWithCovarianceStamped, transform: TransformStamped
) -> PoseWithCovarianceStamped:
    """Transform a pose with covariance: the pose as :func:`do_transform_pose`,
    the covariance by :func:`transform_covariance` (ROS 2 tf2_geometry_msgs
    ``do_transform_pose_with_covariance_stamped``). The result header is
    ``transform.header``.

    Raises:
        InvalidArgumentException: the covariance is not 36 finite numbers.
    """
    cov = transform_covariance(pose.pose.covariance, transform)
    moved = do_transform_pose(PoseStamped(pose.header, pose.pose.pose), transform)
    return PoseWithCovarianceStamped(transform.header, PoseWithCovariance(moved.pose, cov))


def _twist(twist: Twist, transform: TransformStamped) -> Twist:
    """tf2's re-expression of a twist (``lookupVelocity`` step 4, ROS 2
    tf2_geometry_msgs ``doTransform(VelocityStamped)``): ``ω' = R ω``,
    ``v' = R v + t x ω'`` (x: cross product)."""
    w = _rotate(twist.angular, transform)
    v = _rotate(twist.linear, transform)
    t = transform.transform.translation
    return Twist(
        Vector3(v.x + t.y * w.z - t.z * w.y, v.y + t.z * w.x - t.x * w.z,
                v.z + t.x * w.y - t.y * w.x),
        w,
    )  # fmt: skip


def do_transform_twist(twist: TwistStamped, transform: TransformStamped) -> TwistStamped:
    """Re-express a stamped twist (m/s, rad/s) in the transform's parent frame with tf2's
    formula: angular rotated, linear rotated plus ``t x ω'`` (ROS 2 tf2_geometry_msgs
    ``doTransform(VelocityStamped)``, whose C++ also adds the input twist to the result
    and keeps the input header: not reproduced). The result header is
    ``transform.header``.

    Raises:
        Nothing of its own (no frame or stamp check, like tf2_geometry_msgs).
    """
    return TwistStamped(transform.header, _twist(twist.twist, transform))


def do_transform_velocity(
    velocity: VelocityStamped, transform: TransformStamped
) -> VelocityStamped:
    """:func:`do_transform_twist` for a VelocityStamped: ``velocity`` re-expressed, header
    ``transform.header``, ``body_frame_id`` and ``reference_frame_id`` kept."""
    return velocity._replace(
        header=transform.header, velocity=_twist(velocity.velocity, transform)
    )


def do_transform_polygon(polygon: PolygonStamped, transform: TransformStamped) -> PolygonStamped:
    """Move every vertex of a stamped polygon (metres) as :func:`do_transform_point`
    does (ROS 2 tf2_geometry_msgs ``do_transform_polygon_stamped``). The result header is
    ``transform.header``."""
    points = tuple(
        Point32(*do_transform_point(PointStamped(polygon.header, Point(*p)), transform).point)
        for p in polygon.polygon.points
    )
    return PolygonStamped(transform.header, Polygon(points))


def do_transform_stamped(obj: Stamped[Any], transform: TransformStamped) -> Stamped[Any]:
    """Transform a :class:`~tfbus.messages.Stamped` value by the type of its ``data``:
    Point (moved), Vector3 (rotated), Pose, Quaternion (rotated: ``q ⊗ data``),
    Transform (``transform * data``) or Wrench (force and torque rotated), with the
    arithmetic of the matching ``do_transform_*``. The result header is
    ``transform.header``.

    Raises:
        TypeError: ``data`` is of another type (named in the message).
    """
    data = obj.data
    header = transform.header
    if isinstance(data, Point):
        return Stamped(header, do_transform_point(PointStamped(obj.header, data), transform).point)
    if isinstance(data, Vector3):
        return Stamped(header, _rotate(data, transform))
    if isinstance(data, Pose):
        return Stamped(header, do_transform_pose(PoseStamped(obj.header, data), transform).pose)
    if isinstance(data, Quaternion):
        moved = do_transform_pose(PoseStamped(obj.header, Pose(Point(), data)), transform)
        return Stamped(header, moved.pose.orientation)
    if isinstance(data, Transform):
        ts = TransformStamped(obj.header, "", data)
        return Stamped(header, do_transform_transform(ts, transform).transform)
    if isinstance(data, Wrench):
        moved_wrench = do_transform_wrench(WrenchStamped(obj.header, data), transform)
        return Stamped(header, moved_wrench.wrench)
    raise TypeError(
        f"no transform for Stamped data of type {type(data).__name__} (Point, Vector3, Pose, "
        "Quaternion, Transform, Wrench)"
    )


register_transform(PointStamped, do_transform_point)
register_transform(PoseStamped, do_transform_pose)
register_transform(Vector3Stamped, do_transform_vector3)
register_transform(TransformStamped, do_transform_transform)
register_transform(WrenchStamped, do_transform_wrench)
register_transform(PoseWithCovarianceStamped, do_transform_pose_with_covariance)
register_transform(TwistStamped, do_transform_twist)
register_transform(VelocityStamped, do_transform_velocity)
register_transform(PolygonStamped, do_transform_polygon)
register_transform(PointCloud2, do_transform_cloud)
register_transform(Stamped, do_transform_stamped)


class ConvertRegistration:
    """tf2_ros's conversion registry (``tf2_ros/buffer_interface.py``), one table per
    process: ``add_to_msg(type, fn)``, ``add_from_msg(type, fn)``,
    ``add_convert((from_type, to_type), fn)`` and their ``get_*``; :func:`convert` uses
    them. ``get_*`` raise TypeError naming the type when nothing is registered."""

    _to_msg: ClassVar[dict[Any, Callable[[Any], Any]]] = {}
    _from_msg: ClassVar[dict[Any, Callable[[Any], Any]]] = {}
    _convert: ClassVar[dict[Any, Callable[[Any], Any]]] = {}

    def add_to_msg(self, key: Any, callback: Callable[[Any], Any]) -> None:
        """Register ``callback(obj) -> message`` for objects of type ``key``."""
        ConvertRegistration._to_msg[key] = callback

    def add_from_msg(self, key: Any, callback: Callable[[Any], Any]) -> None:
        """Register ``callback(message) -> obj`` building objects of type ``key``."""
        ConvertRegistration._from_msg[key] = callback

    def add_convert(self, key: Any, callback: Callable[[Any], Any]) -> None:
        """Register a direct conversion for ``key = (from_type, to_type)``."""
        ConvertRegistration._convert[key] = callback

    @staticmethod
    def _get(table: dict[Any, Callable[[Any], Any]], key: Any) -> Callable[[Any], Any]:
        fn = table.get(key)
        if fn is None:
            raise TypeError(f"Type {key} if not loaded or supported")  # tf2_ros's text
        return fn

    def get_to_msg(self, key: Any) -> Callable[[Any], Any]:
        """The ``to_msg`` function of ``key``. Raises TypeError when absent."""
        return self._get(ConvertRegistration._to_msg, key)

    def get_from_msg(self, key: Any) -> Callable[[Any], Any]:
        """The ``from_msg`` function of ``key``. Raises TypeError when absent."""
        return self._get(ConvertRegistration._from_msg, key)

    def get_convert(self, key: Any) -> Callable[[Any], Any]:
        """The direct conversion for ``(from_type, to_type)``. Raises TypeError when
        absent."""
        return self._get(ConvertRegistration._convert, key)


def convert(a: Any, b_type: Any) -> Any:
    """tf2_ros ``convert(a, b_type)``: a direct conversion when registered, else a copy
    when ``a`` already is a ``b_type``, else ``from_msg[b_type](to_msg[type(a)](a))``.

    Raises:
        TypeError: no way to convert (the missing type is named).
    """
    registry = ConvertRegistration()
    try:
        return registry.get_convert((type(a), b_type))(a)
    except TypeError:
        if type(a) is b_type:
            return copy.deepcopy(a)
        return registry.get_from_msg(b_type)(registry.get_to_msg(type(a))(a))
