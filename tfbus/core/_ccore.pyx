# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""Compiled heart of :class:`tfbus.core.BufferCore`: link storage, insert and the walk.

Semantics are tf2's (geometry2 0.7.6); every rule here is a transcription of the tf2 C++
named next to it, and the arithmetic is done in the same order as tf2, in IEEE doubles
with no fused multiply-add, so results are bit-for-bit tf2's (checked by the
conformance corpus, ``tests/core/test_conformance.py``).

* :class:`TimeCache` — a dynamic link (``tf2/src/cache.cpp``):

  - ``insert``: refused as TF_OLD_DATA iff ``newest > stamp + cache_time``; refused as
    TF_REPEATED_DATA if a sample with the same stamp exists (the first one wins, whatever
    its values or parent); otherwise stored, then every sample older than
    ``newest - cache_time`` is dropped (``TimeCache::insertData`` / ``pruneList``).
  - ``gather(t)``: t = 0 gives the newest sample; a single sample answers only at its
    exact stamp; otherwise t must lie in [oldest, newest] (no extrapolation, not even
    1 ns); between two samples with the same parent the result is interpolated (linear
    translation, tf2 slerp rotation, ratio from integer ns), between samples with
    different parents the older one is used (``findClosest`` / ``getData`` /
    ``interpolate``).
  - Storage: numpy arrays ``(cap,) int64`` stamps (ns) and ``(cap, 7) float64`` rows
    (tx, ty, tz, qx, qy, qz, qw), live samples sorted by stamp in ``[head, tail)``, plus
    a ``(cap,) int32`` parent id per sample only once the link has had two different
    parents: 64 bytes per sample, ~68 with the growth slack.

* :class:`StaticCache` — a static link (``tf2/src/static_cache.cpp``): one value, valid
  at every time; each insert overwrites it; its latest stamp is 0.

* :class:`CoreBase` — the frame table and the hot paths of ``BufferCore``: ``_store``
  (``BufferCore::setTransformImpl`` over a batch: returns counts, refusals, problems and
  the frames it touched) and ``_store_one`` (one transform: True, or what it refused
  and why), ``_query`` (``lookupTransform`` in one call: checks, memo,
  ``walkToTopParent`` with ``TransformAccum``, the TransformStamped built here; or a
  failure tuple), ``_chain`` (the frames an answer depends on), ``_cwalk`` and
  ``_ccommon_time`` (``getLatestCommonTime``). Nothing here calls into the Python
  subclass: error *messages* and log lines are built by ``tfbus.core`` from the codes
  returned here.

* ``_tf_from_ros1``: a ROS 1 serialised ``TFMessage`` into TransformStamped values, built
  in C like the lookups' results (``tfbus.bag.decode.decode_ros1`` uses it).

* The scalar transform math of tf2 (``quat_multiply``, ``quat_rotate``, ``compose``,
  ``inverse``, ``slerp``, ``compose_full``): one home, used by the caches, the walk and
  :mod:`tfbus.geometry`; ``tfbus/core/_pycore.py`` is its pure-Python twin (same numbers).
"""

import numpy as np

cimport cython
from libc.math cimport acos, fabs, sin, sqrt
from libc.stdint cimport INT64_MAX, int32_t, int64_t
from libc.string cimport memcpy, memmove
from cpython.float cimport PyFloat_FromDouble
from cpython.object cimport PyObject
from cpython.ref cimport Py_DECREF, Py_INCREF
from cpython.tuple cimport PyTuple_SET_ITEM
from cpython.unicode cimport PyUnicode_GET_LENGTH, PyUnicode_READ_CHAR

from tfbus.errors import InvalidArgumentException
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

# insert outcomes (tf2 cache insertData)
OK = 0
OLD_DATA = 1
REPEATED_DATA = 2

# outcomes of BufferCore._cwalk / _ccommon_time (tf2_msgs::TF2Error)
NO_ERROR = 0
LOOKUP_ERROR = 1
CONNECTIVITY_ERROR = 2
EXTRAPOLATION_ERROR = 3

MAX_GRAPH_DEPTH = 1000
"""Walks longer than this are taken to be loops (tf2 ``MAX_GRAPH_DEPTH``)."""

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

cdef int64_t EXACT_SPAN = 1LL << 53  # int64 -> double is exact below this


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


# ---------------------------------------------------------------------- messages


def format_sec(ns):
    """A stamp as tf2 prints it in error messages: ``%.09f`` of ``(double)sec + 1e-9*nsec``
    (``ros::Time::toSec``)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    return "%.09f" % (float(sec) + 1e-9 * float(nsec))


cdef str _detail(int code, int64_t requested, int64_t known):
    """tf2's extrapolation detail for a failed gather (cache.cpp
    createExtrapolationException1/2/3, with their snprintf buffer sizes)."""
    if code == G_AT:
        return (
            f"Lookup would require extrapolation at time {format_sec(requested)}, "
            f"but only time {format_sec(known)} is in the buffer"
        )[:115]
    if code == G_FUTURE:
        return (
            f"Lookup would require extrapolation {format_sec(requested - known)}s into the "
            f"future.  Requested time {format_sec(requested)} but the latest data is at "
            f"time {format_sec(known)}"
        )[:162]
    if code == G_PAST:
        return (
            f"Lookup would require extrapolation {format_sec(known - requested)}s into the "
            f"past.  Requested time {format_sec(requested)} but the earliest data is at "
            f"time {format_sec(known)}"
        )[:162]
    return ""


# ---------------------------------------------------------------------- links


cdef class Link:
    """Common base of :class:`TimeCache` and :class:`StaticCache` (tf2 ``TimeCacheInterface``)."""

    cdef int c_gather(self, int64_t time, double* out, int* parent) except -1:
        return G_EMPTY

    cdef int c_latest(self, int64_t* stamp) noexcept:
        stamp[0] = 0
        return 0

    cdef int c_insert(self, int64_t stamp, int parent, const double* v) except -1:
        return C_OK

    cdef int64_t c_known(self, int code) noexcept:
        return 0

    def gather(self, time):
        """The link's transform at ``time`` (ns; 0 = newest) as ``(parent id, values)``,
        ``values`` a 7-tuple (tx, ty, tz, qx, qy, qz, qw), or tf2's extrapolation detail
        string (possibly empty) when there is no data. A parent id of 0 (tf2's
        ``NO_PARENT``) is returned as is; callers treat it as a failure with an empty
        detail, like tf2's ``gather``."""
        cdef double v[7]
        cdef int parent = 0
        cdef int64_t t = time
        cdef int code = self.c_gather(t, v, &parent)
        if code != G_OK:
            return _detail(code, t, self.c_known(code))
        return parent, (v[0], v[1], v[2], v[3], v[4], v[5], v[6])

    def latest(self):
        """``(newest stamp ns, its parent id)``; ``(0, 0)`` when empty
        (``getLatestTimeAndParent``)."""
        cdef int64_t stamp = 0
        cdef int parent = self.c_latest(&stamp)
        return stamp, parent

    def insert(self, stamp, parent, values):
        """Store one sample (stamp ns, parent id, 7 floats); returns ``OK``, ``OLD_DATA``
        or ``REPEATED_DATA`` (tf2 ``insertData``)."""
        cdef double v[7]
        cdef int k
        if len(values) != 7:
            raise ValueError(f"expected 7 values, got {len(values)}")
        for k in range(7):
            v[k] = values[k]
        return self.c_insert(stamp, parent, v)


