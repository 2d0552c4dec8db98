"""Rigid-transform geometry on numpy arrays (tf2_geometry_msgs' ``do_transform_*`` on
messages are in :mod:`tfbus.convert`).

Conventions (the same everywhere in tfbus):

* A transform is a translation ``(3,)`` in metres plus a rotation quaternion ``(4,)`` in
  **(x, y, z, w)** order, w last, as in ROS messages. It maps a point ``p`` expressed in
  the child frame into the parent frame: ``R(q) p + t``.
* Batched forms take ``(N, 3)`` / ``(N, 4)`` float64 arrays and work row by row; a single
  ``(3,)`` / ``(4,)`` operand is broadcast against a batch. Two batched operands must have
  the same ``N``. Wrong shapes raise :class:`ValueError`. Inputs are anything
  ``numpy.asarray`` accepts (lists, tuples, :class:`~tfbus.messages.Quaternion` …);
  outputs are new float64 arrays.
* Angles are radians.

Formulas:

* :func:`compose`, :func:`inverse`, :func:`rotate_vectors`, :func:`apply_transform` and
  :func:`quat_multiply` evaluate tf2's expressions (``tf2/LinearMath/Quaternion.h``
  ``operator*`` and ``quatRotate``, ``tf2/src/buffer_core.cpp`` ``TransformAccum``) in the
  same order as the core's scalar math (:mod:`tfbus.core._cmath` or :mod:`tfbus.core._pymath`): row
  by row, results are bit-for-bit equal to the
  scalar ones that :class:`~tfbus.core.BufferCore` computes. One quaternion against many
  vectors or points uses the equivalent 3x3 matrix instead (KDL's
  ``Rotation::Quaternion``, as tf2_geometry_msgs), ~5x faster and equal within a few ulp.
* :func:`slerp` *is* tf2's ``Quaternion::slerp`` (the core's ``slerp``);
  :func:`slerp_batch` repeats it with numpy and agrees to within a few ulp (numpy's
  ``arccos`` may round differently from the C library's ``acos``).
* Matrices and Euler angles go through transforms3d (``quaternions.quat2mat`` /
  ``mat2quat``, ``euler.euler2quat`` / ``quat2euler``), whose quaternions are
  (w, x, y, z): the order is swapped in :func:`_to_wxyz` / :func:`_to_xyzw` and nowhere
  else.

Non-unit quaternions: like tf2, tfbus never normalises. Rotating a vector computes
``q v q*``, which for a non-unit ``q`` is the rotation by ``q/|q|`` scaled by ``|q|²``
(exactly as tf2's lookups and tf2_geometry_msgs' KDL ``Rotation::Quaternion`` do), and
:func:`inverse` uses the conjugate. The matrix and Euler conversions, on the other hand,
normalise (transforms3d's ``quat2mat`` divides by ``|q|²``). Feed unit quaternions and
all of these agree.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from transforms3d import euler as _t3d_euler
from transforms3d import quaternions as _t3d_quat

from tfbus.core import kernels as _core
from tfbus.core.batch import quat_rotate_rows
from tfbus.messages import (
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
)

__all__ = [
    "apply_transform",
    "compose",
    "euler_from_quaternion",
    "from_matrix",
    "inverse",
    "quat_multiply",
    "quaternion_from_euler",
    "rotate_vectors",
    "slerp",
    "slerp_batch",
    "to_matrix",
    "transform_from_arrays",
    "transform_from_matrix",
    "transform_points",
    "transform_to_arrays",
    "transform_to_matrix",
]

Array = NDArray[np.float64]
"""A float64 numpy array."""

_HOMOGENEOUS_ROW: Final = np.array([0.0, 0.0, 0.0, 1.0])
_CONJUGATE_SIGNS: Final = np.array([-1.0, -1.0, -1.0, 1.0])


# --------------------------------------------------------------------------- helpers


def _to_wxyz(q: Array) -> Array:
    """(x, y, z, w) -> (w, x, y, z) for transforms3d. The only place the order is swapped."""
    return q[..., [3, 0, 1, 2]]


def _to_xyzw(q: Array) -> Array:
    """(w, x, y, z) from transforms3d -> (x, y, z, w). The only place the order is swapped."""
    return np.asarray(q, dtype=np.float64)[..., [1, 2, 3, 0]]


def _as_array(value: npt.ArrayLike, width: int, name: str) -> Array:
    """``value`` as float64 of shape ``(width,)`` or ``(N, width)``, else ValueError."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[-1] != width:
        raise ValueError(f"{name} must have shape ({width},) or (N, {width}), got {arr.shape}")
    return arr


