# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
# The scalar transform arithmetic of tf2 (``tf2/LinearMath/Quaternion.h``, ``Vector3.h``;
# ``buffer_core.cpp`` ``TransformAccum``), once, in tf2's evaluation order, as C inline
# functions: the caches (``_ccache``), the walk (``_ccore``), the batch kernel (``_cbatch``)
# and the Python entry points (``_cmath.pyx``) all compile these same bodies. Quaternions
# are (x, y, z, w) and never normalised: ``_qrot`` scales a vector by |q|² for a non-unit
# q, exactly as tf2.

from libc.math cimport acos, fabs, sin, sqrt
from libc.stdint cimport int64_t

cdef extern from *:
    """
    #define TFB_EXACT_SPAN (((long long)1) << 53)  /* int64 -> double is exact below this */
    """
    const int64_t EXACT_SPAN "TFB_EXACT_SPAN"


cdef inline Py_ssize_t _bisect_left(const int64_t* a, int64_t x, Py_ssize_t lo,
                                    Py_ssize_t hi) noexcept nogil:
    cdef Py_ssize_t mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


cdef inline void _qrot(double qx, double qy, double qz, double qw, double vx, double vy,
                       double vz, double* out) noexcept nogil:
    """tf2 ``quatRotate``: ``q ⊗ (v, 0) ⊗ conj(q)``, vector part, into out[0:3]."""
    cdef double tx = qw * vx + qy * vz - qz * vy
    cdef double ty = qw * vy + qz * vx - qx * vz
    cdef double tz = qw * vz + qx * vy - qy * vx
    cdef double tw = -qx * vx - qy * vy - qz * vz
    out[0] = -tw * qx + tx * qw - ty * qz + tz * qy
    out[1] = -tw * qy + ty * qw - tz * qx + tx * qz
    out[2] = -tw * qz + tz * qw - tx * qy + ty * qx


cdef inline void _qmul(double ax, double ay, double az, double aw, double bx, double by,
                       double bz, double bw, double* out) noexcept nogil:
    """Hamilton product ``a ⊗ b`` (Quaternion.h ``operator*``), into out[0:4]."""
    out[0] = aw * bx + ax * bw + ay * bz - az * by
    out[1] = aw * by + ay * bw + az * bx - ax * bz
    out[2] = aw * bz + az * bw + ax * by - ay * bx
    out[3] = aw * bw - ax * bx - ay * by - az * bz


cdef inline void _compose(const double* a, const double* b, double* out) noexcept nogil:
    """``a ∘ b`` (apply b, then a): ``t = quatRotate(qa, tb) + ta``, ``q = qa ⊗ qb``
    (``TransformAccum::accum``). ``out`` may alias ``b``."""
    cdef double r[3]
    cdef double q[4]
    _qrot(a[3], a[4], a[5], a[6], b[0], b[1], b[2], r)
    _qmul(a[3], a[4], a[5], a[6], b[3], b[4], b[5], b[6], q)
    out[0] = r[0] + a[0]
    out[1] = r[1] + a[1]
    out[2] = r[2] + a[2]
    out[3] = q[0]
    out[4] = q[1]
    out[5] = q[2]
    out[6] = q[3]


cdef inline void _slerp(const double* a, double bx, double by, double bz, double bw,
                        double r, double* out) noexcept nogil:
    """tf2's shortest-path slerp from a (r = 0) to b (r = 1) (Quaternion.h ``slerp`` /
    ``angleShortestPath``; ``tf2Acos`` clamps to [-1, 1], so a cosine that rounds to 1 or
    above is a zero angle, for which tf2 returns ``a`` unchanged). into out[0:4]."""
    cdef double dot = a[0] * bx + a[1] * by + a[2] * bz + a[3] * bw
    cdef double c, theta, d, s0, s1
    if dot < 0.0:
        dot = -dot
        bx = -bx
        by = -by
        bz = -bz
        bw = -bw
    c = dot / sqrt(
        (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3])
        * (bx * bx + by * by + bz * bz + bw * bw)
    )
    if c >= 1.0:
        out[0] = a[0]
        out[1] = a[1]
        out[2] = a[2]
        out[3] = a[3]
        return
    theta = acos(c)  # NaN only for NaN input, as in tf2
    d = 1.0 / sin(theta)
    s0 = sin((1.0 - r) * theta)
    s1 = sin(r * theta)
    out[0] = (a[0] * s0 + bx * s1) * d
    out[1] = (a[1] * s0 + by * s1) * d
    out[2] = (a[2] * s0 + bz * s1) * d
    out[3] = (a[3] * s0 + bw * s1) * d


cdef inline void _accumulate(double* acc, const double* st) noexcept nogil:
    """``acc = link ∘ acc`` (tf2 ``TransformAccum::accum``)."""
    _compose(st, acc, acc)


cdef inline void _identity(double* acc) noexcept nogil:
    acc[0] = acc[1] = acc[2] = acc[3] = acc[4] = acc[5] = 0.0
    acc[6] = 1.0
