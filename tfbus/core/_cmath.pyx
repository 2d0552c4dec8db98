# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""tf2's scalar transform math and its per-point row kernels, compiled (the twin of
:mod:`tfbus.core._pymath`, same numbers bit for bit).

* ``quat_multiply``, ``quat_rotate``, ``compose``, ``inverse``, ``slerp``,
  ``compose_full``: tf2's ``Quaternion.h`` / ``Vector3.h`` / ``TransformAccum``
  expressions in tf2's evaluation order (the C bodies are in ``_cmath.pxd``, shared with
  the caches, the walk and the batch kernel); :mod:`tfbus.geometry` calls these.
* ``slerp_rows``, ``lerp_rows``, ``apply_transforms``: the same expressions over rows of
  numpy arrays (laser projection).
"""

__all__ = [
    "apply_transforms",
    "compose",
    "compose_full",
    "inverse",
    "lerp_rows",
    "quat_multiply",
    "quat_rotate",
    "slerp",
    "slerp_rows",
]

cimport cython

# The scalar transform arithmetic of tf2 (``tf2/LinearMath/Quaternion.h``,
# ``Vector3.h``; ``buffer_core.cpp`` ``TransformAccum``), once, in tf2's evaluation
# order; the walk, the caches and the Python callers (:mod:`tfbus.geometry`) all use it.
# Quaternions are (x, y, z, w) and never normalised: ``quat_rotate`` scales a vector by
# |q|² for a non-unit q, exactly as tf2.

def quat_multiply(double ax, double ay, double az, double aw,
                  double bx, double by, double bz, double bw):
    """Hamilton product ``a ⊗ b`` of two (x, y, z, w) quaternions, as ``(x, y, z, w)``
    (tf2 ``Quaternion.h`` ``operator*``)."""
    cdef double q[4]
    _qmul(ax, ay, az, aw, bx, by, bz, bw, q)
    return (q[0], q[1], q[2], q[3])


def quat_rotate(double qx, double qy, double qz, double qw,
                double vx, double vy, double vz):
    """Vector ``(vx, vy, vz)`` rotated by quaternion q as ``q ⊗ (v, 0) ⊗ conj(q)`` (tf2
    ``quatRotate``); scaled by ``|q|²`` for a non-unit q, exactly as tf2."""
    cdef double r[3]
    _qrot(qx, qy, qz, qw, vx, vy, vz, r)
    return (r[0], r[1], r[2])


@cython.boundscheck(True)  # a sequence shorter than 7 is an IndexError, not a crash
def compose(a, b):
    """``a ∘ b`` of two 7-tuples ``(tx, ty, tz, qx, qy, qz, qw)`` (metres; x, y, z, w):
    apply b, then a (tf2 ``TransformAccum::accum``).

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    cdef double x[7]
    cdef double y[7]
    cdef int k
    for k in range(7):
        x[k] = a[k]
        y[k] = b[k]
    _compose(x, y, y)
    return (y[0], y[1], y[2], y[3], y[4], y[5], y[6])


@cython.boundscheck(True)  # a sequence shorter than 7 is an IndexError, not a crash
def inverse(a):
    """tf2's inverse of a 7-tuple: rotation ``conj(q)``, translation ``quatRotate(conj(q),
    -t)`` (``TransformAccum::finalize``); exact for unit quaternions.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    cdef double r[3]
    _qrot(-a[3], -a[4], -a[5], a[6], -a[0], -a[1], -a[2], r)
    return (r[0], r[1], r[2], -a[3], -a[4], -a[5], a[6])


def slerp(double ax, double ay, double az, double aw, double bx, double by, double bz,
          double bw, double ratio):
    """tf2's shortest-path spherical interpolation from a (ratio 0) to b (ratio 1) of two
    (x, y, z, w) quaternions, not normalised (Quaternion.h ``slerp``)."""
    cdef double a[4]
    cdef double q[4]
    a[0] = ax
    a[1] = ay
    a[2] = az
    a[3] = aw
    _slerp(a, bx, by, bz, bw, ratio, q)
    return (q[0], q[1], q[2], q[3])


@cython.boundscheck(True)  # a sequence shorter than 7 is an IndexError, not a crash
def compose_full(leg2, leg1):
    """tf2's time-travel composition ``leg2 ∘ leg1`` of two 7-tuples
    (``lookupTransform`` with a fixed frame): both rotations are normalised first, as
    ``tf2::Transform`` keeps a normalised rotation matrix, and so is the result's.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    cdef double a[7]
    cdef double b[7]
    cdef double n
    cdef int k
    for k in range(7):
        a[k] = leg2[k]
        b[k] = leg1[k]
    n = sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
    for k in range(3, 7):
        a[k] = a[k] / n
    n = sqrt(b[3] * b[3] + b[4] * b[4] + b[5] * b[5] + b[6] * b[6])
    for k in range(3, 7):
        b[k] = b[k] / n
    _compose(a, b, b)
    n = sqrt(b[3] * b[3] + b[4] * b[4] + b[5] * b[5] + b[6] * b[6])
    return (b[0], b[1], b[2], b[3] / n, b[4] / n, b[5] / n, b[6] / n)


# ----- per-point tf2 math for sensor data (laser projection)