cdef class TimeCache(Link):
    """The time-indexed samples of one dynamic link (child frame → parent frame).

    Args:
        cache_time_ns: how far back from the newest sample data is kept, nanoseconds
            (values beyond int64 keep everything).
    """

    cdef readonly int64_t cache_time_ns
    cdef object _stamps_arr
    cdef object _values_arr
    cdef object _parents_arr
    cdef int64_t* _st
    cdef double* _va
    cdef int32_t* _pa
    cdef Py_ssize_t _cap
    cdef Py_ssize_t _head
    cdef Py_ssize_t _tail
    cdef int _parent

    def __cinit__(self, cache_time_ns):
        self.cache_time_ns = min(cache_time_ns, INT64_MAX)
        self._alloc(MIN_CAPACITY)
        self._head = 0
        self._tail = 0
        self._parent = 0
        self._parents_arr = None
        self._pa = NULL

    @property
    def is_static(self):
        """False: a dynamic link."""
        return False

    cdef int _alloc(self, Py_ssize_t cap) except -1:
        cdef int64_t[::1] s
        cdef double[:, ::1] v
        self._stamps_arr = np.empty(cap, dtype=np.int64)
        self._values_arr = np.empty((cap, 7), dtype=np.float64)
        s = self._stamps_arr
        v = self._values_arr
        self._st = &s[0]
        self._va = &v[0, 0]
        self._cap = cap
        return 0

    cdef int _alloc_parents(self, Py_ssize_t cap) except -1:
        cdef int32_t[::1] p
        self._parents_arr = np.full(cap, self._parent, dtype=np.int32)
        p = self._parents_arr
        self._pa = &p[0]
        return 0

    def __len__(self):
        return self._tail - self._head

    def nbytes(self):
        """Bytes held by this link's sample arrays (capacity, not just live samples)."""
        n = self._stamps_arr.nbytes + self._values_arr.nbytes
        return n + (self._parents_arr.nbytes if self._parents_arr is not None else 0)

    def stamps(self):
        """Stored stamps, oldest first, ``(N,) int64`` nanoseconds (a copy)."""
        return self._stamps_arr[self._head:self._tail].copy()

    def values(self):
        """Stored samples, oldest first, ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz,
        qw) (a copy)."""
        return self._values_arr[self._head:self._tail].copy()

    def latest_stamp(self):
        """Newest stamp in ns, 0 when empty (``getLatestTimestamp``)."""
        return self._st[self._tail - 1] if self._tail != self._head else 0

    def oldest_stamp(self):
        """Oldest stamp in ns, 0 when empty (``getOldestTimestamp``)."""
        return self._st[self._head] if self._tail != self._head else 0

    def clear(self):
        """Drop every sample (``clearList``); capacity is released."""
        self._alloc(MIN_CAPACITY)
        self._head = 0
        self._tail = 0
        self._parents_arr = None
        self._pa = NULL

    cdef int c_latest(self, int64_t* stamp) noexcept:
        cdef Py_ssize_t tail = self._tail
        if tail == self._head:
            stamp[0] = 0
            return 0
        stamp[0] = self._st[tail - 1]
        return self._parent if self._pa == NULL else self._pa[tail - 1]

    cdef int64_t c_known(self, int code) noexcept:
        # The stamp named by a gather failure: the newest one, or the oldest for G_PAST.
        if self._tail == self._head:
            return 0
        return self._st[self._head] if code == G_PAST else self._st[self._tail - 1]

    cdef int c_insert(self, int64_t stamp, int parent, const double* v) except -1:
        cdef Py_ssize_t head = self._head
        cdef Py_ssize_t tail = self._tail
        cdef Py_ssize_t pos, n
        cdef int64_t newest, horizon
        cdef int64_t* st = self._st
        if tail != head:
            newest = st[tail - 1]
            # newest > stamp + cache_time, without overflow (stamps are >= 0).
            if newest - self.cache_time_ns > stamp:
                return C_OLD_DATA
            if stamp > newest:
                pos = tail
            else:
                pos = _bisect_left(st, stamp, head, tail)
                if st[pos] == stamp:
                    return C_REPEATED_DATA
        else:
            pos = tail
        if parent != self._parent and self._pa == NULL:
            if tail == head:
                self._parent = parent
            else:
                self._alloc_parents(self._cap)
        if tail == self._cap:
            self._make_room()
            pos += self._head - head
            head = self._head
            tail = self._tail
        st = self._st
        if pos != tail:  # out-of-order insert: shift the newer samples up by one
            n = tail - pos
            memmove(&st[pos + 1], &st[pos], n * sizeof(int64_t))
            memmove(&self._va[(pos + 1) * 7], &self._va[pos * 7], n * 7 * sizeof(double))
            if self._pa != NULL:
                memmove(&self._pa[pos + 1], &self._pa[pos], n * sizeof(int32_t))
        st[pos] = stamp
        memcpy(&self._va[pos * 7], v, 7 * sizeof(double))
        if self._pa != NULL:
            self._pa[pos] = parent
        tail += 1
        self._tail = tail
        # pruneList: drop samples older than newest - cache_time (strict comparison).
        horizon = st[tail - 1] - self.cache_time_ns
        if st[head] < horizon:
            self._head = _bisect_left(st, horizon, head, tail)
        return C_OK

    cdef int _make_room(self) except -1:
        """Storage is full at the top: slide the live samples down if at least 1/16 of the
        capacity is free below them, else grow by 1/16 (amortised O(1) inserts; a steady
        stream settles at ~7 % slack, i.e. ~68 bytes per sample)."""
        cdef Py_ssize_t head = self._head, tail = self._tail, cap = self._cap
        cdef Py_ssize_t n = tail - head, new_cap
        cdef int64_t* old_st
        cdef double* old_va
        cdef int32_t* old_pa
        cdef object keep_s, keep_v, keep_p
        if head >= cap // 16 and head > 0:
            memmove(self._st, &self._st[head], n * sizeof(int64_t))
            memmove(self._va, &self._va[head * 7], n * 7 * sizeof(double))
            if self._pa != NULL:
                memmove(self._pa, &self._pa[head], n * sizeof(int32_t))
        else:
            new_cap = max(MIN_CAPACITY, n + max(n // 16, 4))
            keep_s, keep_v, keep_p = self._stamps_arr, self._values_arr, self._parents_arr
            old_st, old_va, old_pa = self._st, self._va, self._pa
            self._alloc(new_cap)
            memcpy(self._st, &old_st[head], n * sizeof(int64_t))
            memcpy(self._va, &old_va[head * 7], n * 7 * sizeof(double))
            if old_pa != NULL:
                self._alloc_parents(new_cap)
                memcpy(self._pa, &old_pa[head], n * sizeof(int32_t))
            del keep_s, keep_v, keep_p
        self._head = 0
        self._tail = n
        return 0

    cdef int c_gather(self, int64_t time, double* out, int* parent) except -1:
        cdef Py_ssize_t head = self._head, tail = self._tail, i, i0
        cdef const int64_t* st = self._st
        cdef const double* a
        cdef const double* b
        cdef int64_t newest, t0, span
        cdef int p0
        cdef double r, s
        if tail == head:
            return G_EMPTY
        if time == 0:
            i = tail - 1
        else:
            newest = st[tail - 1]
            if time == newest:
                i = tail - 1
            elif tail - head == 1:
                return G_AT
            elif time > newest:
                return G_FUTURE
            else:
                i = _bisect_left(st, time, head, tail)
                if st[i] != time:
                    if i == head:
                        return G_PAST
                    # Between samples i-1 (older) and i (newer).
                    i0 = i - 1
                    p0 = self._parent if self._pa == NULL else self._pa[i0]
                    parent[0] = p0
                    a = &self._va[i0 * 7]
                    if self._pa != NULL and self._pa[i] != p0:
                        memcpy(out, a, 7 * sizeof(double))
                        return G_OK
                    b = &self._va[i * 7]
                    # TimeCache::interpolate; the ratio is correctly rounded from integer
                    # ns (tf2 divides double seconds; the two differ by < 1e-15 relative).
                    t0 = st[i0]
                    span = st[i] - t0
                    if span < EXACT_SPAN:
                        r = <double>(time - t0) / <double>span
                    else:  # Python's int true division is correctly rounded at any size
                        r = (<object>(time - t0)) / (<object>span)
                    s = 1.0 - r
                    out[0] = s * a[0] + r * b[0]
                    out[1] = s * a[1] + r * b[1]
                    out[2] = s * a[2] + r * b[2]
                    _slerp(&a[3], b[3], b[4], b[5], b[6], r, &out[3])
                    return G_OK
        parent[0] = self._parent if self._pa == NULL else self._pa[i]
        memcpy(out, &self._va[i * 7], 7 * sizeof(double))
        return G_OK


cdef class StaticCache(Link):
    """The single value of a static link, valid at every time (``tf2::StaticCache``).

    ``insert`` always overwrites (last wins, stamp ignored); ``latest()`` reports stamp 0,
    so static links never limit tf2's latest common time; ``clear()`` keeps the value.
    """

    cdef double _v[7]
    cdef int _parent
    cdef int64_t _stamp

    def __cinit__(self):
        self._v[:] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        self._parent = 0
        self._stamp = 0

    @property
    def is_static(self):
        """True: a static link."""
        return True

    @property
    def cache_time_ns(self):
        """0: a static link keeps no history."""
        return 0

    def __len__(self):
        return 1

    def nbytes(self):
        """Bytes of sample storage (one row of 7 doubles)."""
        return 7 * 8

    def latest_stamp(self):
        """Always 0 (``StaticCache::getLatestTimestamp``)."""
        return 0

    def oldest_stamp(self):
        """Always 0 (``StaticCache::getOldestTimestamp``)."""
        return 0

    def stamp_sent(self):
        """Stamp (ns) of the last message that set this static value (informational)."""
        return self._stamp

    def clear(self):
        """No-op: ``BufferCore.clear()`` keeps static transforms, as in tf2."""

    cdef int c_latest(self, int64_t* stamp) noexcept:
        stamp[0] = 0
        return self._parent

    cdef int c_insert(self, int64_t stamp, int parent, const double* v) except -1:
        self._parent = parent
        memcpy(self._v, v, 7 * sizeof(double))
        self._stamp = stamp
        return C_OK

    cdef int c_gather(self, int64_t time, double* out, int* parent) except -1:
        parent[0] = self._parent
        memcpy(out, self._v, 7 * sizeof(double))
        return G_OK


# ---------------------------------------------------------------------- the core


cdef inline void _accumulate(double* acc, const double* st) noexcept nogil:
    """``acc = link ∘ acc`` (tf2 ``TransformAccum::accum``)."""
    _compose(st, acc, acc)


cdef inline void _identity(double* acc) noexcept nogil:
    acc[0] = acc[1] = acc[2] = acc[3] = acc[4] = acc[5] = 0.0
    acc[6] = 1.0


cdef inline object _link(list caches, int frame):
    """The link of ``frame``, or None; an id outside the table (only reachable by writing
    bogus parent ids into a cache by hand) counts as a frame without a link."""
    if frame < 0 or frame >= len(caches):
        return None
    return caches[frame]


cdef int _climb(list caches, int frame, int stop, int early, int64_t time, double* acc,
                int* reached) except -1:
    """One half of tf2's ``walkToTopParent``: walk up from ``frame`` gathering each link
    at ``time`` and accumulating ``frame -> current`` into ``acc``.

    Stops at ``stop`` (not gathered), at a frame without a link, at a link with no data
    (CLIMB_FAILED, ``reached`` = the failing frame), or at ``early`` once its link
    gathered (CLIMB_EARLY; that link is not accumulated). ``reached`` is the frame where
    the climb ended.
    """
    cdef double st[7]
    cdef int parent = 0
    cdef int depth = 0
    cdef bint first = True
    cdef object obj
    _identity(acc)
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        if (<Link>obj).c_gather(time, st, &parent) != G_OK or parent == 0:
            reached[0] = frame
            return CLIMB_FAILED
        if frame == early:
            reached[0] = frame
            return CLIMB_EARLY
        if first:
            memcpy(acc, st, 7 * sizeof(double))
            first = False
        else:
            _accumulate(acc, st)
        frame = parent
        depth += 1
        if depth > C_MAX_DEPTH:
            reached[0] = frame
            return CLIMB_LOOP
    reached[0] = frame
    return CLIMB_STOPPED


# ---------------------------------------------------------------------- scalar math

# The scalar transform arithmetic of tf2 (``tf2/LinearMath/Quaternion.h``,
# ``Vector3.h``; ``buffer_core.cpp`` ``TransformAccum``), once, in tf2's evaluation
# order; the walk, the caches and the Python callers (:mod:`tfbus.geometry`) all use it.
# Quaternions are (x, y, z, w) and never normalised: ``quat_rotate`` scales a vector by
# |q|² for a non-unit q, exactly as tf2.

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


# ---------------------------------------------------------------------- results

cdef extern from "Python.h":
    ctypedef PyObject* (*allocfunc)(PyTypeObject* tp, Py_ssize_t n) except NULL
    ctypedef struct PyTypeObject:
        allocfunc tp_alloc
    PyObject* PyType_GenericAlloc(PyTypeObject* tp, Py_ssize_t n) except NULL
    int PyObject_GenericSetAttr(object o, object name, object value) except -1
    void PyObject_GC_UnTrack(void* op)


cdef inline object _named(object cls, object a, object b):
    """``tuple.__new__(cls, (a, b))`` for a NamedTuple class, without its Python-level
    ``__new__`` (what ``tuple_subtype_new`` does, minus the argument tuple)."""
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 2)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    Py_INCREF(b)
    PyTuple_SET_ITEM(obj, 0, a)
    PyTuple_SET_ITEM(obj, 1, b)
    return obj


cdef inline object _named3(object cls, object a, object b, object c):
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 3)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    Py_INCREF(b)
    Py_INCREF(c)
    PyTuple_SET_ITEM(obj, 0, a)
    PyTuple_SET_ITEM(obj, 1, b)
    PyTuple_SET_ITEM(obj, 2, c)
    return obj


cdef inline object _named4(object cls, double a, double b, double c, double d):
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 4)
    PyObject_GC_UnTrack(p)  # four floats: it can never be part of a reference cycle
    cdef object obj = <object>p
    cdef object fa = PyFloat_FromDouble(a)
    cdef object fb = PyFloat_FromDouble(b)
    cdef object fc = PyFloat_FromDouble(c)
    cdef object fd = PyFloat_FromDouble(d)
    Py_DECREF(obj)
    Py_INCREF(fa)
    Py_INCREF(fb)
    Py_INCREF(fc)
    Py_INCREF(fd)
    PyTuple_SET_ITEM(obj, 0, fa)
    PyTuple_SET_ITEM(obj, 1, fb)
    PyTuple_SET_ITEM(obj, 2, fc)
    PyTuple_SET_ITEM(obj, 3, fd)
    return obj


cdef object _stamped(object stamp, str target, str source, const double* v):
    """The lookup result: ``TransformStamped(Header(stamp, target), source,
    Transform(Vector3(v[0:3]), Quaternion(v[3:7])))``, built in C."""
    cdef object vec = _named3(Vector3, PyFloat_FromDouble(v[0]), PyFloat_FromDouble(v[1]),
                              PyFloat_FromDouble(v[2]))
    PyObject_GC_UnTrack(<PyObject*>vec)  # three floats: never part of a reference cycle
    cdef object rot = _named4(Quaternion, v[3], v[4], v[5], v[6])
    return _named3(
        TransformStamped, _named(Header, stamp, target), source, _named(Transform, vec, rot)
    )


cdef object _time_of(int64_t ns):
    """``Time.from_ns(ns)`` for a valid ns, without re-validating it: the instance from
    the type's ``tp_alloc`` (what ``object.__new__`` does, minus looking up and calling
    it), its ``_ns`` slot set through the generic setattr (the slot's descriptor)."""
    cdef PyObject* p = (<PyTypeObject*>Time).tp_alloc(<PyTypeObject*>Time, 0)
    cdef object t = <object>p
    Py_DECREF(t)  # tp_alloc's reference, now owned by ``t``
    PyObject_GenericSetAttr(t, "_ns", ns)
    return t


# ---------------------------------------------------------------------- ROS 1 wire

from struct import error as _StructError

from cpython.list cimport PyList_New, PyList_SET_ITEM
from cpython.unicode cimport PyUnicode_DecodeUTF8
from libc.stdint cimport uint32_t
from libc.string cimport memcmp


cdef extern from "Python.h":
    int PyUnicode_IS_ASCII(object o)
    void* PyUnicode_DATA(object o)


# Frame ids by their position in a message: a publisher sends the same ids message
# after message, so an id whose bytes equal the ASCII str decoded last time at the same
# position is that (immutable) str again, not a new one. Compared byte for byte on
# every use; a different id replaces it. Positions past _ROS1_ID_SLOTS are decoded.
DEF _ROS1_ID_SLOTS = 4096
cdef list _ros1_children = [None] * _ROS1_ID_SLOTS
cdef list _ros1_frames = [None] * _ROS1_ID_SLOTS


