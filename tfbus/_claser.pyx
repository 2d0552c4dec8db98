# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False
"""Compiled laser projection: laser_geometry's ``projectLaser_`` (PointCloud2 output) in
one pass, writing the cloud's bytes directly.

The same numbers as the numpy path of :mod:`tfbus.laser` bit for bit: each kept beam's
``x = (float)((double) range * cos)``, ``y`` likewise with ``sin`` (laser_geometry
``projectLaser_``: an ``Eigen::ArrayXXd`` of ranges times the cached co-sine map, stored
as float), ``z = 0``; kept when ``(double) range < range_cutoff`` and ``range >=
range_min`` (both false for NaN); ``index`` the beam number as int32 bits, ``distances``
the range, ``stamps`` ``(float) i * time_increment`` in float, ``vp_*`` zero. Built with
``-ffp-contract=off`` (setup.py): no fused multiply-add.

The co-sine table (``(N,) float64`` each, the caller's, computed once per scan geometry)
is copied into the projector when it changes; a call then reads only the ranges and the
intensities.
"""

from cpython.bytes cimport PyBytes_AS_STRING, PyBytes_FromStringAndSize
from libc.stdint cimport int32_t
from libc.stdlib cimport free, malloc
from libc.string cimport memcpy, memset

DEF F_INTENSITY = 0x01
DEF F_INDEX = 0x02
DEF F_DISTANCE = 0x04
DEF F_TIMESTAMP = 0x08
DEF F_VIEWPOINT = 0x10


cdef class Projector:
    """Holds a copy of one scan geometry's co-sine table and projects scans with it."""

    cdef double* _cos
    cdef double* _sin
    cdef Py_ssize_t _n
    cdef object _key

    def __cinit__(self):
        self._cos = NULL
        self._sin = NULL
        self._n = 0
        self._key = None

    def __dealloc__(self):
        free(self._cos)
        free(self._sin)

    def set_table(self, object key, const double[::1] cos, const double[::1] sin):
        """Copy the ``(N,) float64`` cos and sin tables of the geometry ``key``."""
        cdef Py_ssize_t n = cos.shape[0]
        if sin.shape[0] != n:
            raise ValueError("cos and sin tables differ in length")
        cdef double* c = <double*> malloc(max(n, 1) * sizeof(double))
        cdef double* s = <double*> malloc(max(n, 1) * sizeof(double))
        if c == NULL or s == NULL:
            free(c)
            free(s)
            raise MemoryError()
        if n:
            memcpy(c, &cos[0], n * sizeof(double))
            memcpy(s, &sin[0], n * sizeof(double))
        free(self._cos)
        free(self._sin)
        self._cos, self._sin, self._n, self._key = c, s, n, key

    @property
    def key(self):
        """The geometry whose table is held (``None`` before the first)."""
        return self._key

    def project(self, const float[::1] ranges, const float[::1] intensities, int opts,
                double range_cutoff, float range_min, float time_increment):
        """``(data, kept)``: the little-endian point bytes (``kept`` points of the layout
        ``opts`` selects, 4 bytes a field) and the number of kept beams.

        ``intensities`` is read only when ``opts`` has the intensity flag (then it must
        have at least as many values as ``ranges``: checked by the caller)."""
        cdef Py_ssize_t n = ranges.shape[0]
        cdef Py_ssize_t i, kept = 0, k
        cdef float r
        if n != self._n:
            raise ValueError("the co-sine table is for another number of beams")
        if opts & F_INTENSITY and intensities.shape[0] < n:
            raise ValueError("fewer intensities than ranges")
        for i in range(n):
            r = ranges[i]
            if <double> r < range_cutoff and r >= range_min:
                kept += 1
        cdef int fields = 3
        if opts & F_INTENSITY:
            fields += 1
        if opts & F_INDEX:
            fields += 1
        if opts & F_DISTANCE:
            fields += 1
        if opts & F_TIMESTAMP:
            fields += 1
        if opts & F_VIEWPOINT:
            fields += 3
        data = PyBytes_FromStringAndSize(NULL, kept * fields * 4)
        cdef char* out = PyBytes_AS_STRING(data)
        cdef float* p
        cdef int32_t index
        cdef double* cos = self._cos
        cdef double* sin = self._sin
        with nogil:
            for i in range(n):
                r = ranges[i]
                if not (<double> r < range_cutoff and r >= range_min):
                    continue
                p = <float*> out
                p[0] = <float> (<double> r * cos[i])
                p[1] = <float> (<double> r * sin[i])
                p[2] = 0.0
                k = 3
                if opts & F_INTENSITY:
                    p[k] = intensities[i]
                    k += 1
                if opts & F_INDEX:
                    index = <int32_t> i
                    memcpy(&p[k], &index, 4)
                    k += 1
                if opts & F_DISTANCE:
                    p[k] = r
                    k += 1
                if opts & F_TIMESTAMP:
                    p[k] = (<float> i) * time_increment
                    k += 1
                if opts & F_VIEWPOINT:
                    memset(&p[k], 0, 12)
                out += fields * 4
        return data, kept