def slerp_rows(a, b, const double[::1] ratios, double[:, ::1] out):
    """tf2 ``Quaternion::slerp(a, b, r)`` for every r of ``ratios`` into ``out`` (N, 4)
    (x, y, z, w): the angle (``angleShortestPath``, ``tf2Acos``'s clamp) and ``1/sin``
    are computed once, each row as ``_slerp`` computes it (a zero angle returns ``a``;
    laser_geometry ``transformLaserScanToPointCloud_`` calls this per beam)."""
    cdef double qa[4]
    cdef double qb[4]
    cdef double dot, c, theta, d, s0, s1, r
    cdef Py_ssize_t i, n = ratios.shape[0]
    cdef int k
    if out.shape[0] != n or out.shape[1] != 4:
        raise ValueError("slerp_rows: out must be (N, 4) for N ratios")
    for k in range(4):
        qa[k] = a[k]
        qb[k] = b[k]
    dot = qa[0] * qb[0] + qa[1] * qb[1] + qa[2] * qb[2] + qa[3] * qb[3]
    if dot < 0.0:
        dot = -dot
        for k in range(4):
            qb[k] = -qb[k]
    c = dot / sqrt(
        (qa[0] * qa[0] + qa[1] * qa[1] + qa[2] * qa[2] + qa[3] * qa[3])
        * (qb[0] * qb[0] + qb[1] * qb[1] + qb[2] * qb[2] + qb[3] * qb[3])
    )
    with nogil:
        if c >= 1.0:
            for i in range(n):
                for k in range(4):
                    out[i, k] = qa[k]
        else:
            theta = acos(c)
            d = 1.0 / sin(theta)
            for i in range(n):
                r = ratios[i]
                s0 = sin((1.0 - r) * theta)
                s1 = sin(r * theta)
                for k in range(4):
                    out[i, k] = (qa[k] * s0 + qb[k] * s1) * d


def apply_transforms(const double[:, ::1] q, const double[:, ::1] v,
                     const double[:, ::1] p, double[:, ::1] out):
    """Point i mapped by the tf2::Transform with rotation ``q[i]`` (x, y, z, w) and origin
    ``v[i]`` (metres), as tf2 computes it: ``Matrix3x3::setRotation`` (its basis, which
    normalises q) then ``Transform::operator()`` (``p.dot3(row0, row1, row2) +
    origin``), in tf2's evaluation order. ``q`` (N, 4) or (1, 4), ``v`` (N, 3) or
    (1, 3), ``p`` and ``out`` (N, 3); a single row is used for every point."""
    cdef Py_ssize_t i, n = p.shape[0], iq, iv
    cdef bint one_q = q.shape[0] == 1, one_v = v.shape[0] == 1
    cdef double x, y, z, w, s, xs, ys, zs, wx, wy, wz, xx, xy, xz, yy, yz, zz
    cdef double m00, m01, m02, m10, m11, m12, m20, m21, m22, p0, p1, p2
    if (p.shape[1] != 3 or out.shape[0] != n or out.shape[1] != 3 or q.shape[1] != 4
            or v.shape[1] != 3 or not (one_q or q.shape[0] == n)
            or not (one_v or v.shape[0] == n)):
        raise ValueError("apply_transforms: q (N|1, 4), v (N|1, 3), p and out (N, 3)")
    with nogil:
        for i in range(n):
            iq = 0 if one_q else i
            iv = 0 if one_v else i
            x = q[iq, 0]
            y = q[iq, 1]
            z = q[iq, 2]
            w = q[iq, 3]
            s = 2.0 / (((x * x + y * y) + z * z) + w * w)
            xs = x * s
            ys = y * s
            zs = z * s
            wx = w * xs
            wy = w * ys
            wz = w * zs
            xx = x * xs
            xy = x * ys
            xz = x * zs
            yy = y * ys
            yz = y * zs
            zz = z * zs
            m00 = 1.0 - (yy + zz)
            m01 = xy - wz
            m02 = xz + wy
            m10 = xy + wz
            m11 = 1.0 - (xx + zz)
            m12 = yz - wx
            m20 = xz - wy
            m21 = yz + wx
            m22 = 1.0 - (xx + yy)
            p0 = p[i, 0]
            p1 = p[i, 1]
            p2 = p[i, 2]
            out[i, 0] = ((m00 * p0 + m01 * p1) + m02 * p2) + v[iv, 0]
            out[i, 1] = ((m10 * p0 + m11 * p1) + m12 * p2) + v[iv, 1]
            out[i, 2] = ((m20 * p0 + m21 * p1) + m22 * p2) + v[iv, 2]


def lerp_rows(a, b, const double[::1] ratios, double[:, ::1] out):
    """``(1 - r) * a + r * b`` per component for every r of ``ratios`` into ``out``
    (N, 3): tf2 ``lerp`` of two origins (metres), as laser_geometry interpolates the
    viewpoint between the first and last beam."""
    cdef double va[3]
    cdef double vb[3]
    cdef double r
    cdef Py_ssize_t i, n = ratios.shape[0]
    cdef int k
    if out.shape[0] != n or out.shape[1] != 3:
        raise ValueError("lerp_rows: out must be (N, 3) for N ratios")
    for k in range(3):
        va[k] = a[k]
        vb[k] = b[k]
    with nogil:
        for i in range(n):
            r = ratios[i]
            for k in range(3):
                out[i, k] = (1.0 - r) * va[k] + r * vb[k]
