"""The arithmetic of Debian's ``tf2_geometry_msgs`` (ROS 1), which goes through PyKDL:
operation for operation as orocos_kdl's ``frames.cpp`` / ``frames.inl`` does it, so
results are equal bit for bit (IEEE doubles, same order of operations).

* ``Rotation::Quaternion(x, y, z, w)``: the rotation matrix of a quaternion;
* ``Rotation * Rotation``, ``Rotation * Vector``, ``Frame * Frame``, ``Frame * Vector``;
* ``Rotation::GetQuaternion``: back to a quaternion (trace branch first, then the
  largest diagonal element), which picks the sign: (x=1, w=0)∘(x=1, w=0) gives w = +1.
"""

from __future__ import annotations

import math

__all__ = ["Frame", "Mat", "Vec", "frame_mul", "frame_vec", "get_quaternion", "rotation"]

Vec = tuple[float, float, float]
Mat = tuple[float, float, float, float, float, float, float, float, float]
Frame = tuple[Mat, Vec]


def rotation(x: float, y: float, z: float, w: float) -> Mat:
    """KDL ``Rotation::Quaternion(x, y, z, w)`` (row-major 3x3; not normalised)."""
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    return (w2 + x2 - y2 - z2, 2 * x * y - 2 * w * z, 2 * x * z + 2 * w * y,
            2 * x * y + 2 * w * z, w2 - x2 + y2 - z2, 2 * y * z - 2 * w * x,
            2 * x * z - 2 * w * y, 2 * y * z + 2 * w * x, w2 - x2 - y2 + z2)


def rot_vec(m: Mat, v: Vec) -> Vec:
    """KDL ``Rotation * Vector``."""
    return (m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
            m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
            m[6] * v[0] + m[7] * v[1] + m[8] * v[2])


def rot_mul(a: Mat, b: Mat) -> Mat:
    """KDL ``Rotation * Rotation``."""
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


def frame_vec(f: Frame, v: Vec) -> Vec:
    """KDL ``Frame * Vector``: ``M * v + p``."""
    r = rot_vec(f[0], v)
    p = f[1]
    return (r[0] + p[0], r[1] + p[1], r[2] + p[2])


def frame_mul(a: Frame, b: Frame) -> Frame:
    """KDL ``Frame * Frame``: ``(a.M * b.M, a.M * b.p + a.p)``."""
    return rot_mul(a[0], b[0]), frame_vec(a, b[1])


def get_quaternion(m: Mat) -> tuple[float, float, float, float]:
    """KDL ``Rotation::GetQuaternion`` → ``(x, y, z, w)``."""
    trace = m[0] + m[4] + m[8]
    if trace > 1e-12:
        s = 0.5 / math.sqrt(trace + 1.0)
        return ((m[7] - m[5]) * s, (m[2] - m[6]) * s, (m[3] - m[1]) * s, 0.25 / s)
    if m[0] > m[4] and m[0] > m[8]:
        s = 2.0 * math.sqrt(1.0 + m[0] - m[4] - m[8])
        return (0.25 * s, (m[1] + m[3]) / s, (m[2] + m[6]) / s, (m[7] - m[5]) / s)
    if m[4] > m[8]:
        s = 2.0 * math.sqrt(1.0 + m[4] - m[0] - m[8])
        return ((m[1] + m[3]) / s, 0.25 * s, (m[5] + m[7]) / s, (m[2] - m[6]) / s)
    s = 2.0 * math.sqrt(1.0 + m[8] - m[0] - m[4])
    return ((m[2] + m[6]) / s, (m[5] + m[7]) / s, 0.25 * s, (m[3] - m[1]) / s)