def _batch_size(**arrays: Array) -> int | None:
    """The common N of the 2-D arrays (None if all are 1-D); ValueError if they differ."""
    sizes = {name: a.shape[0] for name, a in arrays.items() if a.ndim == 2}
    if len(set(sizes.values())) > 1:
        detail = ", ".join(f"{name} has {n}" for name, n in sizes.items())
        raise ValueError(f"batched operands must have the same number of rows N: {detail}")
    return next(iter(sizes.values()), None)


def _fit(arr: Array, n: int | None) -> Array:
    """Broadcast a result to ``(n, width)`` when the call was batched."""
    if n is None or arr.ndim == 2:
        return arr
    out: Array = np.broadcast_to(arr, (n, arr.shape[-1])).copy()  # typed for Python 3.10
    return out


def _quat_multiply(a: Array, b: Array) -> Array:
    # Quaternion.h operator* / _cmath.quat_multiply, same evaluation order.
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by + ay * bw + az * bx - ax * bz,
            aw * bz + az * bw + ax * by - ay * bx,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def _rotation_matrix(q: Array) -> Array:
    # The 3x3 matrix of v -> q v q* for one, possibly non-unit, quaternion (|q|² R(q/|q|)):
    # KDL ``Rotation::Quaternion``, which tf2_geometry_msgs' doTransform uses.
    x, y, z, w = q.tolist()
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    return np.array(
        [
            [w2 + x2 - y2 - z2, 2 * x * y - 2 * w * z, 2 * x * z + 2 * w * y],
            [2 * x * y + 2 * w * z, w2 - x2 + y2 - z2, 2 * y * z - 2 * w * x],
            [2 * x * z - 2 * w * y, 2 * y * z + 2 * w * x, w2 - x2 - y2 + z2],
        ]
    )


def _rotate(q: Array, v: Array) -> Array:
    # One quaternion and many vectors: a 3x3 matrix product is ~5x faster than the
    # element-wise quatRotate and equal to it within a few ulp.
    if q.ndim == 1 and v.ndim == 2:
        rotated: Array = v @ _rotation_matrix(q).T
        return rotated
    return quat_rotate_rows(q, v)


def _conjugate(q: Array) -> Array:
    conj: Array = q * _CONJUGATE_SIGNS
    return conj


# --------------------------------------------------------------------------- arrays


def quat_multiply(a: npt.ArrayLike, b: npt.ArrayLike) -> Array:
    """Hamilton product ``a ⊗ b`` (rotate by b, then by a).

    Args:
        a, b: quaternions, (x, y, z, w), shape ``(4,)`` or ``(N, 4)``.

    Returns:
        ``(4,)`` or ``(N, 4) float64``; not normalised.

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: ``tf2/LinearMath/Quaternion.h`` ``operator*``.
    """
    qa = _as_array(a, 4, "a")
    qb = _as_array(b, 4, "b")
    n = _batch_size(a=qa, b=qb)
    return _fit(_quat_multiply(qa, qb), n)


def rotate_vectors(rotation: npt.ArrayLike, vectors: npt.ArrayLike) -> Array:
    """Rotate direction vectors (no translation): ``q v q*``.

    Args:
        rotation: quaternion(s), (x, y, z, w), ``(4,)`` or ``(N, 4)``.
        vectors: ``(3,)`` or ``(N, 3)``, any unit.

    Returns:
        Rotated vectors, ``(3,)`` or ``(N, 3) float64``. A non-unit quaternion scales the
        result by ``|q|²``, as in tf2.

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: ``tf2/LinearMath/Quaternion.h`` ``quatRotate``.
    """
    q = _as_array(rotation, 4, "rotation")
    v = _as_array(vectors, 3, "vectors")
    n = _batch_size(rotation=q, vectors=v)
    return _fit(_rotate(q, v), n)