cdef inline object _ros1_id(list cache, Py_ssize_t k, const unsigned char* s, uint32_t n):
    """The str of the UTF-8 bytes ``s[:n]``: the one cached at ``k`` if equal."""
    cdef object cached
    if k < _ROS1_ID_SLOTS:
        cached = cache[k]
        if (cached is not None and <uint32_t>PyUnicode_GET_LENGTH(cached) == n
                and memcmp(PyUnicode_DATA(cached), s, n) == 0):
            return cached
    cdef object text = PyUnicode_DecodeUTF8(<const char*>s, n, NULL)
    if k < _ROS1_ID_SLOTS and PyUnicode_IS_ASCII(text):
        cache[k] = text
    return text


cdef inline uint32_t _u32le(const unsigned char* p) noexcept:
    return <uint32_t>p[0] | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef enum:
    _ROS1_TF_MIN = 76  # bytes of a transform with empty ids: 4 u32 + 2 u32 + 7 float64


def _tf_from_ros1(const unsigned char[::1] buf):
    """The transforms of a ROS 1 serialised ``tf2_msgs/TFMessage`` (``u32 count``, then
    per transform ``u32 seq, u32 sec, u32 nsec, u32 len, frame_id, u32 len,
    child_frame_id, 7 float64``, little endian), built in C: what
    ``tfbus.bag.decode.decode_ros1``'s struct decoder returns, equal values (frame ids
    decoded as strict UTF-8; a transform whose serialised header is byte for byte the
    previous one's shares its Header; an ASCII frame id equal to the one at the same
    position of an earlier message is that message's str, not a new one; bytes after
    the last transform are ignored).
    Little-endian hosts only (the doubles are read in host order).

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    cdef Py_ssize_t size = buf.shape[0], off = 4, head, hlen = 0, prev = -1, k
    cdef const unsigned char* p
    cdef uint32_t n, flen, clen, sec, nsec
    cdef double v[7]
    cdef object header = None, child, vec, rot, tf, ts
    cdef list out
    if size < 4:
        raise _StructError("message shorter than its contents")
    p = &buf[0]
    n = _u32le(p)
    if n > (size - 4) // _ROS1_TF_MIN:
        raise _StructError("message shorter than its contents")
    out = PyList_New(n)
    for k in range(n):
        # The list owns a reference to None in each slot until it is set (PyList_New
        # leaves NULLs, which a failure below must not expose).
        Py_INCREF(None)
        PyList_SET_ITEM(out, k, None)
    for k in range(n):
        head = off
        if off + 16 > size:
            raise _StructError("message shorter than its contents")
        flen = _u32le(p + off + 12)
        if flen > size - off - 16:
            raise _StructError("message shorter than its contents")
        off += 16 + flen
        if not (prev >= 0 and hlen == off - head and memcmp(p + prev, p + head, hlen) == 0):
            sec = _u32le(p + head + 4)
            nsec = _u32le(p + head + 8)
            header = _named(
                Header,
                _time_of(<int64_t>sec * 1000000000 + nsec),
                _ros1_id(_ros1_frames, k, p + head + 16, flen),
            )
            prev = head
            hlen = off - head
        if off + 4 > size:
            raise _StructError("message shorter than its contents")
        clen = _u32le(p + off)
        if clen > size - off - 4 or size - off - 4 - clen < 56:
            raise _StructError("message shorter than its contents")
        child = _ros1_id(_ros1_children, k, p + off + 4, clen)
        off += 4 + clen
        memcpy(v, p + off, 7 * sizeof(double))
        off += 56
        vec = _named3(Vector3, PyFloat_FromDouble(v[0]), PyFloat_FromDouble(v[1]),
                      PyFloat_FromDouble(v[2]))
        PyObject_GC_UnTrack(<PyObject*>vec)  # three floats: never part of a cycle
        rot = _named4(Quaternion, v[3], v[4], v[5], v[6])
        tf = _named(Transform, vec, rot)
        PyObject_GC_UnTrack(<PyObject*>tf)  # two untracked tuples: never part of a cycle
        ts = _named3(TransformStamped, header, child, tf)
        out[k] = ts
    return out


# Validation outcomes of an inserted transform (beyond the cache's OK / OLD / REPEATED).
INVALID = 3
"""``CoreBase._store``: the transform breaks one of tf2's rules (setTransformImpl)."""

# Query failures beyond tf2's codes: a bad argument (empty or '/'-prefixed id).
INVALID_ARGUMENT = 4
UNKNOWN_FRAME = 5


cdef inline str _as_str(object value):
    """A frame id as the exact ``str`` it is (``numpy.str_`` or any ``str`` subclass is
    accepted as its string value); None for anything that is not a string."""
    if type(value) is str:
        return <str>value
    if isinstance(value, str):
        return str.__str__(value)
    return None


cdef inline bint _slashed(str frame_id) noexcept:
    """Whether ``frame_id`` starts with '/' (tf2 ``stripSlash`` strips one)."""
    return PyUnicode_GET_LENGTH(frame_id) != 0 and PyUnicode_READ_CHAR(frame_id, 0) == 47


cdef str _show(object value):
    """``repr`` of a bad value for an error message, bounded in length."""
    cdef str text
    try:
        text = repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 80 else text[:77] + "..."


cdef inline double _number(object value, str field) except? -1.0:
    """A transform component as a double; anything but a real number (bool, None, str,
    an int beyond double range, ...) is an InvalidArgumentException naming the field."""
    if type(value) is float:
        return <double>value
    if not isinstance(value, (bool, np.bool_, str, bytes, complex)) and value is not None:
        try:
            return float(value)
        except (OverflowError, TypeError, ValueError):
            pass
    raise InvalidArgumentException(f"{field} must be a real number, got {_show(value)}")


cdef tuple _FIELDS = (
    "transform.translation.x",
    "transform.translation.y",
    "transform.translation.z",
    "transform.rotation.x",
    "transform.rotation.y",
    "transform.rotation.z",
    "transform.rotation.w",
)


cdef tuple _bad_id(str frame_id, int which):
    """The failure tuple of a query argument that is not a known frame (tf2
    ``validateFrameId``): empty or '/'-prefixed ids are invalid, others unknown."""
    if not frame_id or frame_id[0] == "/":
        return (INVALID_ARGUMENT, which)
    return (UNKNOWN_FRAME, which)


cdef enum:
    # Slots of the lookup memo (a power of two). Small: a memo holds results alive.
    MEMO_SIZE = 64


