# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
# Declarations of the compiled link storage (``_ccache.pyx``), shared with the walk
# (``_ccore``) and the batch kernel (``_cbatch``), which read the caches' C arrays.

from libc.stdint cimport int32_t, int64_t

cdef enum:
    C_OK = 0
    C_OLD_DATA = 1
    C_REPEATED_DATA = 2
    C_INVALID = 3  # CoreBase._insert_one: a tf2 rule is broken (INVALID below)
    # gather outcomes
    G_OK = 0
    G_EMPTY = 1  # no samples: tf2 gives an empty detail
    G_AT = 2  # a single sample, at another time
    G_FUTURE = 3
    G_PAST = 4
    # climb outcomes
    CLIMB_STOPPED = 0  # reached the stop frame, or a frame without a link
    CLIMB_EARLY = 1  # reached the other frame of the lookup
    CLIMB_FAILED = 2  # a link had no data at the time
    CLIMB_LOOP = 3  # longer than MAX_GRAPH_DEPTH
    C_MAX_DEPTH = 1000
    MIN_CAPACITY = 8
    GEOMETRIC_UP_TO = 256  # a link's capacity doubles below this many samples


cdef class Link:
    cdef int c_gather(self, int64_t time, double* out, int* parent) except -1
    cdef int c_pick(self, int64_t time, int mode, int64_t before, int64_t after, double* out,
                    int* parent, int64_t* used) except -1
    cdef int c_latest(self, int64_t* stamp) noexcept
    cdef int c_insert(self, int64_t stamp, int parent, const double* v) except -1
    cdef int64_t c_known(self, int code) noexcept


cdef class TimeCache(Link):
    cdef readonly int64_t cache_time_ns
    cdef readonly bint replace_repeated
    cdef int64_t* _st
    cdef double* _va
    cdef int32_t* _pa
    cdef Py_ssize_t _cap
    cdef Py_ssize_t _head
    cdef Py_ssize_t _tail
    cdef int _parent
    cdef int _resize(self, Py_ssize_t cap) except -1
    cdef int _alloc_parents(self, Py_ssize_t cap) except -1
    cdef int _make_room(self) except -1
    cdef int _replace_newest(self, int parent, const double* v) except -1


cdef class StaticCache(Link):
    cdef double _v[7]
    cdef int _parent
    cdef int64_t _stamp


cdef str _detail(int code, int64_t requested, int64_t known)


cdef inline object _link(list caches, int frame):
    """The link of ``frame``, or None; an id outside the table (only reachable by writing
    bogus parent ids into a cache by hand) counts as a frame without a link."""
    if frame < 0 or frame >= len(caches):
        return None
    return caches[frame]