def apply_transform(
    translation: npt.ArrayLike, rotation: npt.ArrayLike, points: npt.ArrayLike
) -> Array:
    """Map points from the child frame to the parent frame: ``q p q* + t``.

    Args:
        translation: metres, ``(3,)`` or ``(N, 3)``.
        rotation: quaternion(s), (x, y, z, w), ``(4,)`` or ``(N, 4)``.
        points: metres, ``(3,)`` or ``(N, 3)``. One transform applies to all points; N
            transforms apply row by row.

    Returns:
        Points in the parent frame, ``(3,)`` or ``(N, 3) float64``.

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: tf2's ``TransformAccum`` (``quatRotate(q, p) + t``).
    """
    t = _as_array(translation, 3, "translation")
    q = _as_array(rotation, 4, "rotation")
    p = _as_array(points, 3, "points")
    n = _batch_size(translation=t, rotation=q, points=p)
    return _fit(_rotate(q, p) + t, n)


def compose(
    translation_a: npt.ArrayLike,
    rotation_a: npt.ArrayLike,
    translation_b: npt.ArrayLike,
    rotation_b: npt.ArrayLike,
) -> tuple[Array, Array]:
    """``a ∘ b``: the transform that applies b, then a.

    If b maps frame C into B and a maps B into A, the result maps C into A:
    translation ``q_a t_b q_a* + t_a``, rotation ``q_a ⊗ q_b``.

    Args:
        translation_a, translation_b: metres, ``(3,)`` or ``(N, 3)``.
        rotation_a, rotation_b: quaternions, (x, y, z, w), ``(4,)`` or ``(N, 4)``.

    Returns:
        ``(translation, rotation)``: ``(3,)``/``(4,)``, or ``(N, 3)``/``(N, 4) float64``
        if any operand is batched. The rotation is not normalised.

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: ``tf2/src/buffer_core.cpp`` ``TransformAccum::accum``;
    :func:`tfbus.core._cmath.compose` gives bit-identical numbers for one transform.
    """
    ta = _as_array(translation_a, 3, "translation_a")
    qa = _as_array(rotation_a, 4, "rotation_a")
    tb = _as_array(translation_b, 3, "translation_b")
    qb = _as_array(rotation_b, 4, "rotation_b")
    n = _batch_size(translation_a=ta, rotation_a=qa, translation_b=tb, rotation_b=qb)
    return _fit(_rotate(qa, tb) + ta, n), _fit(_quat_multiply(qa, qb), n)


def inverse(translation: npt.ArrayLike, rotation: npt.ArrayLike) -> tuple[Array, Array]:
    """The inverse transform: rotation ``q*``, translation ``q* (-t) q``.

    Args:
        translation: metres, ``(3,)`` or ``(N, 3)``.
        rotation: quaternion(s), (x, y, z, w), ``(4,)`` or ``(N, 4)``.

    Returns:
        ``(translation, rotation)`` with the shapes of :func:`compose`. Exact inverse for
        unit quaternions; for non-unit ones it is tf2's (conjugate, not reciprocal).

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: ``tf2/src/buffer_core.cpp`` ``TransformAccum::finalize``;
    :func:`tfbus.core._cmath.inverse`.
    """
    t = _as_array(translation, 3, "translation")
    q = _as_array(rotation, 4, "rotation")
    n = _batch_size(translation=t, rotation=q)
    qc = _conjugate(q)
    return _fit(_rotate(qc, -t), n), _fit(qc, n)


def slerp(q0: npt.ArrayLike, q1: npt.ArrayLike, ratio: float) -> Quaternion:
    """tf2's shortest-path spherical linear interpolation of one pair of quaternions.

    Args:
        q0: start, (x, y, z, w), shape ``(4,)`` (a :class:`Quaternion`, tuple, array …).
        q1: end, same form.
        ratio: 0 gives ``q0``, 1 gives ``q1`` or ``-q1`` (whichever is nearer ``q0``).

    Returns:
        The interpolated :class:`Quaternion`. If ``q0·q1 < 0`` the path runs towards
        ``-q1`` (the shorter arc); if the angle between them is exactly 0, ``q0`` is
        returned unchanged. Not normalised.

    Raises:
        ValueError: if ``q0`` or ``q1`` is not of shape ``(4,)``.
        ZeroDivisionError: if either quaternion is zero (tf2 would return NaN).

    Source: ``tf2/LinearMath/Quaternion.h`` ``Quaternion::slerp`` via
    :func:`tfbus.core._cmath.slerp`.
    """
    a = np.asarray(q0, dtype=np.float64)
    b = np.asarray(q1, dtype=np.float64)
    for name, arr in (("q0", a), ("q1", b)):
        if arr.shape != (4,):
            raise ValueError(f"{name} must have shape (4,), got {arr.shape}")
    ax, ay, az, aw = (float(c) for c in a)
    bx, by, bz, bw = (float(c) for c in b)
    return Quaternion(*_core.slerp(ax, ay, az, aw, bx, by, bz, bw, float(ratio)))


