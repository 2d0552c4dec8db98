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


cdef inline Py_ssize_t _search_left(const int64_t* a, int64_t x, Py_ssize_t lo,
                                    Py_ssize_t hi) noexcept nogil:
    """``_bisect_left(a, x, lo, hi)`` (the first index of ``a[lo:hi]``, sorted ascending,
    whose value is ``>= x``, else ``hi``), found from where ``x`` would lie were the
    values evenly spaced: interpolation search's first probe (Perl, Itai and Avni,
    "Interpolation search - a log log N search", CACM 21(7), 1978), then steps doubling
    away from it (Bentley and Yao, "An almost optimal algorithm for unbounded
    searching", IPL 5(3), 1976) until ``x`` is bracketed, then a bisection of the
    bracket. A link published at a steady rate has evenly spaced stamps: the first probe
    or its neighbour is the answer, where a bisection of 1 000 stamps takes ten
    dependent steps that the branch predictor cannot guess for a new time. Irregular
    stamps cost at most about twice a bisection."""
    cdef Py_ssize_t n = hi - lo, i, j, step, below, above
    cdef int64_t first, last
    if n < 8:
        return _bisect_left(a, x, lo, hi)
    first = a[lo]
    last = a[hi - 1]
    if x <= first:
        return lo
    if x > last:
        return hi
    # a[lo] < x <= a[hi - 1]: the answer k is in [lo + 1, hi - 1]
    i = lo + <Py_ssize_t>(<double>(x - first) / <double>(last - first) * <double>(n - 1))
    if i <= lo:
        i = lo + 1
    elif i > hi - 1:
        i = hi - 1
    if a[i] >= x:  # k <= i
        if a[i - 1] < x:
            return i
        above = i - 1  # a[above] >= x
        step = 2
        j = i - step
        while j > lo and a[j] >= x:
            above = j
            step <<= 1
            j = i - step
        below = j if j > lo else lo  # a[below] < x
        return _bisect_left(a, x, below + 1, above)
    # a[i] < x, so k > i (and i < hi - 1, since a[hi - 1] >= x)
    if a[i + 1] >= x:
        return i + 1
    below = i + 1  # a[below] < x
    step = 2
    j = i + step
    while j < hi - 1 and a[j] < x:
        below = j
        step <<= 1
        j = i + step
    above = j if j < hi - 1 else hi - 1  # a[above] >= x
    return _bisect_left(a, x, below + 1, above)


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