cdef class CoreBase:
    """Frame table and hot paths of :class:`tfbus.core.BufferCore` (which subclasses it).

    Nothing here calls into the subclass: inserts and queries return codes and data, and
    ``tfbus.core`` turns them into tf2's messages, exceptions and log lines.

    Read-only internals (for white-box tests and the batch kernel, never written from
    Python): ``_frame_ids`` (frame id → int id; 0 is tf2's ``NO_PARENT``), ``_frame_names``
    (int id → frame id), ``_caches`` (int id → link or None), ``_authority`` (int id →
    authority of its last stored transform) and ``_generation`` (bumped by every insert
    attempt and by ``clear``). Python code uses the public methods: ``clear``,
    ``get_frame_names``, ``frame_exists``, ``parent_of``, ``link_info``,
    ``extrapolation_detail``, ``common_time``.
    """

    cdef readonly dict _frame_ids
    cdef readonly list _frame_names
    cdef readonly list _caches
    cdef readonly dict _authority
    cdef readonly long long _generation
    cdef int64_t _cache_ns
    # The lookup memo, direct-mapped: slot -> the last result stored there, the time
    # asked and the generation it is valid for (no key tuple, no dict: a never-repeated
    # query pays a few compares and one list store).
    cdef list _memo
    cdef int64_t _memo_t[MEMO_SIZE]
    cdef long long _memo_gen[MEMO_SIZE]
    # What the last ``_insert_one`` did, beyond its code (read by ``_store`` and
    # ``_store_one`` right after it; no list per transform): the stripped ids, the stamp,
    # the values (for INVALID only) and whether the tree's shape may have changed.
    cdef str _last_parent
    cdef str _last_child
    cdef int64_t _last_stamp
    cdef object _last_values
    cdef bint _last_relinked

    def __cinit__(self, *args, **kwargs):
        cdef int k
        self._frame_ids = {"NO_PARENT": 0}
        self._frame_names = ["NO_PARENT"]
        self._caches = [None]
        self._authority = {}
        self._generation = 0
        self._cache_ns = 0
        self._memo = [None] * MEMO_SIZE
        for k in range(MEMO_SIZE):
            self._memo_gen[k] = -1
            self._memo_t[k] = 0

    @property
    def cache_time_ns(self):
        """The history kept per dynamic link, nanoseconds (the one copy: every link is
        created with it; read-only)."""
        return self._cache_ns

    def _set_cache_time_ns(self, ns):
        """Set the cache time (ns); only before the first insert (``BufferCore.__init__``)."""
        if len(self._frame_names) > 1:
            raise RuntimeError("cache_time is fixed once transforms are stored")
        self._cache_ns = min(ns, INT64_MAX)

    cdef object _register(self, str frame_id):
        cdef object fid = len(self._frame_names)
        self._frame_ids[frame_id] = fid
        self._frame_names.append(frame_id)
        self._caches.append(None)
        return fid

    # ------------------------------------------------------------------ insert

    cdef int _insert_one(self, object ts, str authority, bint is_static) except -1:
        """``BufferCore::setTransformImpl``: check, register frames, store.

        Returns the cache's C_OK / C_OLD_DATA / C_REPEATED_DATA, or INVALID (a tf2 rule
        is broken). What it did beyond the code is left in ``_last_parent``,
        ``_last_child`` (stripped ids), ``_last_stamp`` (ns; not for INVALID),
        ``_last_values`` (the 7 values, INVALID only) and ``_last_relinked``. A field of
        the wrong type raises InvalidArgumentException naming it; nothing is stored or
        registered before every check has passed (no half-stored frame)."""
        cdef object header, tf, tr, rot, stamp_obj, cid, pid, cache
        cdef str child, parent
        cdef double v[7]
        cdef double norm2
        cdef int64_t stamp, old_stamp
        cdef int code, k, old_parent
        header = (<tuple>ts)[0]
        tf = (<tuple>ts)[2]
        if not isinstance(header, Header):
            raise InvalidArgumentException(f"header must be a Header, got {_show(header)}")
        if not isinstance(tf, Transform):
            raise InvalidArgumentException(f"transform must be a Transform, got {_show(tf)}")
        tr = (<tuple>tf)[0]
        rot = (<tuple>tf)[1]
        if not (isinstance(tr, tuple) and len(<tuple>tr) == 3):
            raise InvalidArgumentException(
                f"transform.translation must be a Vector3, got {_show(tr)}")
        if not (isinstance(rot, tuple) and len(<tuple>rot) == 4):
            raise InvalidArgumentException(
                f"transform.rotation must be a Quaternion, got {_show(rot)}")
        parent = _as_str((<tuple>header)[1])
        if parent is None:
            raise InvalidArgumentException(
                f"header.frame_id must be a str, got {_show((<tuple>header)[1])}")
        child = _as_str((<tuple>ts)[1])
        if child is None:
            raise InvalidArgumentException(
                f"child_frame_id must be a str, got {_show((<tuple>ts)[1])}")
        stamp_obj = (<tuple>header)[0]
        if not isinstance(stamp_obj, Time):
            raise InvalidArgumentException(f"header.stamp must be a Time, got {_show(stamp_obj)}")
        for k in range(3):
            v[k] = _number((<tuple>tr)[k], _FIELDS[k])
        for k in range(4):
            v[3 + k] = _number((<tuple>rot)[k], _FIELDS[3 + k])
        if _slashed(parent):
            parent = parent[1:]
        if _slashed(child):
            child = child[1:]
        self._last_parent = parent
        self._last_child = child
        # tf2's order (setTransformImpl: w² + x² + y² + z²): it decides cases at the limit.
        norm2 = v[6] * v[6] + v[3] * v[3] + v[4] * v[4] + v[5] * v[5]
        # `v - v == 0` fails for NaN and ±Inf alike; the norm test fails for NaN too.
        if (
            child == parent
            or not child
            or not parent
            or v[0] - v[0] != 0.0
            or v[1] - v[1] != 0.0
            or v[2] - v[2] != 0.0
            or not fabs(norm2 - 1.0) < 0.01
        ):
            self._last_values = (v[0], v[1], v[2], v[3], v[4], v[5], v[6])
            return C_INVALID
        stamp = stamp_obj._ns
        self._last_stamp = stamp
        self._generation += 1
        cid = self._frame_ids.get(child)
        if cid is None:
            cid = self._register(child)
        cache = self._caches[cid]
        if cache is None:
            cache = StaticCache() if is_static else TimeCache(self._cache_ns)
            self._caches[cid] = cache
        pid = self._frame_ids.get(parent)
        if pid is None:
            pid = self._register(parent)
        old_parent = (<Link>cache).c_latest(&old_stamp)
        code = (<Link>cache).c_insert(stamp, pid, v)
        # The tree's shape may have changed: a new or emptied link, another parent, or a
        # link that keeps one parent per sample.
        self._last_relinked = False
        if code == C_OK:
            if old_parent != <int>pid:
                self._last_relinked = True
            elif isinstance(cache, TimeCache) and (<TimeCache>cache)._pa != NULL:
                self._last_relinked = True
            self._authority[cid] = authority
        return code

    def _store(self, transforms, str authority, bint is_static):
        """Store every :class:`~tfbus.messages.TransformStamped` of ``transforms``, in
        order; one bad item never stops the others. Calls nothing back.

        Returns ``(stored, refused, errors, touched, relinked, refusals)`` (the first
        five are ``BatchResult``'s fields):

        * ``stored``: how many were stored; ``refused``: how many were refused;
        * ``refusals``: ``[(code, child, stamp ns)]`` for each refused by its cache
          (``OLD_DATA`` / ``REPEATED_DATA``);
        * ``errors``: ``[(index, problem)]``, ``problem`` either an exception
          (InvalidArgumentException for a field of the wrong type, TypeError for an item
          that is not a TransformStamped) or ``(parent, child, values)`` for a transform
          that breaks a tf2 rule (the caller builds tf2's message);
        * ``touched``: set of the (stripped) child and parent ids of every stored transform;
        * ``relinked``: whether a stored transform may have changed the tree's shape.
        """
        cdef Py_ssize_t stored = 0, i = 0
        cdef list refusals = []
        cdef list errors = []
        cdef set touched = set()
        cdef bint relinked = False
        cdef int code
        for ts in transforms:
            try:
                if not isinstance(ts, TransformStamped):
                    raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                code = self._insert_one(ts, authority, is_static)
            except Exception as exc:
                errors.append((i, exc))
            else:
                if code == C_OK:
                    stored += 1
                    touched.add(self._last_child)
                    touched.add(self._last_parent)
                    if self._last_relinked:
                        relinked = True
                elif code == C_INVALID:
                    errors.append((i, (self._last_parent, self._last_child, self._last_values)))
                else:
                    refusals.append((code, self._last_child, self._last_stamp))
            i += 1
        return stored, len(refusals), errors, touched, relinked, refusals

    def _store_one(self, ts, str authority, bint is_static):
        """One transform, as ``_store`` would store it (``BufferCore.set_transform``'s
        path: no list, set or tuple on success). Calls nothing back.

        Returns True when stored; else what ``_store`` reports for it: ``(OLD_DATA |
        REPEATED_DATA, child, stamp ns)`` for a refusal by the cache, ``(INVALID, parent,
        child, values)`` for a transform that breaks a tf2 rule.

        Raises:
            TypeError: ``ts`` is not a TransformStamped.
            InvalidArgumentException: a field of the wrong type (named).
        """
        cdef int code
        if not isinstance(ts, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
        code = self._insert_one(ts, authority, is_static)
        if code == C_OK:
            return True
        if code == C_INVALID:
            return (INVALID, self._last_parent, self._last_child, self._last_values)
        return (code, self._last_child, self._last_stamp)

    def _last_touched(self):
        """``(child, parent, relinked)`` of the transform ``_store_one`` last stored: the
        (stripped) ids whose lookups may have changed and whether the tree's shape may
        have (what ``_store`` reports per batch); read by ``tfbus.buffer.Buffer`` when
        waits are pending."""
        return self._last_child, self._last_parent, self._last_relinked

    # ------------------------------------------------------------------ queries

    def _id_status(self, frame_id):
        """0 for a known, queryable frame id; else INVALID_ARGUMENT (not a string, empty,
        '/'-prefixed) or UNKNOWN_FRAME (tf2 ``validateFrameId``)."""
        cdef str name = _as_str(frame_id)
        if name is None:
            return INVALID_ARGUMENT
        if self._frame(name) >= 0:
            return 0
        return _bad_id(name, 0)[0]

    cdef inline int _frame(self, object frame_id) except -2:
        """Id of a known, queryable frame, or -1 (empty, '/'-prefixed, unknown)."""
        cdef object fid = self._frame_ids.get(frame_id)
        if fid is None or <int>fid == 0:
            return -1
        if type(frame_id) is not str or not len(<str>frame_id) or (<str>frame_id)[0] == "/":
            return -1
        return <int>fid

    def _query(self, object target, object source, time):
        """``lookupTransform(target, source, time)`` in one call: the TransformStamped
        (built here, memoised until the next insert or clear), or a failure tuple:

        * ``(INVALID_ARGUMENT, 0 | 1)`` / ``(UNKNOWN_FRAME, 0 | 1)``: the target (0) or
          source (1) id is empty / '/'-prefixed, or unknown;
        * ``(LOOKUP_ERROR, 0)``: a loop; ``(CONNECTIVITY_ERROR, 0)``: two trees;
        * ``(EXTRAPOLATION_ERROR, frame id, time ns, expired)``: the link of that frame has
          no data at the time; ``expired`` when the time is older than the path's latest
          common time minus cache_time (tf2's transformable-request test), i.e. waiting
          cannot help.
        """
        cdef int64_t t = (<object>time)._ns
        cdef int64_t used, lct
        cdef int target_id, source_id, err, where = 0, gcode = 0
        cdef double v[7]
        cdef object hit, out, cache
        cdef size_t slot
        cdef bint expired
        cdef Link link
        cdef double st[7]
        cdef int p = 0
        if type(target) is not str:
            target = _as_str(target)
            if target is None:
                return (INVALID_ARGUMENT, 0)
        if type(source) is not str:
            source = _as_str(source)
            if source is None:
                return (INVALID_ARGUMENT, 1)
        # The memo slot of (target, source, t), by the ids' identity: an equal id in
        # another string object only misses. A hit is the very query: same objects (the
        # result holds them), same time, no insert or clear since.
        slot = (((<size_t><PyObject*>target) >> 4) ^ ((<size_t><PyObject*>source) >> 3)
                ^ <size_t>t ^ (<size_t>t >> 20)) & (MEMO_SIZE - 1)
        if self._memo_gen[slot] == self._generation and self._memo_t[slot] == t:
            hit = self._memo[slot]
            if (<tuple>hit)[1] is source and (<tuple>(<tuple>hit)[0])[1] is target:
                return hit
        if target == source:
            if t == 0:
                # tf2 stamps the identity with the frame's newest sample; an unknown id
                # maps to frame 0 (NO_PARENT), whose link exists only if "NO_PARENT" was
                # stored as a child (lookupFrameNumber / getFrame).
                cache = self._caches[self._frame_ids.get(target, 0)]
                if cache is not None:
                    (<Link>cache).c_latest(&t)
            _identity(v)
            return _stamped(_time_of(t) if t != (<object>time)._ns else time, target, source, v)
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(<str>target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(<str>source, 1)
        used = t
        err = self._walk(target_id, source_id, &used, v, &where)
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = <Link>self._caches[where]
            gcode = link.c_gather(used, st, &p)
            if gcode != G_FUTURE and self._common(target_id, source_id, &lct) == NO_ERROR:
                expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        out = _stamped(time if used == t and t != 0 else _time_of(used), target, source, v)
        self._memo[slot] = out
        self._memo_t[slot] = t
        self._memo_gen[slot] = self._generation
        return out

    def _chain(self, target_frame, source_frame, time=None):
        """The frames an answer for ``lookup_transform(target_frame, source_frame, time)``
        depends on, now and as data arrives: both ids, and the ancestors of each by its
        link's newest parent and, for a time other than 0, by its parent at ``time`` (a
        link re-parented over time), at most ``MAX_GRAPH_DEPTH + 1`` per chain (a longer
        walk is tf2's loop error). Unknown ids are included as given (they may arrive).
        Like tf2's ``_chainAsVector``, but as a set and for both parentage rules.

        Returns:
            A list of frame ids (no duplicates, in discovery order).
        """
        cdef int64_t t = 0 if time is None else (<object>time)._ns
        cdef list names = self._frame_names
        cdef list caches = self._caches
        cdef set seen = set()
        cdef list out = []
        cdef list todo = [target_frame, source_frame]
        cdef object name, fid, obj
        cdef int frame, parent, depth, p2
        cdef int64_t stamp
        cdef double st[7]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            out.append(name)
            fid = self._frame_ids.get(name)
            if fid is None:
                continue
            frame = <int>fid
            depth = 0
            while frame != 0 and depth <= C_MAX_DEPTH:
                obj = _link(caches, frame)
                if obj is None:
                    break
                if t != 0:
                    p2 = 0
                    if (<Link>obj).c_gather(t, st, &p2) == G_OK and p2 != 0:
                        if names[p2] not in seen:
                            todo.append(names[p2])
                parent = (<Link>obj).c_latest(&stamp)
                if parent == 0 or parent >= len(names):
                    break
                name = names[parent]
                if name in seen:
                    break
                seen.add(name)
                out.append(name)
                frame = parent
                depth += 1
        return out

    # ------------------------------------------------------------------ the walk

    cdef int _common(self, int target, int source, int64_t* out) except -1:
        """tf2 ``getLatestCommonTime``; NO_ERROR with ``out`` set, or an error code."""
        cdef list caches = self._caches
        cdef object obj
        cdef int64_t lct_stamp[C_MAX_DEPTH + 2]
        cdef int lct_parent[C_MAX_DEPTH + 2]
        cdef Py_ssize_t n = 0, k
        cdef int frame, parent, depth, common_parent
        cdef int64_t stamp, common
        cdef bint have = False, found
        out[0] = 0
        if source == target:
            obj = _link(caches, source)
            if obj is not None:
                (<Link>obj).c_latest(out)
            return NO_ERROR
        # Walk up from the source, remembering (stamp, parent) of each link.
        frame = source
        common = INT64_MAX
        depth = 0
        while frame != 0:
            obj = _link(caches, frame)
            if obj is None:
                break
            parent = (<Link>obj).c_latest(&stamp)
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            lct_stamp[n] = stamp
            lct_parent[n] = parent
            n += 1
            frame = parent
            if frame == target:
                out[0] = common if have else 0
                return NO_ERROR
            depth += 1
            if depth > C_MAX_DEPTH:
                return LOOKUP_ERROR
        # Walk up from the target until a parent seen on the source side.
        frame = target
        depth = 0
        have = False
        common = INT64_MAX
        common_parent = 0
        while True:
            obj = _link(caches, frame)
            if obj is None:
                break
            parent = (<Link>obj).c_latest(&stamp)
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            found = False
            for k in range(n):
                if lct_parent[k] == parent:
                    found = True
                    break
            if found:
                common_parent = parent
                break
            frame = parent
            if frame == source:
                out[0] = common if have else 0
                return NO_ERROR
            depth += 1
            if depth > C_MAX_DEPTH:
                return LOOKUP_ERROR
        if common_parent == 0:
            return CONNECTIVITY_ERROR
        for k in range(n):
            stamp = lct_stamp[k]
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if lct_parent[k] == common_parent:
                break
        out[0] = common if have else 0
        return NO_ERROR

    def _ccommon_time(self, int target_id, int source_id):
        """``(NO_ERROR, time ns)``, or ``(LOOKUP_ERROR (loop) | CONNECTIVITY_ERROR, 0)``."""
        cdef int64_t t = 0
        cdef int err = self._common(target_id, source_id, &t)
        return err, t

    # ------------------------------------------------------------------ public state

    def clear(self):
        """Drop every stored sample, keeping the frames and their links (tf2
        ``BufferCore::clear``). As in tf2, the reserved frame 0 (``NO_PARENT``) is
        skipped: a link stored with child ``"NO_PARENT"`` keeps its samples."""
        cdef object cache
        self._generation += 1
        for cache in self._caches[1:]:
            if cache is not None:
                cache.clear()

    def get_frame_names(self):
        """Every known frame id (children and parents), in registration order."""
        return self._frame_names[1:]

    def frame_exists(self, frame_id):
        """Whether ``frame_id`` is known (tf2 ``_frameExists``)."""
        return self._frame_ids.get(frame_id, 0) != 0

    def parent_of(self, frame_id, int64_t time_ns):
        """The parent id of ``frame_id`` at ``time_ns`` (0 = latest), or None for a root,
        an unknown frame or a time its link has no data for (tf2 ``_getParent``)."""
        cdef object fid = self._frame_ids.get(frame_id, 0)
        cdef object cache = self._caches[fid] if fid else None
        if cache is None:
            return None
        r = cache.gather(time_ns)
        if isinstance(r, str) or r[0] == 0:
            return None
        return self._frame_names[r[0]]

    def link_info(self):
        """Per linked frame, in registration order, ``(child, parent, authority,
        is_static, samples, oldest_ns, newest_ns)``; the parent of an emptied link is
        ``NO_PARENT``, a link with no recorded authority says so."""
        cdef list names = self._frame_names
        cdef list out = []
        cdef Py_ssize_t fid
        cdef object cache, r
        for fid in range(1, len(self._caches)):
            cache = self._caches[fid]
            if cache is None:
                continue
            r = cache.gather(0)
            out.append((
                names[fid],
                names[0 if isinstance(r, str) else r[0]],
                self._authority.get(fid, "no recorded authority"),
                cache.is_static,
                len(cache),
                cache.oldest_stamp(),
                cache.latest_stamp(),
            ))
        return out

    def extrapolation_detail(self, int where, int64_t used):
        """tf2's extrapolation text of the link of frame ``where`` (the int id a failed
        query reported) at ``used`` ns: ``"Lookup would require extrapolation ..."``;
        ``""`` for no link or a link that can answer that time."""
        cache = self._caches[where] if 0 < where < len(self._caches) else None
        detail = cache.gather(used) if cache is not None else ""
        return detail if isinstance(detail, str) else ""

    def common_time(self, target_frame, source_frame):
        """tf2 ``getLatestCommonTime`` for two known frame ids: ``(NO_ERROR, time ns)``,
        or ``(LOOKUP_ERROR (a loop) | CONNECTIVITY_ERROR, 0)``.

        Raises:
            KeyError: an id is unknown (validate first).
        """
        return self._ccommon_time(self._frame_ids[target_frame], self._frame_ids[source_frame])

    cdef int _walk(self, int target_id, int source_id, int64_t* time, double* out,
                   int* where) except -1:
        """tf2 ``walkToTopParent`` with ``TransformAccum``: ``out`` = the transform mapping
        source coordinates into target coordinates at ``time[0]`` (0 = latest common time,
        replaced by the time used). Returns NO_ERROR, LOOKUP_ERROR (a loop),
        CONNECTIVITY_ERROR, or EXTRAPOLATION_ERROR with ``where`` = the frame whose link had
        no data."""
        cdef list caches = self._caches
        cdef double src[7]
        cdef double tgt[7]
        cdef double r[3]
        cdef double q[4]
        cdef int top = 0, frame = 0, src_failed_at = 0
        cdef int outcome, err
        cdef bint failed
        if source_id == target_id:
            _identity(out)
            return NO_ERROR
        if time[0] == 0:
            err = self._common(target_id, source_id, time)
            if err:
                return err

        # Source side: source -> top. A failure here is only remembered: the path may
        # still close below it (only links between the two frames must be valid).
        outcome = _climb(caches, source_id, 0, target_id, time[0], src, &top)
        if outcome == CLIMB_EARLY:  # TargetParentOfSource
            memcpy(out, src, 7 * sizeof(double))
            return NO_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        failed = outcome == CLIMB_FAILED
        if failed:
            src_failed_at = top

        # Target side: target -> top. A failure here is reported at once.
        outcome = _climb(caches, target_id, top, source_id, time[0], tgt, &frame)
        if outcome == CLIMB_FAILED:
            where[0] = frame
            return EXTRAPOLATION_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        if outcome == CLIMB_EARLY:  # SourceParentOfTarget: the source side is unused
            _identity(src)
        elif frame != top:
            if failed:
                where[0] = src_failed_at
                return EXTRAPOLATION_ERROR
            return CONNECTIVITY_ERROR

        # FullPath: inv(target -> top) ∘ (source -> top), inv = (conj q, conj q * (-t)):
        # conj(q) applied to (s - g), then conj(q) ⊗ q_s.
        _qrot(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[0] - tgt[0], src[1] - tgt[1],
              src[2] - tgt[2], r)
        _qmul(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[3], src[4], src[5], src[6], q)
        out[0] = r[0]
        out[1] = r[1]
        out[2] = r[2]
        out[3] = q[0]
        out[4] = q[1]
        out[5] = q[2]
        out[6] = q[3]
        return NO_ERROR

    def _cwalk(self, int target_id, int source_id, int64_t time):
        """tf2 ``walkToTopParent`` with ``TransformAccum`` (see ``_walk``).

        Returns ``(NO_ERROR, 7-tuple, time used)``, ``(EXTRAPOLATION_ERROR, id of the
        frame whose link had no data, time)``, ``(CONNECTIVITY_ERROR, None, 0)`` or
        ``(LOOKUP_ERROR, None, 0)`` (a loop).
        """
        cdef double v[7]
        cdef int where = 0
        cdef int err = self._walk(target_id, source_id, &time, v, &where)
        if err == NO_ERROR:
            return NO_ERROR, (v[0], v[1], v[2], v[3], v[4], v[5], v[6]), time
        if err == EXTRAPOLATION_ERROR:
            return err, where, time
        return err, None, 0


# ===== batched lookups (issue 12) =====
#
# ``batch_lookup`` answers ``lookup_transform`` for many times at once. The path between
# the two frames is resolved once (the same climbs as ``_cwalk``, by each link's parent);
# then every time is gathered and accumulated along it in C, in ``_cwalk``'s arithmetic
# order (only the slerp angle and 1/sin of an interval are reused between the times that
# fall in it, which is exact). Rows are walked in blocks of 32, one row per lane
# (structure of arrays), so the composition runs in SIMD lanes with the scalar
# expressions (no FMA contraction: same bits). The one inexact step: slerp's two
# per-time sines come from libmvec's vector sin where it is available
# (``_batch_lookup_vector``, if ``_BATCH_VECTOR_SIN``), a few ulp from libm's, so such
# rows agree with the single
# lookup to ~1e-15 (the issue allows 1e-12), not bit for bit; rows without a per-time
# sine (exact stamps, statics, zero slerp angles), and every row where libmvec is not
# used, are the single lookup's bit for bit. Rows the plan cannot answer
# exactly (time 0, a gather that fails, a link with several parents, a span >= 2**53 ns)
# go through ``CoreBase._walk``; rows that fail there too are left unanswered, and
# ``tfbus.core.batch`` asks the single lookup for tf2's exception: no error is reproduced.

import os

from libc.string cimport memset
from libc.stdlib cimport free, malloc
from cpython.pythread cimport (
    WAIT_LOCK,
    PyThread_acquire_lock,
    PyThread_allocate_lock,
    PyThread_free_lock,
    PyThread_release_lock,
    PyThread_start_new_thread,
    PyThread_type_lock,
)

cdef extern from "pythread.h":
    # CPython's lock free needs no GIL (it frees with PyMem_RawFree); Cython's
    # declaration of it lacks ``nogil``.
    void _free_lock_nogil "PyThread_free_lock"(PyThread_type_lock lock) noexcept nogil

cdef int _NCPU = os.cpu_count() or 1
cdef Py_ssize_t _SPLIT_ROWS = 8192  # below this a second thread costs more than it saves
cdef Py_ssize_t _SORT_ROWS = 64  # below this, unsorted times are walked as given


cdef bint _nondecreasing(const int64_t* t, Py_ssize_t n) noexcept nogil:
    """Whether ``t[0] <= t[1] <= ... <= t[n - 1]``."""
    cdef Py_ssize_t i
    for i in range(1, n):
        if t[i] < t[i - 1]:
            return False
    return True


cdef extern from *:
    """
    /* tfbus batched lookups: the element-wise kernels over a block of rows (structure of
       arrays, one row per lane) and the atomics of the two-thread split. Plain IEEE
       double expressions in tf2's evaluation order; the extension is compiled with
       -ffp-contract=off, so vectorised lanes round exactly as the scalar walk does. */
    #define TFB_BLOCK 32
    /* The block kernels in AVX2 lanes too where GCC can dispatch at load time (ifunc):
       vector or scalar, each lane is the same IEEE expression (no FMA contraction). */
    #if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 6 && defined(__x86_64__) \
        && defined(__linux__)
    #define TFB_CLONES __attribute__((target_clones("avx2", "default")))
    #else
    #define TFB_CLONES
    #endif
    #if defined(__GNUC__) || defined(__clang__)
    #define TFB_RESTRICT __restrict__
    #elif defined(_MSC_VER)
    #define TFB_RESTRICT __restrict
    #else
    #define TFB_RESTRICT
    #endif

    /* acc = link o acc for every lane: tf2 TransformAccum::accum / quatRotate and
       Quaternion operator* (the expressions of _qrot, _qmul, _compose, same order). */
    static TFB_CLONES void tfb_compose_block(double (*TFB_RESTRICT acc)[TFB_BLOCK],
                                  const double (*TFB_RESTRICT st)[TFB_BLOCK]) {
        int j;
        for (j = 0; j < TFB_BLOCK; j++) {
            double qx = st[3][j], qy = st[4][j], qz = st[5][j], qw = st[6][j];
            double vx = acc[0][j], vy = acc[1][j], vz = acc[2][j];
            double bx = acc[3][j], by = acc[4][j], bz = acc[5][j], bw = acc[6][j];
            double tx = qw * vx + qy * vz - qz * vy;
            double ty = qw * vy + qz * vx - qx * vz;
            double tz = qw * vz + qx * vy - qy * vx;
            double tw = -qx * vx - qy * vy - qz * vz;
            acc[0][j] = (-tw * qx + tx * qw - ty * qz + tz * qy) + st[0][j];
            acc[1][j] = (-tw * qy + ty * qw - tz * qx + tx * qz) + st[1][j];
            acc[2][j] = (-tw * qz + tz * qw - tx * qy + ty * qx) + st[2][j];
            acc[3][j] = qw * bx + qx * bw + qy * bz - qz * by;
            acc[4][j] = qw * by + qy * bw + qz * bx - qx * bz;
            acc[5][j] = qw * bz + qz * bw + qx * by - qy * bx;
            acc[6][j] = qw * bw - qx * bx - qy * by - qz * bz;
        }
    }

    /* _cwalk's FullPath step for every lane (tf2 BufferCore::walkToTopParent, FullPath:
       inverse(target -> top) * (source -> top)), the expressions of _bfull. */
    static TFB_CLONES void tfb_full_block(const double (*TFB_RESTRICT src)[TFB_BLOCK],
                               const double (*TFB_RESTRICT tgt)[TFB_BLOCK],
                               double (*TFB_RESTRICT out)[TFB_BLOCK]) {
        int j;
        for (j = 0; j < TFB_BLOCK; j++) {
            double sqx = src[3][j], sqy = src[4][j], sqz = src[5][j], sqw = src[6][j];
            double iqx = -tgt[3][j], iqy = -tgt[4][j], iqz = -tgt[5][j], iqw = tgt[6][j];
            double vx = src[0][j] - tgt[0][j], vy = src[1][j] - tgt[1][j];
            double vz = src[2][j] - tgt[2][j];
            double tx = iqw * vx + iqy * vz - iqz * vy;
            double ty = iqw * vy + iqz * vx - iqx * vz;
            double tz = iqw * vz + iqx * vy - iqy * vx;
            double tw = -iqx * vx - iqy * vy - iqz * vz;
            out[0][j] = -tw * iqx + tx * iqw - ty * iqz + tz * iqy;
            out[1][j] = -tw * iqy + ty * iqw - tz * iqx + tx * iqz;
            out[2][j] = -tw * iqz + tz * iqw - tx * iqy + ty * iqx;
            out[3][j] = iqw * sqx + iqx * sqw + iqy * sqz - iqz * sqy;
            out[4][j] = iqw * sqy + iqy * sqw + iqz * sqx - iqx * sqz;
            out[5][j] = iqw * sqz + iqz * sqw + iqx * sqy - iqy * sqx;
            out[6][j] = iqw * sqw - iqx * sqx - iqy * sqy - iqz * sqz;
        }
    }

    #if defined(_MSC_VER) && !defined(__clang__)
    #include <intrin.h>
    static long tfb_fetch_add(long* p, long v) {
        return _InterlockedExchangeAdd((volatile long*)p, v);
    }
    static int tfb_cas(long* p, long expected, long desired) {
        return _InterlockedCompareExchange((volatile long*)p, desired, expected) == expected;
    }
    #else
    static long tfb_fetch_add(long* p, long v) {
        return __atomic_fetch_add(p, v, __ATOMIC_SEQ_CST);
    }
    static int tfb_cas(long* p, long expected, long desired) {
        return __atomic_compare_exchange_n(p, &expected, desired, 0, __ATOMIC_SEQ_CST,
                                           __ATOMIC_SEQ_CST);
    }
    #endif

    #include <math.h>
    #include <stdint.h>
    #if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
    #define TFB_X86_64 1
    #include <immintrin.h>
    #endif

    /* Rows j0 <= j < j1 of a block, all in one interval (samples a, a + 7; bq = b with
       slerp's sign flip, d = 1 / sin(theta)): TimeCache::interpolate's lerp and tf2 slerp's
       (a sin((1 - r) theta) + b sin(r theta)) / sin(theta), the expressions of
       _binterp_run lane by lane (separate multiplies and adds: no FMA in this target). */
    static int tfb_avx2 = 0;
    #if defined(TFB_X86_64)
    static __attribute__((target("avx2"))) void tfb_interp_run_avx2(
            const double* a, const double* bq, double d, const double* rr, const double* sy,
            int j0, int j1, double (*st)[TFB_BLOCK]) {
        const __m256d one = _mm256_set1_pd(1.0), dd = _mm256_set1_pd(d);
        const __m256d a0 = _mm256_set1_pd(a[0]), a1 = _mm256_set1_pd(a[1]);
        const __m256d a2 = _mm256_set1_pd(a[2]), a3 = _mm256_set1_pd(a[3]);
        const __m256d a4 = _mm256_set1_pd(a[4]), a5 = _mm256_set1_pd(a[5]);
        const __m256d a6 = _mm256_set1_pd(a[6]), b0 = _mm256_set1_pd(a[7]);
        const __m256d b1 = _mm256_set1_pd(a[8]), b2 = _mm256_set1_pd(a[9]);
        const __m256d c0 = _mm256_set1_pd(bq[0]), c1 = _mm256_set1_pd(bq[1]);
        const __m256d c2 = _mm256_set1_pd(bq[2]), c3 = _mm256_set1_pd(bq[3]);
        const __m256i lanes = _mm256_set_epi64x(3, 2, 1, 0);
        const __m256i lo = _mm256_set1_epi64x(j0 - 1), hi = _mm256_set1_epi64x(j1);
        int j;
        for (j = j0 & ~3; j < j1; j += 4) {
            __m256i lane = _mm256_add_epi64(_mm256_set1_epi64x(j), lanes);
            __m256i m = _mm256_and_si256(_mm256_cmpgt_epi64(lane, lo),
                                         _mm256_cmpgt_epi64(hi, lane));
            __m256d r = _mm256_loadu_pd(rr + j), s = _mm256_sub_pd(one, r);
            __m256d q0 = _mm256_loadu_pd(sy + j), q1 = _mm256_loadu_pd(sy + TFB_BLOCK + j);
            _mm256_maskstore_pd(&st[0][j], m, _mm256_add_pd(_mm256_mul_pd(s, a0), _mm256_mul_pd(r, b0)));
            _mm256_maskstore_pd(&st[1][j], m, _mm256_add_pd(_mm256_mul_pd(s, a1), _mm256_mul_pd(r, b1)));
            _mm256_maskstore_pd(&st[2][j], m, _mm256_add_pd(_mm256_mul_pd(s, a2), _mm256_mul_pd(r, b2)));
            _mm256_maskstore_pd(&st[3][j], m, _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a3, q0), _mm256_mul_pd(c0, q1)), dd));
            _mm256_maskstore_pd(&st[4][j], m, _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a4, q0), _mm256_mul_pd(c1, q1)), dd));
            _mm256_maskstore_pd(&st[5][j], m, _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a5, q0), _mm256_mul_pd(c2, q1)), dd));
            _mm256_maskstore_pd(&st[6][j], m, _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a6, q0), _mm256_mul_pd(c3, q1)), dd));
        }
    }
    #define TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st) \
        (tfb_avx2 ? (tfb_interp_run_avx2(a, bq, d, rr, sy, j0, j1, st), 1) : 0)
    #else
    #define TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st) 0
    #endif

    /* The SIMD kernels this CPU runs (x86-64: AVX2), checked once at import. */
    /* slerp's per-time sines in vector lanes: glibc's libmvec (_ZGVdN4v_sin, the AVX2
       variant of sin in the x86-64 vector function ABI; at most 4 ulp from the correctly
       rounded sine, where libm's scalar sin is within 1 ulp). Its address is found at
       import by ctypes (_libmvec_sin_address below) and handed over with tfb_vsin_set,
       so the extension neither links libmvec nor calls dlopen itself (whose glibc 2.34
       symbol version would lift the wheel's manylinux tag). Without it (other libc,
       other CPU), libm's sin is called per lane, bit for bit the scalar walk's. */
    static int tfb_vsin_ok = 0;
    #if defined(TFB_X86_64) && defined(__linux__)
    typedef __m256d (*tfb_vsin_fn)(__m256d);
    static tfb_vsin_fn tfb_vsin = NULL;
    static __attribute__((target("avx2"))) void tfb_sin_lanes_vec(const double* x, double* y) {
        int j;
        for (j = 0; j < 2 * TFB_BLOCK; j += 4)
            _mm256_storeu_pd(y + j, tfb_vsin(_mm256_loadu_pd(x + j)));
    }
    static void tfb_vsin_set(size_t address) { tfb_vsin = (tfb_vsin_fn)(uintptr_t)address; }
    #define TFB_SIN_LANES_VEC(x, y) (tfb_vsin_ok ? (tfb_sin_lanes_vec(x, y), 1) : 0)
    #else
    static void tfb_vsin_set(size_t address) { (void)address; }
    #define TFB_SIN_LANES_VEC(x, y) 0
    #endif

    /* The SIMD kernels this CPU runs (x86-64: AVX2, and libmvec's sin if found), checked
       once at import; returns whether the vector sine is used. */
    static int tfb_simd_init(void) {
    #if defined(TFB_X86_64)
        __builtin_cpu_init();
        tfb_avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    #endif
    #if defined(TFB_X86_64) && defined(__linux__)
        /* libmvec's AVX2 variants also use FMA instructions */
        tfb_vsin_ok = tfb_avx2 && __builtin_cpu_supports("fma") && tfb_vsin != NULL;
    #endif
        return tfb_vsin_ok;
    }
    """
    int tfb_avx2
    int tfb_vsin_ok
    int tfb_simd_init() noexcept nogil
    void tfb_vsin_set(size_t address) noexcept nogil
    bint TFB_SIN_LANES_VEC(const double* x, double* y) noexcept nogil
    bint TFB_INTERP_RUN_AVX2(const double* a, const double* bq, double d, const double* rr,
                             const double* sy, int j0, int j1,
                             double (*st)[32]) noexcept nogil
    void tfb_compose_block(double (*acc)[32], const double (*st)[32]) noexcept nogil
    void tfb_full_block(const double (*src)[32], const double (*tgt)[32],
                        double (*out)[32]) noexcept nogil
    long tfb_fetch_add(long* p, long v) noexcept nogil
    bint tfb_cas(long* p, long expected, long desired) noexcept nogil


cdef enum:
    _BLOCK = 32  # rows gathered and composed together (must equal TFB_BLOCK above)
    _CHUNK = 512  # rows a thread claims at a time (a multiple of _BLOCK)


def _libmvec_sin_address():
    """The address of glibc libmvec's ``_ZGVdN4v_sin`` (the x86-64 vector function ABI's
    AVX2 sine of 4 doubles), or 0 where there is none (another libc, another system).
    Found with :mod:`ctypes` (``dlopen``/``dlsym``), which keeps the library loaded."""
    import ctypes

    global _LIBMVEC
    try:
        _LIBMVEC = ctypes.CDLL("libmvec.so.1")
        return ctypes.cast(_LIBMVEC._ZGVdN4v_sin, ctypes.c_void_p).value or 0
    except (OSError, AttributeError):
        return 0


_LIBMVEC = None
tfb_vsin_set(<size_t>_libmvec_sin_address())
_BATCH_VECTOR_SIN = bool(tfb_simd_init())
"""True when :func:`_batch_lookup_vector` takes slerp's per-time sines from glibc's libmvec
(``_ZGVdN4v_sin``, AVX2): its rows then agree with ``lookup_transform`` to within a few
ulp of the sines (well inside the issue's 1e-12), not bit for bit. False (no libmvec, no
AVX2): libm's ``sin``, rows bit-identical to the scalar lookup."""


def _batch_simd(bint enable):
    """Tests only: False makes :func:`batch_lookup` take its scalar, bit-exact loops
    everywhere (libm's ``sin``, no AVX2 kernels: what a CPU without AVX2 runs); True
    restores what the import-time checks found. Returns whether the vector sine is now
    used. Not thread-safe: no batch may be running."""
    global tfb_avx2, tfb_vsin_ok
    if enable:
        return bool(tfb_simd_init())
    tfb_avx2 = 0
    tfb_vsin_ok = 0
    return False


cdef struct _BLink:
    const int64_t* st
    const double* va
    Py_ssize_t head
    Py_ssize_t tail
    double sv[7]  # a static link's value
    bint is_static
    bint check_only  # gathered (must succeed) but not accumulated: tf2's early exit
    Py_ssize_t cur  # search cursor: the last index found (sorted times advance it)
    # The last interpolation interval [ci - 1, ci] and its slerp constants (exact reuse).
    Py_ssize_t ci
    int64_t ct0  # its two stamps
    int64_t ct1
    double cspan  # <double>(ct1 - ct0)
    bint zero_angle
    double theta
    double d
    double bq[4]


cdef enum:
    _K_SKIP = 0  # row already failed, or fails here
    _K_COPY = 1  # a stored sample exactly
    _K_INTERP = 2  # between samples idx and idx + 1


cdef void _bgather(_BLink* L, const int64_t* times, int m, signed char* good,
                   double st[7][_BLOCK], bint vector_sin) noexcept nogil:
    """``TimeCache::c_gather`` of one link for the ``m`` rows of a block (times != 0,
    single-parent link) into ``st`` (column c, row j); ``good[j] = 0`` where tf2's gather
    would fail or the row needs the scalar walk (span >= 2**53 ns).

    Three passes, so that the libm calls run back to back: (1) find each row's sample or
    interval (a cursor that advances over sorted times, else a bisection) and the
    interval's slerp constants — tf2 ``Quaternion::slerp`` / ``angleShortestPath``:
    ``theta = acos(|dot| / |a||b|)``, ``1 / sin(theta)``, the sign flip of b — which
    depend on the two samples only and are computed once per interval (held in ``L``
    across blocks); (2) ``sin((1 - r) theta)`` and ``sin(r theta)`` per row (libmvec's
    vector sin if ``vector_sin`` and ``_BATCH_VECTOR_SIN``, else libm's); (3) each row as
    ``TimeCache.c_gather`` / ``_slerp`` compute it (``TimeCache::interpolate``: linear
    translation, the ratio from integer ns), same expressions, same order: bit-identical
    given the same sines.
    """
    cdef signed char kind[_BLOCK]
    cdef Py_ssize_t idx[_BLOCK]
    cdef int slot[_BLOCK]
    cdef double rr[_BLOCK]
    cdef double sx[2 * _BLOCK]
    cdef double sy[2 * _BLOCK]
    # per interval met in this block (at most one per row)
    cdef double sd[_BLOCK]
    cdef double sbq[_BLOCK][4]
    cdef bint szero[_BLOCK]
    cdef int nslots = 0, cur_slot = -1, j, j1, c, sl
    cdef Py_ssize_t head = L.head, tail = L.tail, i, cur
    cdef const int64_t* stp = L.st
    cdef const double* va = L.va
    cdef const double* a
    cdef const double* b
    cdef int64_t t, t0, span, newest
    cdef double r, s, dot, cc, d, q0, q1
    cdef bint single, any_sin = False
    if L.is_static:
        for c in range(7):
            for j in range(_BLOCK):
                st[c][j] = L.sv[c]
        return
    if tail == head:  # not planned (a link without data makes the plan fail)
        for j in range(m):
            good[j] = 0
        return
    newest = stp[tail - 1]
    single = tail - head == 1
    cur = L.cur
    memset(rr, 0, sizeof(rr))  # (lanes outside runs are computed, never stored)
    memset(sx, 0, sizeof(sx))  # lanes without a sine compute sin(0)
    # (1) locate
    for j in range(m):
        if not good[j]:
            kind[j] = _K_SKIP
            continue
        t = times[j]
        if L.ci > 0 and L.ct0 < t and t < L.ct1:
            # Strictly inside the last interval (most sorted times): the slow path below
            # would find i = ci, nothing to recompute; same ratio, same arguments.
            if cur_slot < 0:
                cur_slot = _bslot(L, nslots, szero, sd, sbq)
                nslots += 1
            kind[j] = _K_INTERP
            idx[j] = L.ci - 1
            slot[j] = cur_slot
            r = <double>(t - L.ct0) / L.cspan
            rr[j] = r
            if not L.zero_angle:
                sx[j] = (1.0 - r) * L.theta
                sx[_BLOCK + j] = r * L.theta
                any_sin = True
            continue
        kind[j] = _K_SKIP
        if t == newest:
            kind[j] = _K_COPY
            idx[j] = tail - 1
            continue
        if single or t > newest:
            good[j] = 0
            continue
        # i = the first index with stp[i] >= t (bisect_left), from the cursor if it can
        i = cur
        if not (i > head and i < tail and stp[i - 1] < t and t <= stp[i]):
            if i > head and i + 1 < tail and stp[i] < t and t <= stp[i + 1]:
                i += 1
            else:
                i = _bisect_left(stp, t, head, tail)
        cur = i
        if stp[i] == t:
            kind[j] = _K_COPY
            idx[j] = i
            continue
        if i == head:
            good[j] = 0
            continue
        t0 = stp[i - 1]
        span = stp[i] - t0
        if span >= EXACT_SPAN:
            good[j] = 0
            continue
        if i != L.ci:
            # tf2 slerp's per-interval part (Quaternion.h slerp / angleShortestPath,
            # as _slerp): same expressions and order.
            a = &va[(i - 1) * 7]
            b = &va[i * 7]
            L.bq[0] = b[3]
            L.bq[1] = b[4]
            L.bq[2] = b[5]
            L.bq[3] = b[6]
            dot = a[3] * L.bq[0] + a[4] * L.bq[1] + a[5] * L.bq[2] + a[6] * L.bq[3]
            if dot < 0.0:
                dot = -dot
                L.bq[0] = -L.bq[0]
                L.bq[1] = -L.bq[1]
                L.bq[2] = -L.bq[2]
                L.bq[3] = -L.bq[3]
            cc = dot / sqrt(
                (a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
                * (L.bq[0] * L.bq[0] + L.bq[1] * L.bq[1] + L.bq[2] * L.bq[2]
                   + L.bq[3] * L.bq[3])
            )
            L.zero_angle = cc >= 1.0
            if not L.zero_angle:
                L.theta = acos(cc)
                L.d = 1.0 / sin(L.theta)
            L.ci = i
            L.ct0 = t0
            L.ct1 = stp[i]
            L.cspan = <double>span
            cur_slot = -1
        if cur_slot < 0:
            cur_slot = _bslot(L, nslots, szero, sd, sbq)
            nslots += 1
        kind[j] = _K_INTERP
        idx[j] = i - 1
        slot[j] = cur_slot
        r = <double>(t - t0) / <double>span
        rr[j] = r
        if not L.zero_angle:
            # the arguments of tf2 slerp's per-time sines (as _slerp)
            sx[j] = (1.0 - r) * L.theta
            sx[_BLOCK + j] = r * L.theta
            any_sin = True
    L.cur = cur
    # (2) sin((1 - r) theta) in lanes 0..31, sin(r theta) in 32..63 (tf2 slerp's two
    # per-time transcendental calls): libmvec's vector sin where available (rows within
    # a few ulp of the scalar walk's), else libm's sin per row (bit for bit)
    if any_sin and not (vector_sin and TFB_SIN_LANES_VEC(sx, sy)):
        memset(sy, 0, sizeof(sy))
        for j in range(m):
            if kind[j] == _K_INTERP and not szero[slot[j]]:
                sy[j] = sin(sx[j])
                sy[_BLOCK + j] = sin(sx[_BLOCK + j])
    # (3) the rows; a run of rows in one interval shares its samples and constants
    j = 0
    while j < m:
        if kind[j] == _K_INTERP and not szero[slot[j]]:
            j1 = j + 1
            while j1 < m and kind[j1] == _K_INTERP and idx[j1] == idx[j]:
                j1 += 1
            sl = slot[j]
            _binterp_run(&va[idx[j] * 7], sbq[sl], sd[sl], rr, sy, j, j1, st)
            j = j1
            continue
        if kind[j] == _K_COPY:
            a = &va[idx[j] * 7]
            st[0][j] = a[0]
            st[1][j] = a[1]
            st[2][j] = a[2]
            st[3][j] = a[3]
            st[4][j] = a[4]
            st[5][j] = a[5]
            st[6][j] = a[6]
        elif kind[j] == _K_INTERP:
            a = &va[idx[j] * 7]
            b = a + 7
            r = rr[j]
            s = 1.0 - r
            st[0][j] = s * a[0] + r * b[0]
            st[1][j] = s * a[1] + r * b[1]
            st[2][j] = s * a[2] + r * b[2]
            sl = slot[j]
            if szero[sl]:
                st[3][j] = a[3]
                st[4][j] = a[4]
                st[5][j] = a[5]
                st[6][j] = a[6]
            else:
                d = sd[sl]
                q0 = sy[j]
                q1 = sy[_BLOCK + j]
                st[3][j] = (a[3] * q0 + sbq[sl][0] * q1) * d
                st[4][j] = (a[4] * q0 + sbq[sl][1] * q1) * d
                st[5][j] = (a[5] * q0 + sbq[sl][2] * q1) * d
                st[6][j] = (a[6] * q0 + sbq[sl][3] * q1) * d
        j += 1


cdef inline int _bslot(const _BLink* L, int n, bint* szero, double* sd,
                       double sbq[][4]) noexcept nogil:
    """Slot ``n`` of a block's intervals := the link's cached slerp constants."""
    szero[n] = L.zero_angle
    sd[n] = L.d
    sbq[n][0] = L.bq[0]
    sbq[n][1] = L.bq[1]
    sbq[n][2] = L.bq[2]
    sbq[n][3] = L.bq[3]
    return n


cdef inline void _binterp_run(const double* a, const double* bq, double d,
                              const double* rr, const double* sy, int j0, int j1,
                              double st[7][_BLOCK]) noexcept nogil:
    """Rows ``j0 <= j < j1``, all between samples ``a`` and ``a + 7`` (non-zero slerp
    angle): ``TimeCache::interpolate`` (lerp of the origins) and tf2 slerp's last step
    ``(a sin((1 - r) theta) + b sin(r theta)) / sin(theta)``, as ``TimeCache.c_gather``
    and ``_slerp`` compute them (``bq`` is b with slerp's sign flip, ``d`` 1/sin); in
    AVX2 lanes when the CPU has them (``tfb_interp_run_avx2``, same expressions)."""
    cdef const double* b = a + 7
    cdef double a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3], a4 = a[4], a5 = a[5]
    cdef double a6 = a[6], b0 = b[0], b1 = b[1], b2 = b[2]
    cdef double c0 = bq[0], c1 = bq[1], c2 = bq[2], c3 = bq[3]
    cdef double r, s, q0, q1
    cdef int j
    if TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st):
        return
    for j in range(j0, j1):
        r = rr[j]
        s = 1.0 - r
        st[0][j] = s * a0 + r * b0
        st[1][j] = s * a1 + r * b1
        st[2][j] = s * a2 + r * b2
        q0 = sy[j]
        q1 = sy[_BLOCK + j]
        st[3][j] = (a3 * q0 + c0 * q1) * d
        st[4][j] = (a4 * q0 + c1 * q1) * d
        st[5][j] = (a5 * q0 + c2 * q1) * d
        st[6][j] = (a6 * q0 + c3 * q1) * d


cdef enum:
    C_MAX_DEPTH_BATCH = 64  # longer chains take the scalar walk


cdef int _bplan_side(list caches, int frame, int stop, int early, _BLink* links,
                     int* n, int* reached, bint* early_hit) except -1:
    """The structure of one ``_climb`` (by each link's single parent): append its links
    to ``links``. Returns 0, or 1 when no row can take the fast path (a link with no
    data, several parents or NO_PARENT, or a loop)."""
    cdef object obj
    cdef int parent
    cdef int depth = 0
    cdef _BLink* L
    early_hit[0] = False
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        if n[0] >= C_MAX_DEPTH_BATCH:
            return 1
        L = &links[n[0]]
        memset(L, 0, sizeof(_BLink))
        L.ci = -1
        L.cur = -1
        if isinstance(obj, StaticCache):
            L.is_static = True
            memcpy(L.sv, (<StaticCache>obj)._v, 7 * sizeof(double))
            parent = (<StaticCache>obj)._parent
        elif isinstance(obj, TimeCache):
            if (<TimeCache>obj)._pa != NULL or (<TimeCache>obj)._tail == (<TimeCache>obj)._head:
                return 1
            L.st = (<TimeCache>obj)._st
            L.va = (<TimeCache>obj)._va
            L.head = (<TimeCache>obj)._head
            L.tail = (<TimeCache>obj)._tail
            parent = (<TimeCache>obj)._parent
        else:
            return 1
        if parent == 0:
            return 1
        n[0] += 1
        if frame == early:
            L.check_only = True
            early_hit[0] = True
            reached[0] = frame
            return 0
        frame = parent
        depth += 1
        if depth > C_MAX_DEPTH:
            return 1
    reached[0] = frame
    return 0


cdef inline void _bidentity_block(double acc[7][_BLOCK]) noexcept nogil:
    cdef int j
    for j in range(_BLOCK):
        acc[0][j] = acc[1][j] = acc[2][j] = acc[3][j] = acc[4][j] = acc[5][j] = 0.0
        acc[6][j] = 1.0


cdef inline void _bchain(_BLink* links, int n, const int64_t* times, int m,
                         double acc[7][_BLOCK], double st[7][_BLOCK],
                         signed char* good, bint vector_sin) noexcept nogil:
    """One ``_climb`` for the ``m`` rows of a block, link by link: each link's samples
    (``_bgather``), then ``acc = link ∘ acc`` over the whole block
    (``tfb_compose_block``: ``_compose``'s expressions in its order, so each row is
    bit-for-bit the scalar climb; lanes no longer good, or beyond ``m``, compute
    garbage that is never read)."""
    cdef int k
    _bidentity_block(acc)
    for k in range(n):
        _bgather(&links[k], times, m, good, st, vector_sin)
        if links[k].check_only:
            continue
        if k == 0:
            memcpy(acc, st, sizeof(double) * 7 * _BLOCK)
        else:
            tfb_compose_block(acc, st)


cdef struct _BJob:
    # the plan (copied: a worker may outlive a caller that stopped waiting for it)
    _BLink src[C_MAX_DEPTH_BATCH]
    _BLink tgt[C_MAX_DEPTH_BATCH]
    int ns
    int nt
    bint src_early
    bint tgt_early
    const int64_t* times
    const int64_t* order  # row r of ``times`` is row order[r] of out / ok; NULL: r itself
    Py_ssize_t n_rows
    double* out
    signed char* ok
    long next_chunk  # atomic: the next chunk of _CHUNK rows to claim
    long state  # atomic: _W_IDLE, then _W_RUNNING (worker) or _W_ABANDONED (caller)
    bint vector_sin  # slerp's per-time sines from libmvec (if found), else libm
    Py_ssize_t answered_worker
    PyThread_type_lock done


cdef enum:
    _W_IDLE = 0
    _W_RUNNING = 1
    _W_ABANDONED = 2


cdef inline int _bstore(_BJob* job, Py_ssize_t rb, int m, const signed char* good,
                        double block[7][_BLOCK]) noexcept nogil:
    """Write the good rows of a block (rows ``rb`` .. ``rb + m - 1`` of ``job.times``)
    to ``job.out`` (at ``job.order``'s rows when the times were sorted) and mark them
    answered; how many were written."""
    cdef int j, k, n = 0
    cdef Py_ssize_t row
    cdef double* o
    for j in range(m):
        if good[j]:
            row = rb + j if job.order == NULL else job.order[rb + j]
            o = &job.out[row * 7]
            for k in range(7):
                o[k] = block[k][j]
            job.ok[row] = 1
            n += 1
    return n


cdef Py_ssize_t _brows(_BJob* job) noexcept nogil:
    """The per-time loop of :func:`batch_lookup`: claims chunks of ``_CHUNK`` rows until
    none is left and walks each in blocks of ``_BLOCK`` (no GIL). Every chunk starts from
    the plan's links (fresh cursor and interval cache: the result does not depend on
    which thread took which chunk)."""
    cdef _BLink src_links[C_MAX_DEPTH_BATCH]
    cdef _BLink tgt_links[C_MAX_DEPTH_BATCH]
    cdef double acc_s[7][_BLOCK]
    cdef double acc_t[7][_BLOCK]
    cdef double st[7][_BLOCK]
    cdef double res[7][_BLOCK]
    cdef signed char good[_BLOCK]
    cdef Py_ssize_t r0, r1, rb, answered = 0, n_rows = job.n_rows
    cdef const int64_t* times = job.times
    cdef int m, j, ns = job.ns, nt = job.nt
    cdef bint src_early = job.src_early, tgt_early = job.tgt_early
    memset(st, 0, sizeof(st))
    memset(acc_t, 0, sizeof(acc_t))
    while True:
        r0 = <Py_ssize_t>tfb_fetch_add(&job.next_chunk, 1) * _CHUNK
        if r0 >= n_rows:
            break
        r1 = r0 + _CHUNK if n_rows - r0 > _CHUNK else n_rows
        memcpy(src_links, job.src, ns * sizeof(_BLink))
        memcpy(tgt_links, job.tgt, nt * sizeof(_BLink))
        rb = r0
        while rb < r1:
            m = <int>(r1 - rb) if r1 - rb < _BLOCK else _BLOCK
            for j in range(m):
                good[j] = times[rb + j] != 0
            _bchain(src_links, ns, times + rb, m, acc_s, st, good, job.vector_sin)
            if src_early:
                answered += _bstore(job, rb, m, good, acc_s)
            else:
                _bchain(tgt_links, nt, times + rb, m, acc_t, st, good, job.vector_sin)
                if tgt_early:
                    _bidentity_block(acc_s)  # _cwalk's TargetParentOfSource: source = I
                tfb_full_block(acc_s, acc_t, res)
                answered += _bstore(job, rb, m, good, res)
            rb += _BLOCK
    return answered


cdef void _bworker(void* arg) noexcept nogil:
    """The second thread: takes chunks if the caller has not finished them all before
    it started (then it only frees the job), and releases ``done`` when finished."""
    cdef _BJob* job = <_BJob*>arg
    if not tfb_cas(&job.state, _W_IDLE, _W_RUNNING):
        # the caller did every row and returned without waiting: the job is ours
        _free_lock_nogil(job.done)
        free(job)
        return
    job.answered_worker = _brows(job)
    PyThread_release_lock(job.done)  # last touch: the caller frees the job


cdef Py_ssize_t _bsplit(const _BLink* src, int ns, bint src_early, const _BLink* tgt,
                        int nt, bint tgt_early, const int64_t* times, const int64_t* order,
                        Py_ssize_t n_rows, double* out, signed char* ok,
                        bint vector_sin) except -1:
    """``_brows`` over all rows; from ``_SPLIT_ROWS`` rows on (several CPUs), a second
    thread claims chunks too. The split is dynamic (chunks of ``_CHUNK`` rows claimed
    from a shared counter), so a core busy with other work slows the call down by at
    most one chunk, and a worker that has not started when the rows are done is not
    waited for."""
    cdef _BJob* job = <_BJob*>malloc(sizeof(_BJob))
    cdef Py_ssize_t answered
    cdef bint threaded = n_rows >= _SPLIT_ROWS and _NCPU >= 2
    if job == NULL:
        raise MemoryError()
    memcpy(job.src, src, ns * sizeof(_BLink))
    memcpy(job.tgt, tgt, nt * sizeof(_BLink))
    job.ns = ns
    job.nt = nt
    job.src_early = src_early
    job.tgt_early = tgt_early
    job.times = times
    job.order = order
    job.n_rows = n_rows
    job.out = out
    job.ok = ok
    job.next_chunk = 0
    job.state = _W_IDLE
    job.vector_sin = vector_sin
    job.answered_worker = 0
    job.done = NULL
    if threaded:
        job.done = PyThread_allocate_lock()
        if job.done == NULL:
            free(job)
            raise MemoryError()
        PyThread_acquire_lock(job.done, WAIT_LOCK)
        if PyThread_start_new_thread(_bworker, job) == <unsigned long>-1:
            PyThread_release_lock(job.done)
            PyThread_free_lock(job.done)
            job.done = NULL
            threaded = False
    with nogil:
        answered = _brows(job)
        if threaded and not tfb_cas(&job.state, _W_IDLE, _W_ABANDONED):
            PyThread_acquire_lock(job.done, WAIT_LOCK)  # the worker is running: wait
            answered += job.answered_worker
            _free_lock_nogil(job.done)
            free(job)
        elif not threaded:
            free(job)
        # else: the worker never started; it frees the job when it does
    return answered


def batch_lookup(CoreBase core, object target_frame, object source_frame,
                 const int64_t[::1] times, double[:, ::1] out, int64_t[::1] stamps,
                 signed char[::1] ok):
    """``lookupTransform(target_frame, source_frame, t)`` for every t of ``times``, into
    caller-owned arrays (the bit-exact compiled entry of the batched lookups).

    For each row r with ``ok[r] == 1`` on return, ``out[r]`` is the transform (tx, ty,
    tz, qx, qy, qz, qw) mapping source into target and ``stamps[r]`` the time used
    (the caller fills ``stamps`` with ``times``; only rows at time 0 change): what
    ``lookup_transform`` returns for ``times[r]``, bit for bit (libm's sines; see
    :func:`_batch_lookup_vector` for the vectorised ones). Rows left at 0 are
    those the single lookup would fail for (the caller asks it for the exception).
    Returns the number of rows answered, or -1 when a frame id is not a known,
    queryable id (then no row is answered: the single lookup raises tf2's
    InvalidArgument / Lookup exception). ``target_frame == source_frame`` is the
    caller's (identity) case and returns -1 too.

    The path is resolved once; each time is then gathered and accumulated along it in C
    (no GIL), in ``_walk``'s arithmetic order. ``times`` may come in any order: from 64
    rows on, times that are not non-decreasing are walked sorted (numpy's argsort; the
    kernel's cursor and per-interval constants pay off on sorted times) and each row is
    written back to its place (a row's value does not depend on the order). Rows that plan cannot take (time 0,
    a link with several parents, a span >= 2**53 ns, a row missing data) go through
    ``_walk`` itself. From 8192 rows on a machine with several CPUs, a second thread
    claims chunks of rows alongside the caller (the caller keeps the GIL and waits for a
    worker that has started, so nothing writes the buffer meanwhile).
    """
    return _batch_lookup(core, target_frame, source_frame, times, out, stamps, ok, False)


def lookup_rows(CoreBase core, object target_frame, object source_frame,
                const int64_t[::1] times, double[:, ::1] out, int64_t[::1] stamps,
                signed char[::1] ok):
    """:func:`batch_lookup` with slerp's per-time sines from glibc's libmvec where
    ``_BATCH_VECTOR_SIN`` (AVX2 vector sine, a few ulp from libm's): rows then agree with
    ``lookup_transform`` to within 1e-12 (issue 12's tolerance; ~1e-14 in practice), bit
    for bit where a row has no per-time sine; elsewhere it is :func:`batch_lookup`. The
    entry :meth:`tfbus.core.BufferCore.lookup_transforms` uses (the pure-Python core's
    ``lookup_rows`` is its ``batch_lookup``: it has no vector sine)."""
    return _batch_lookup(core, target_frame, source_frame, times, out, stamps, ok, True)


cdef Py_ssize_t _batch_lookup(CoreBase core, object target_frame, object source_frame,
                              const int64_t[::1] times, double[:, ::1] out,
                              int64_t[::1] stamps, signed char[::1] ok,
                              bint vector_sin) except -2:
    """:func:`batch_lookup` (``vector_sin`` False) and :func:`_batch_lookup_vector`."""
    cdef Py_ssize_t n_rows = times.shape[0], r, answered = 0
    cdef _BLink src_links[C_MAX_DEPTH_BATCH]
    cdef _BLink tgt_links[C_MAX_DEPTH_BATCH]
    cdef int ns = 0, nt = 0, top = 0, frame = 0, where = 0, err
    cdef int target_id, source_id
    cdef bint src_early = False, tgt_early = False, planned
    cdef int64_t used
    cdef list caches = core._caches
    cdef const int64_t* row_times
    cdef const int64_t* order = NULL
    cdef const int64_t[::1] sorted_times
    cdef const int64_t[::1] sort_order
    if (out.shape[0] != n_rows or out.shape[1] != 7 or ok.shape[0] != n_rows
            or stamps.shape[0] != n_rows):
        raise ValueError("batch_lookup: out must be (N, 7), stamps and ok (N,) for N times")
    ok[:] = 0
    target_id = core._frame(target_frame)
    source_id = core._frame(source_frame)
    if target_id < 0 or source_id < 0 or target_id == source_id:
        return -1
    planned = _bplan_side(caches, source_id, 0, target_id, src_links, &ns, &top,
                          &src_early) == 0
    if planned and not src_early:
        planned = _bplan_side(caches, target_id, top, source_id, tgt_links, &nt, &frame,
                              &tgt_early) == 0
        if planned and not tgt_early and frame != top:
            planned = False  # disconnected: the scalar walk reports it
    if planned and n_rows:
        row_times = &times[0]
        if n_rows >= _SORT_ROWS and not _nondecreasing(row_times, n_rows):
            # The kernel's cursor and per-interval constants pay off on sorted times: walk
            # them sorted (numpy's argsort) and write each row back to its place.
            arr = np.asarray(times)
            sort_order = np.argsort(arr, kind="quicksort").astype(np.int64, copy=False)
            sorted_times = arr.take(sort_order)
            row_times = &sorted_times[0]
            order = &sort_order[0]
        answered = _bsplit(src_links, ns, src_early, tgt_links, nt, tgt_early,
                           row_times, order, n_rows, &out[0, 0], &ok[0], vector_sin)
    if answered == n_rows:
        return answered
    for r in range(n_rows):
        if ok[r]:
            continue
        used = times[r]
        err = core._walk(target_id, source_id, &used, &out[r, 0], &where)
        if err == NO_ERROR:
            stamps[r] = used
            ok[r] = 1
            answered += 1
    return answered


# ----- per-point tf2 math for sensor data (issue 12: laser projection)


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