def slerp_batch(q0: npt.ArrayLike, q1: npt.ArrayLike, ratio: npt.ArrayLike) -> Array:
    """:func:`slerp` row by row with numpy.

    Args:
        q0, q1: quaternions, (x, y, z, w), ``(4,)`` or ``(N, 4)``.
        ratio: a scalar or an ``(N,)`` array of ratios.

    Returns:
        ``(4,)`` or ``(N, 4) float64``: the same numbers as :func:`slerp` to within a few
        ulp. Rows with a zero quaternion give NaN (as tf2 would) instead of raising.

    Raises:
        ValueError: wrong shapes, or batches of different N.

    Source: ``tf2/LinearMath/Quaternion.h`` ``Quaternion::slerp``, ``angleShortestPath``.
    """
    a = _as_array(q0, 4, "q0")
    b = _as_array(q1, 4, "q1")
    r = np.asarray(ratio, dtype=np.float64)
    if r.ndim > 1:
        raise ValueError(f"ratio must be a scalar or have shape (N,), got {r.shape}")
    n = _batch_size(q0=a, q1=b)
    if r.ndim == 1:
        if n is not None and r.shape[0] != n:
            raise ValueError(f"ratio has {r.shape[0]} rows but the quaternions have {n}")
        n = r.shape[0]
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        dot = ax * bx + ay * by + az * bz + aw * bw
        s = np.sqrt(
            (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
        )
        negative = dot < 0.0
        # tf2Acos clamps to [-1, 1] (a cosine rounding above 1 is a zero angle); NaN stays.
        theta = np.arccos(np.clip(np.where(negative, -dot, dot) / s, -1.0, 1.0))
        b = np.where(negative[..., None], -b, b)
        d = 1.0 / np.sin(theta)
        s0 = np.sin((1.0 - r) * theta)
        s1 = np.sin(r * theta)
        out = (a * s0[..., None] + b * s1[..., None]) * d[..., None]
    out = np.where((theta == 0.0)[..., None], a, out)
    return _fit(out, n)


def to_matrix(translation: npt.ArrayLike, rotation: npt.ArrayLike) -> Array:
    """The 4x4 homogeneous matrix ``[[R, t], [0, 0, 0, 1]]`` of one transform.

    Args:
        translation: metres, shape ``(3,)``.
        rotation: quaternion, (x, y, z, w), shape ``(4,)``; normalised by transforms3d
            (a quaternion of norm below machine epsilon gives the identity rotation).

    Returns:
        ``(4, 4) float64``, acting on column vectors ``(x, y, z, 1)``.

    Raises:
        ValueError: if the shapes are not ``(3,)`` and ``(4,)``.

    Source: ``transforms3d.quaternions.quat2mat``.
    """
    t = np.asarray(translation, dtype=np.float64)
    q = np.asarray(rotation, dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,):
        raise ValueError(
            f"translation must have shape (3,) and rotation (4,), got {t.shape} and {q.shape}"
        )
    m = np.eye(4)
    m[:3, :3] = _t3d_quat.quat2mat(_to_wxyz(q))
    m[:3, 3] = t
    return m


def from_matrix(matrix: npt.ArrayLike) -> tuple[Array, Array]:
    """Translation and unit quaternion of a 4x4 homogeneous rigid transform matrix.

    Args:
        matrix: ``(4, 4)``, bottom row ``(0, 0, 0, 1)``; the upper-left 3x3 should be a
            rotation (the nearest quaternion is taken if it is not quite orthonormal).

    Returns:
        ``(translation (3,), rotation (4,))``, float64, rotation (x, y, z, w) with
        ``w >= 0``.

    Raises:
        ValueError: if the shape is not ``(4, 4)`` or the bottom row is not
            ``(0, 0, 0, 1)`` (within 1e-9).

    Source: ``transforms3d.quaternions.mat2quat`` (Bar-Itzhack's method).
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"matrix must have shape (4, 4), got {m.shape}")
    if not np.allclose(m[3], _HOMOGENEOUS_ROW, rtol=0.0, atol=1e-9):
        raise ValueError(f"matrix bottom row must be (0, 0, 0, 1), got {tuple(m[3].tolist())}")
    return m[:3, 3].copy(), _to_xyzw(_t3d_quat.mat2quat(m[:3, :3]))


def quaternion_from_euler(ai: float, aj: float, ak: float, axes: str = "sxyz") -> Array:
    """Quaternion (x, y, z, w) from Euler angles in radians.

    Args:
        ai, aj, ak: the three angles, radians. With the default ``"sxyz"`` (static axes)
            they are roll, pitch, yaw, as ``tf2::Quaternion::setRPY``.
        axes: one of transforms3d's 24 axis sequences (``"sxyz"``, ``"rzyx"``, …).

    Returns:
        ``(4,) float64`` unit quaternion, (x, y, z, w).

    Raises:
        KeyError: for an unknown ``axes`` string (from transforms3d).

    Source: ``transforms3d.euler.euler2quat``.
    """
    return _to_xyzw(_t3d_euler.euler2quat(ai, aj, ak, axes))


def euler_from_quaternion(
    rotation: npt.ArrayLike, axes: str = "sxyz"
) -> tuple[float, float, float]:
    """Euler angles in radians from a quaternion (x, y, z, w).

    Args:
        rotation: shape ``(4,)``; normalised by transforms3d.
        axes: axis sequence, as in :func:`quaternion_from_euler`.

    Returns:
        ``(ai, aj, ak)`` radians; for ``"sxyz"``, ``(roll, pitch, yaw)`` with pitch in
        ``[-π/2, π/2]``.

    Raises:
        ValueError: if ``rotation`` is not of shape ``(4,)``.
        KeyError: for an unknown ``axes`` string (from transforms3d).

    Source: ``transforms3d.euler.quat2euler``.
    """
    q = np.asarray(rotation, dtype=np.float64)
    if q.shape != (4,):
        raise ValueError(f"rotation must have shape (4,), got {q.shape}")
    ai, aj, ak = _t3d_euler.quat2euler(_to_wxyz(q), axes)
    return float(ai), float(aj), float(ak)


# --------------------------------------------------------------------------- messages


def transform_to_arrays(transform: Transform | TransformStamped) -> tuple[Array, Array]:
    """``(translation (3,), rotation (4,))`` float64 arrays of a message; (x, y, z, w)."""
    if isinstance(transform, TransformStamped):
        transform = transform.transform
    return (
        np.array(transform.translation, dtype=np.float64),
        np.array(transform.rotation, dtype=np.float64),
    )


def transform_from_arrays(translation: npt.ArrayLike, rotation: npt.ArrayLike) -> Transform:
    """A :class:`Transform` message from a ``(3,)`` translation and ``(4,)`` (x, y, z, w).

    Raises:
        ValueError: if the shapes are not ``(3,)`` and ``(4,)``.
    """
    t = np.asarray(translation, dtype=np.float64)
    q = np.asarray(rotation, dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,):
        raise ValueError(
            f"translation must have shape (3,) and rotation (4,), got {t.shape} and {q.shape}"
        )
    tx, ty, tz = t.tolist()
    qx, qy, qz, qw = q.tolist()
    return Transform(Vector3(tx, ty, tz), Quaternion(qx, qy, qz, qw))


def transform_to_matrix(transform: Transform | TransformStamped) -> Array:
    """The ``(4, 4)`` homogeneous matrix of a message (see :func:`to_matrix`)."""
    return to_matrix(*transform_to_arrays(transform))


def transform_from_matrix(matrix: npt.ArrayLike) -> Transform:
    """A :class:`Transform` message from a ``(4, 4)`` matrix (see :func:`from_matrix`).

    Raises:
        ValueError: as :func:`from_matrix`.
    """
    return transform_from_arrays(*from_matrix(matrix))


def transform_points(transform: Transform | TransformStamped, points: npt.ArrayLike) -> Array:
    """Map many points through one transform message, vectorised.

    Args:
        transform: maps child-frame coordinates into the parent frame (for a
            ``TransformStamped`` from ``lookup_transform(target, source, t)``: source into
            target).
        points: metres, ``(N, 3)`` (or a single ``(3,)``).

    Returns:
        ``(N, 3) float64`` (or ``(3,)``), in the transform's parent frame.

    Raises:
        ValueError: if ``points`` is not ``(N, 3)`` or ``(3,)``.
    """
    t, q = transform_to_arrays(transform)
    return apply_transform(t, q, points)
