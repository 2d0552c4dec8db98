"""tf2's scalar transform arithmetic on plain float tuples, in pure Python: the tests'
reference for the compiled scalar math (``tfbus._ccore.compose`` / ``inverse`` /
``quat_multiply`` / ``quat_rotate`` / ``slerp``) and the batched :mod:`tfbus.geometry`.

A transform here is a 7-tuple ``(tx, ty, tz, qx, qy, qz, qw)``: translation in metres,
rotation quaternion in (x, y, z, w) order. numpy's per-call overhead (~1 µs) dominates
arrays this small, so single lookups use plain floats; batched work lives in
:mod:`tfbus.geometry`.

The formulas are tf2's own (``tf2/LinearMath/Quaternion.h`` and ``Vector3.h``,
``tf2/src/buffer_core.cpp`` ``TransformAccum``), including the parts that differ from
textbook quaternion algebra, because tfbus must reproduce tf2's numbers:

* quaternions are never normalised; ``inverse`` is the conjugate (Quaternion.h
  ``inverse()``), and a vector is rotated as ``q v q*`` (``quatRotate``), which scales it
  by ``|q|²`` for a non-unit q;
* slerp takes the shortest path and returns the first quaternion unchanged when the
  angle between the two rounds to zero (Quaternion.h ``slerp``/``angleShortestPath``).
"""

from __future__ import annotations

import math

__all__ = [
    "IDENTITY",
    "Tf7",
    "compose",
    "inverse",
    "quat_multiply",
    "quat_rotate",
    "slerp",
]

Tf7 = tuple[float, float, float, float, float, float, float]
"""A transform as ``(tx, ty, tz, qx, qy, qz, qw)``."""

IDENTITY: Tf7 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def quat_multiply(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    """Hamilton product ``a ⊗ b`` of two (x, y, z, w) quaternions (Quaternion.h ``operator*``)."""
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by + ay * bw + az * bx - ax * bz,
        aw * bz + az * bw + ax * by - ay * bx,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_rotate(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """Rotate vector v by quaternion q as ``q ⊗ (v, 0) ⊗ conj(q)`` (tf2 ``quatRotate``).

    For a unit q this is the rotation of v; for a non-unit q the result is scaled by
    ``|q|²``, exactly as in tf2.
    """
    # t = q ⊗ (v, 0)
    tx = qw * vx + qy * vz - qz * vy
    ty = qw * vy + qz * vx - qx * vz
    tz = qw * vz + qx * vy - qy * vx
    tw = -qx * vx - qy * vy - qz * vz
    # t ⊗ conj(q), vector part
    return (
        -tw * qx + tx * qw - ty * qz + tz * qy,
        -tw * qy + ty * qw - tz * qx + tx * qz,
        -tw * qz + tz * qw - tx * qy + ty * qx,
    )


def compose(a: Tf7, b: Tf7) -> Tf7:
    """``a ∘ b``: apply b, then a. Translation ``quatRotate(qa, tb) + ta``, rotation ``qa ⊗ qb``.

    This is tf2's ``TransformAccum::accum`` step (buffer_core.cpp).
    """
    ax, ay, az, aqx, aqy, aqz, aqw = a
    bx, by, bz, bqx, bqy, bqz, bqw = b
    rx, ry, rz = quat_rotate(aqx, aqy, aqz, aqw, bx, by, bz)
    return (rx + ax, ry + ay, rz + az, *quat_multiply(aqx, aqy, aqz, aqw, bqx, bqy, bqz, bqw))


def inverse(a: Tf7) -> Tf7:
    """tf2's inverse: rotation ``conj(q)``, translation ``quatRotate(conj(q), -t)``.

    Exact inverse for unit quaternions; matches tf2 (``TransformAccum::finalize``) for
    non-unit ones.
    """
    tx, ty, tz, qx, qy, qz, qw = a
    rx, ry, rz = quat_rotate(-qx, -qy, -qz, qw, -tx, -ty, -tz)
    return (rx, ry, rz, -qx, -qy, -qz, qw)


def _acos(x: float) -> float:
    """tf2's ``tf2Acos`` (``tf2/LinearMath/Scalar.h``): the argument is clamped to
    [-1, 1] first, so a cosine that rounds just above 1 is a zero angle; NaN stays NaN."""
    if x > 1.0:
        x = 1.0
    elif x < -1.0:
        x = -1.0
    return math.acos(x)


def slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    ratio: float,
) -> tuple[float, float, float, float]:
    """tf2's shortest-path spherical interpolation from a (ratio 0) to b (ratio 1).

    Source: ``tf2/LinearMath/Quaternion.h`` ``Quaternion::slerp`` and
    ``angleShortestPath``: half-angle ``θ = tf2Acos(|a·b| / sqrt(|a|²|b|²))`` (argument
    clamped to [-1, 1]); if ``a·b < 0``
    it interpolates towards ``-b``; if θ is exactly 0 it returns ``a`` unchanged.
    Quaternions are (x, y, z, w) and are not normalised.
    """
    dot = ax * bx + ay * by + az * bz + aw * bw
    s = math.sqrt((ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw))
    if dot < 0.0:
        theta = _acos(-dot / s)
        bx, by, bz, bw = -bx, -by, -bz, -bw
    else:
        theta = _acos(dot / s)
    if theta == 0.0:
        return (ax, ay, az, aw)
    d = 1.0 / math.sin(theta)
    s0 = math.sin((1.0 - ratio) * theta)
    s1 = math.sin(ratio * theta)
    return (
        (ax * s0 + bx * s1) * d,
        (ay * s0 + by * s1) * d,
        (az * s0 + bz * s1) * d,
        (aw * s0 + bw * s1) * d,
    )
