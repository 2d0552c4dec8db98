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
intensities, once: the cloud's bytes are made for every beam, written in one pass (one
loop per common layout, with no branch per field), then cut to the kept beams (a
scan's beams are usually all kept: nothing to cut). A scan shorter than
``NOGIL_BEAMS`` is projected holding the GIL (a microsecond's work: handing the GIL to
another thread and back would cost more).
"""

from cpython.bytes cimport PyBytes_AS_STRING, PyBytes_FromStringAndSize, _PyBytes_Resize
from cpython.object cimport PyObject
from cpython.ref cimport Py_DECREF, Py_INCREF
from libc.stdint cimport int32_t
from libc.stdlib cimport free, malloc
from libc.string cimport memcpy, memset

DEF F_INTENSITY = 0x01
DEF F_INDEX = 0x02
DEF F_DISTANCE = 0x04
DEF F_TIMESTAMP = 0x08
DEF F_VIEWPOINT = 0x10
DEF NOGIL_BEAMS = 16384  # scans at least this long are projected without the GIL


cdef inline bint _kept(float r, double range_cutoff, float range_min) noexcept nogil:
    """laser_geometry's test of a beam (false for NaN)."""
    return <double> r < range_cutoff and r >= range_min


cdef inline Py_ssize_t _fixed(const float* ranges, const float* intensities,
                              const double* cos, const double* sin, float* p, Py_ssize_t n,
                              double range_cutoff, float range_min, const bint intensity,
                              const bint index) noexcept nogil:
    """The kept beams as x y z [intensity] [index] points written to ``p``; returns how
    many. Called with constant flags, each call is compiled to its own loop with no
    branch per field."""
    cdef Py_ssize_t i, kept = 0
    cdef int fields = 3 + intensity + index
    cdef int32_t number
    cdef float r
    for i in range(n):
        r = ranges[i]
        if _kept(r, range_cutoff, range_min):
            p[0] = <float> (<double> r * cos[i])
            p[1] = <float> (<double> r * sin[i])
            p[2] = 0.0
            if intensity:
                p[3] = intensities[i]
            if index:
                number = <int32_t> i
                memcpy(&p[3 + intensity], &number, 4)
            p += fields
            kept += 1
    return kept


cdef Py_ssize_t _common(const float* ranges, const float* intensities, const double* cos,
                        const double* sin, float* p, Py_ssize_t n, int layout,
                        double range_cutoff, float range_min) noexcept nogil:
    """The kept beams of the common layouts (0: x y z; ``F_INDEX``: x y z index;
    ``F_INTENSITY | F_INDEX``, the default: x y z intensity index) written to ``p``;
    returns how many."""
    if layout == 0:
        return _fixed(ranges, intensities, cos, sin, p, n, range_cutoff, range_min, 0, 0)
    if layout == F_INDEX:
        return _fixed(ranges, intensities, cos, sin, p, n, range_cutoff, range_min, 0, 1)
    return _fixed(ranges, intensities, cos, sin, p, n, range_cutoff, range_min, 1, 1)


cdef Py_ssize_t _any(const float* ranges, const float* intensities, const double* cos,
                     const double* sin, char* out, Py_ssize_t n, int opts, int fields,
                     double range_cutoff, float range_min, float time_increment
                     ) noexcept nogil:
    """The kept beams of any layout written to ``out`` (``fields`` floats a point, in the
    order of laser_geometry's channels); returns how many."""
    cdef Py_ssize_t i, k, kept = 0
    cdef int32_t index
    cdef float r
    cdef float* p
    for i in range(n):
        r = ranges[i]
        if not _kept(r, range_cutoff, range_min):
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
        kept += 1
    return kept


cdef inline Py_ssize_t _points(const float* ranges, const float* intensities,
                               const double* cos, const double* sin, char* out,
                               Py_ssize_t n, int layout, int fields, double range_cutoff,
                               float range_min, float time_increment, bint common
                               ) noexcept nogil:
    """The kept beams written to ``out`` by :func:`_common` or :func:`_any`."""
    if common:
        return _common(ranges, intensities, cos, sin, <float*> out, n, layout,
                       range_cutoff, range_min)
    return _any(ranges, intensities, cos, sin, out, n, layout, fields, range_cutoff,
                range_min, time_increment)


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
        cdef Py_ssize_t kept
        if n != self._n:
            raise ValueError("the co-sine table is for another number of beams")
        if opts & F_INTENSITY and intensities.shape[0] < n:
            raise ValueError("fewer intensities than ranges")
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
        # Room for every beam, written in one pass, then cut to the kept ones (usually all).
        data = PyBytes_FromStringAndSize(NULL, n * fields * 4)
        cdef PyObject* raw = <PyObject*> data
        cdef char* out = PyBytes_AS_STRING(data)
        cdef int layout = opts & (F_INTENSITY | F_INDEX | F_DISTANCE | F_TIMESTAMP
                                  | F_VIEWPOINT)
        cdef const float* r = &ranges[0] if n else NULL
        cdef const float* intensity = (&intensities[0] if n and opts & F_INTENSITY
                                       else NULL)
        cdef bint common = layout == 0 or layout == F_INDEX or layout == F_INTENSITY | F_INDEX
        if n < NOGIL_BEAMS:  # a short scan: handing the GIL over costs more than it saves
            kept = _points(r, intensity, self._cos, self._sin, out, n, layout, fields,
                           range_cutoff, range_min, time_increment, common)
        else:
            with nogil:
                kept = _points(r, intensity, self._cos, self._sin, out, n, layout, fields,
                               range_cutoff, range_min, time_increment, common)
        if kept < n:
            Py_INCREF(data)  # _PyBytes_Resize needs the only reference: ``raw``'s
            data = None
            _PyBytes_Resize(&raw, kept * fields * 4)  # on failure: raw freed, raises
            data = <object> raw
            Py_DECREF(data)
        return data, kept
