# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""Compiled heart of :class:`tfbus.core.BufferCore`: link storage, insert and the walk.

Semantics are tf2's (geometry2 0.7.6); every rule here is a transcription of the tf2 C++
named next to it, and the arithmetic is done in the same order as tf2, in IEEE doubles
with no fused multiply-add, so results are bit-for-bit tf2's (checked by the
conformance corpus, ``tests/test_conformance.py``).

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

* :class:`CoreBase` — the frame table and the hot paths of ``BufferCore``:
  ``_insert_code`` (``BufferCore::setTransformImpl``), ``_insert_many`` (the same over a
  batch), ``_cwalk`` (``walkToTopParent`` with ``TransformAccum``) and
  ``_ccommon_time`` (``getLatestCommonTime``). Error *messages* are built in Python by
  ``tfbus.core`` from the codes returned here.
"""

import numpy as np

from libc.math cimport acos, fabs, sin, sqrt
from libc.stdint cimport INT64_MAX, int32_t, int64_t
from libc.string cimport memcpy, memmove

from tfbus.messages import TransformStamped

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
        cdef double r, s, dot, c, theta, d, s0, s1
        cdef double bqx, bqy, bqz, bqw
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
                    # tf2 slerp (Quaternion.h slerp / angleShortestPath).
                    bqx = b[3]
                    bqy = b[4]
                    bqz = b[5]
                    bqw = b[6]
                    dot = a[3] * bqx + a[4] * bqy + a[5] * bqz + a[6] * bqw
                    if dot < 0.0:
                        dot = -dot
                        bqx = -bqx
                        bqy = -bqy
                        bqz = -bqz
                        bqw = -bqw
                    c = dot / sqrt(
                        (a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
                        * (bqx * bqx + bqy * bqy + bqz * bqz + bqw * bqw)
                    )
                    out[0] = s * a[0] + r * b[0]
                    out[1] = s * a[1] + r * b[1]
                    out[2] = s * a[2] + r * b[2]
                    # tf2Acos clamps its argument to [-1, 1]: a cosine that rounds above
                    # 1 is a zero angle, for which tf2 returns the older rotation as is.
                    if c >= 1.0:
                        out[3] = a[3]
                        out[4] = a[4]
                        out[5] = a[5]
                        out[6] = a[6]
                        return G_OK
                    theta = acos(c)  # NaN only for NaN input, as in tf2
                    d = 1.0 / sin(theta)
                    s0 = sin(s * theta)
                    s1 = sin(r * theta)
                    out[3] = (a[3] * s0 + bqx * s1) * d
                    out[4] = (a[4] * s0 + bqy * s1) * d
                    out[5] = (a[5] * s0 + bqz * s1) * d
                    out[6] = (a[6] * s0 + bqw * s1) * d
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
    """``acc = link ∘ acc`` (tf2 ``TransformAccum::accum``: ``t = quatRotate(q_link, t) +
    t_link``, ``q = q_link ⊗ q``), in tf2's evaluation order."""
    cdef double ax = acc[0], ay = acc[1], az = acc[2]
    cdef double aqx = acc[3], aqy = acc[4], aqz = acc[5], aqw = acc[6]
    cdef double x = st[0], y = st[1], z = st[2]
    cdef double qx = st[3], qy = st[4], qz = st[5], qw = st[6]
    cdef double tx = qw * ax + qy * az - qz * ay
    cdef double ty = qw * ay + qz * ax - qx * az
    cdef double tz = qw * az + qx * ay - qy * ax
    cdef double tw = -qx * ax - qy * ay - qz * az
    acc[0] = -tw * qx + tx * qw - ty * qz + tz * qy + x
    acc[1] = -tw * qy + ty * qw - tz * qx + tx * qz + y
    acc[2] = -tw * qz + tz * qw - tx * qy + ty * qx + z
    acc[3] = qw * aqx + qx * aqw + qy * aqz - qz * aqy
    acc[4] = qw * aqy + qy * aqw + qz * aqx - qx * aqz
    acc[5] = qw * aqz + qz * aqw + qx * aqy - qy * aqx
    acc[6] = qw * aqw - qx * aqx - qy * aqy - qz * aqz


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


cdef class CoreBase:
    """Frame table and hot paths of :class:`tfbus.core.BufferCore` (which subclasses it).

    Attributes (for ``tfbus.core`` only): ``_frame_ids`` (frame id → int id; 0 is tf2's
    ``NO_PARENT``), ``_frame_names`` (int id → frame id), ``_caches`` (int id → link or
    None), ``_authority`` (int id → authority of its last stored transform) and
    ``_generation`` (bumped by every insert attempt and by ``clear``).
    """

    cdef public dict _frame_ids
    cdef public list _frame_names
    cdef public list _caches
    cdef public dict _authority
    cdef public long long _generation
    cdef int64_t _cache_ns

    def __cinit__(self, *args, **kwargs):
        self._frame_ids = {"NO_PARENT": 0}
        self._frame_names = ["NO_PARENT"]
        self._caches = [None]
        self._authority = {}
        self._generation = 0
        self._cache_ns = 0

    def _set_cache_time_ns(self, ns):
        """Cache time (ns) given to links created from now on."""
        self._cache_ns = min(ns, INT64_MAX)

    cdef object _register(self, str frame_id):
        cdef object fid = len(self._frame_names)
        self._frame_ids[frame_id] = fid
        self._frame_names.append(frame_id)
        self._caches.append(None)
        return fid

    # ------------------------------------------------------------------ insert

    cdef int _insert_one(self, object ts, str authority, bint is_static,
                         set touched) except -1:
        """``BufferCore::setTransformImpl``: validate, register frames, store. Returns the
        cache's OK / OLD_DATA / REPEATED_DATA; raises InvalidArgumentException (through
        ``self._reject``) for a malformed transform and TypeError / ValueError for
        something that is not shaped like a TransformStamped."""
        cdef object header, child, parent, tf, tr, rot, stamp_obj
        cdef object cid, pid, cache
        cdef double v[7]
        cdef double norm2
        cdef int64_t stamp
        cdef int code
        if isinstance(ts, tuple) and len(<tuple>ts) == 3:
            header = (<tuple>ts)[0]
            child = (<tuple>ts)[1]
            tf = (<tuple>ts)[2]
        else:
            header, child, tf = ts
        if isinstance(tf, tuple) and len(<tuple>tf) == 2:
            tr = (<tuple>tf)[0]
            rot = (<tuple>tf)[1]
        else:
            tr, rot = tf
        if not (isinstance(tr, tuple) and len(<tuple>tr) == 3):
            tr = tuple(tr)
            if len(<tuple>tr) != 3:
                raise ValueError(f"transform.translation must have 3 values, got {len(tr)}")
        if not (isinstance(rot, tuple) and len(<tuple>rot) == 4):
            rot = tuple(rot)
            if len(<tuple>rot) != 4:
                raise ValueError(f"transform.rotation must have 4 values, got {len(rot)}")
        parent = header.frame_id
        if not isinstance(parent, str):
            raise TypeError(f"header.frame_id must be a str, got {type(parent).__name__}")
        if not isinstance(child, str):
            raise TypeError(f"child_frame_id must be a str, got {type(child).__name__}")
        if len(<str>parent) and (<str>parent)[0] == "/":
            parent = (<str>parent)[1:]
        if len(<str>child) and (<str>child)[0] == "/":
            child = (<str>child)[1:]
        v[0] = (<tuple>tr)[0]
        v[1] = (<tuple>tr)[1]
        v[2] = (<tuple>tr)[2]
        v[3] = (<tuple>rot)[0]
        v[4] = (<tuple>rot)[1]
        v[5] = (<tuple>rot)[2]
        v[6] = (<tuple>rot)[3]
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
            self._reject(parent, child, (<tuple>tr) + (<tuple>rot), authority)
            raise AssertionError("_reject returned")  # pragma: no cover
        stamp_obj = header.stamp._ns
        stamp = stamp_obj
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
        code = (<Link>cache).c_insert(stamp, pid, v)
        if code == C_OK:
            self._authority[cid] = authority
            if touched is not None:
                touched.add(child)
                touched.add(parent)
        else:
            self._refused(code, child, stamp_obj, authority)
        return code

    def _insert_code(self, ts, str authority, bint is_static):
        """Store one transform; returns ``OK``, ``OLD_DATA`` or ``REPEATED_DATA`` (refusals
        are reported through ``self._refused``). Raises as ``BufferCore.set_transform``."""
        return self._insert_one(ts, authority, is_static, None)

    def _insert_many(self, transforms, str authority, bint is_static, set touched=None):
        """Store every :class:`~tfbus.messages.TransformStamped` of ``transforms``; one bad
        item never stops the others.

        Returns ``(stored, refused, errors)``: counts, and ``[(index, exception)]`` for
        items that raised (InvalidArgumentException for an invalid transform, TypeError
        for an item that is not a TransformStamped, TypeError / ValueError / OverflowError
        for badly typed fields). The stripped child and parent frame ids of every stored
        transform are added to ``touched`` when it is a set.
        """
        cdef Py_ssize_t stored = 0, refused = 0, i = 0
        cdef list errors = []
        cdef int code
        for ts in transforms:
            try:
                if not isinstance(ts, TransformStamped):
                    raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                code = self._insert_one(ts, authority, is_static, touched)
            except Exception as exc:
                errors.append((i, exc))
            else:
                if code == C_OK:
                    stored += 1
                else:
                    refused += 1
            i += 1
        return stored, refused, errors

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

    def _cwalk(self, int target_id, int source_id, int64_t time):
        """tf2 ``walkToTopParent`` with ``TransformAccum``: the transform mapping source
        coordinates into target coordinates at ``time`` (0 = latest common time).

        Returns ``(NO_ERROR, 7-tuple, time used)``, ``(EXTRAPOLATION_ERROR, id of the
        frame whose link had no data, time)``, ``(CONNECTIVITY_ERROR, None, 0)`` or
        ``(LOOKUP_ERROR, None, 0)`` (a loop).
        """
        cdef list caches = self._caches
        cdef double src[7]
        cdef double tgt[7]
        cdef int top = 0, frame = 0, src_failed_at = 0
        cdef int outcome, err
        cdef bint failed
        cdef double sx, sy, sz, sqx, sqy, sqz, sqw, gx, gy, gz
        cdef double iqx, iqy, iqz, iqw, vx, vy, vz, tx, ty, tz, tw
        if source_id == target_id:
            return NO_ERROR, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), time
        if time == 0:
            err = self._common(target_id, source_id, &time)
            if err:
                return err, None, 0

        # Source side: source -> top. A failure here is only remembered: the path may
        # still close below it (only links between the two frames must be valid).
        outcome = _climb(caches, source_id, 0, target_id, time, src, &top)
        if outcome == CLIMB_EARLY:  # TargetParentOfSource
            return NO_ERROR, (src[0], src[1], src[2], src[3], src[4], src[5], src[6]), time
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR, None, 0
        failed = outcome == CLIMB_FAILED
        if failed:
            src_failed_at = top

        # Target side: target -> top. A failure here is reported at once.
        outcome = _climb(caches, target_id, top, source_id, time, tgt, &frame)
        if outcome == CLIMB_FAILED:
            return EXTRAPOLATION_ERROR, frame, time
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR, None, 0
        if outcome == CLIMB_EARLY:  # SourceParentOfTarget: the source side is unused
            _identity(src)
        elif frame != top:
            if failed:
                return EXTRAPOLATION_ERROR, src_failed_at, time
            return CONNECTIVITY_ERROR, None, 0

        # FullPath: inv(target -> top) ∘ (source -> top), inv = (conj q, conj q * (-t)).
        sx, sy, sz, sqx, sqy, sqz, sqw = src[0], src[1], src[2], src[3], src[4], src[5], src[6]
        gx, gy, gz = tgt[0], tgt[1], tgt[2]
        iqx, iqy, iqz, iqw = -tgt[3], -tgt[4], -tgt[5], tgt[6]
        # conj(q) applied to (s - g): quatRotate(q*, s) + quatRotate(q*, -g)
        vx, vy, vz = sx - gx, sy - gy, sz - gz
        tx = iqw * vx + iqy * vz - iqz * vy
        ty = iqw * vy + iqz * vx - iqx * vz
        tz = iqw * vz + iqx * vy - iqy * vx
        tw = -iqx * vx - iqy * vy - iqz * vz
        return (
            NO_ERROR,
            (
                -tw * iqx + tx * iqw - ty * iqz + tz * iqy,
                -tw * iqy + ty * iqw - tz * iqx + tx * iqz,
                -tw * iqz + tz * iqw - tx * iqy + ty * iqx,
                iqw * sqx + iqx * sqw + iqy * sqz - iqz * sqy,
                iqw * sqy + iqy * sqw + iqz * sqx - iqx * sqz,
                iqw * sqz + iqz * sqw + iqx * sqy - iqy * sqx,
                iqw * sqw - iqx * sqx - iqy * sqy - iqz * sqz,
            ),
            time,
        )


# ===== batched lookups (issue 12) =====
#
# ``batch_walk`` answers ``lookup_transform`` for many times at once. The path between
# the two frames is resolved once (the same climbs as ``_cwalk``, by each link's parent);
# then every time is gathered and accumulated along it in C, in ``_cwalk``'s arithmetic
# order, so a row is bit-for-bit the single lookup's (only the slerp angle and 1/sin of
# an interval are reused between the times that fall in it). Rows the plan cannot answer exactly
# (time 0, a gather that fails, a link with several parents, a span >= 2**53 ns) are
# flagged and answered by the scalar walk in ``tfbus.batch``, which also raises tf2's
# exception for them: the fast path never has to reproduce an error.

from cpython.mem cimport PyMem_Free, PyMem_Malloc
from libc.string cimport memset

cdef struct _BLink:
    const int64_t* st
    const double* va
    Py_ssize_t head
    Py_ssize_t tail
    double sv[7]  # a static link's value
    bint is_static
    bint check_only  # gathered (must succeed) but not accumulated: tf2's early exit
    # Cache of the last interpolation interval [ci - 1, ci]: its slerp angle is reused.
    Py_ssize_t ci
    bint zero_angle
    double theta
    double d
    double bq[4]


cdef inline int _bgather(_BLink* L, int64_t t, double* out) noexcept nogil:
    """``TimeCache::c_gather`` for a time != 0 on a single-parent link: 1 with ``out``
    set, 0 when tf2's gather would fail, 2 when the row needs the scalar path."""
    cdef Py_ssize_t head = L.head, tail = L.tail, i, i0
    cdef const int64_t* st = L.st
    cdef const double* a
    cdef const double* b
    cdef int64_t t0, span
    cdef double r, s, dot, c, s0, s1, th
    if L.is_static:
        memcpy(out, L.sv, 7 * sizeof(double))
        return 1
    if tail == head:
        return 0
    if t == st[tail - 1]:
        memcpy(out, &L.va[(tail - 1) * 7], 7 * sizeof(double))
        return 1
    if tail - head == 1 or t > st[tail - 1]:
        return 0
    i = L.ci
    if not (i > head and i < tail and st[i - 1] < t and t <= st[i]):
        i = _bisect_left(st, t, head, tail)
    if st[i] == t:
        memcpy(out, &L.va[i * 7], 7 * sizeof(double))
        return 1
    if i == head:
        return 0
    i0 = i - 1
    a = &L.va[i0 * 7]
    t0 = st[i0]
    span = st[i] - t0
    if span >= EXACT_SPAN:
        return 2
    if i != L.ci:
        # tf2 slerp (Quaternion.h slerp / angleShortestPath), as TimeCache.c_gather.
        b = &L.va[i * 7]
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
        c = dot / sqrt(
            (a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
            * (L.bq[0] * L.bq[0] + L.bq[1] * L.bq[1] + L.bq[2] * L.bq[2]
               + L.bq[3] * L.bq[3])
        )
        L.zero_angle = c >= 1.0
        if not L.zero_angle:
            L.theta = acos(c)
            L.d = 1.0 / sin(L.theta)
        L.ci = i
    b = &L.va[i * 7]
    r = <double>(t - t0) / <double>span
    s = 1.0 - r
    out[0] = s * a[0] + r * b[0]
    out[1] = s * a[1] + r * b[1]
    out[2] = s * a[2] + r * b[2]
    if L.zero_angle:
        out[3] = a[3]
        out[4] = a[4]
        out[5] = a[5]
        out[6] = a[6]
        return 1
    th = L.theta
    s0 = sin(s * th)
    s1 = sin(r * th)
    out[3] = (a[3] * s0 + L.bq[0] * s1) * L.d
    out[4] = (a[4] * s0 + L.bq[1] * s1) * L.d
    out[5] = (a[5] * s0 + L.bq[2] * s1) * L.d
    out[6] = (a[6] * s0 + L.bq[3] * s1) * L.d
    return 1


cdef inline void _bfull(const double* src, const double* tgt, double* out) noexcept nogil:
    """``_cwalk``'s FullPath step, same order: inv(target -> top) ∘ (source -> top)."""
    cdef double sqx = src[3], sqy = src[4], sqz = src[5], sqw = src[6]
    cdef double iqx = -tgt[3], iqy = -tgt[4], iqz = -tgt[5], iqw = tgt[6]
    cdef double vx = src[0] - tgt[0], vy = src[1] - tgt[1], vz = src[2] - tgt[2]
    cdef double tx = iqw * vx + iqy * vz - iqz * vy
    cdef double ty = iqw * vy + iqz * vx - iqx * vz
    cdef double tz = iqw * vz + iqx * vy - iqy * vx
    cdef double tw = -iqx * vx - iqy * vy - iqz * vz
    out[0] = -tw * iqx + tx * iqw - ty * iqz + tz * iqy
    out[1] = -tw * iqy + ty * iqw - tz * iqx + tx * iqz
    out[2] = -tw * iqz + tz * iqw - tx * iqy + ty * iqx
    out[3] = iqw * sqx + iqx * sqw + iqy * sqz - iqz * sqy
    out[4] = iqw * sqy + iqy * sqw + iqz * sqx - iqx * sqz
    out[5] = iqw * sqz + iqz * sqw + iqx * sqy - iqy * sqx
    out[6] = iqw * sqw - iqx * sqx - iqy * sqy - iqz * sqz


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
        if n[0] >= C_MAX_DEPTH:
            return 1
        L = &links[n[0]]
        memset(L, 0, sizeof(_BLink))
        L.ci = -1
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


def batch_walk(CoreBase core, int target_id, int source_id, const int64_t[::1] times,
               double[:, ::1] out, signed char[::1] ok):
    """Many ``_cwalk``s at once (tfbus.batch's fast path; ``target_id != source_id``).

    For each row r with ``ok[r] == 1`` on return, ``out[r]`` is the transform (tx, ty,
    tz, qx, qy, qz, qw) mapping source into target at ``times[r]``, bit-for-bit what
    ``_cwalk`` returns. Rows left at 0 must be answered by ``_cwalk`` (time 0, data
    missing at that time, multi-parent links, a disconnected or looping tree).
    Returns the number of rows answered. The per-time loop runs without the GIL, so two
    threads may each take a slice of the rows; the buffer must not be written meanwhile
    (BufferCore is single-threaded; tfbus.batch waits for its worker).
    """
    cdef list caches = core._caches
    cdef Py_ssize_t n_rows = times.shape[0], r
    cdef _BLink* src_links
    cdef _BLink* tgt_links
    cdef int ns = 0, nt = 0, top = 0, frame = 0, k, code
    cdef bint src_early = False, tgt_early = False, good
    cdef double acc_s[7]
    cdef double acc_t[7]
    cdef double st[7]
    cdef Py_ssize_t answered = 0
    cdef int64_t t
    if out.shape[0] != n_rows or out.shape[1] != 7 or ok.shape[0] != n_rows:
        raise ValueError("batch_walk: out must be (N, 7) and ok (N,) for N times")
    ok[:] = 0
    if n_rows == 0 or target_id == source_id:
        return 0
    src_links = <_BLink*>PyMem_Malloc(2 * (C_MAX_DEPTH + 1) * sizeof(_BLink))
    if src_links == NULL:
        raise MemoryError()
    tgt_links = src_links + (C_MAX_DEPTH + 1)
    try:
        if _bplan_side(caches, source_id, 0, target_id, src_links, &ns, &top, &src_early):
            return 0
        if not src_early:
            if _bplan_side(caches, target_id, top, source_id, tgt_links, &nt, &frame,
                           &tgt_early):
                return 0
            if not tgt_early and frame != top:
                return 0  # disconnected: the scalar walk reports it
        with nogil:
            for r in range(n_rows):
                t = times[r]
                if t == 0:
                    continue
                good = True
                _identity(acc_s)
                for k in range(ns):
                    code = _bgather(&src_links[k], t, st)
                    if code != 1:
                        good = False
                        break
                    if src_links[k].check_only:
                        continue
                    if k == 0:
                        memcpy(acc_s, st, 7 * sizeof(double))
                    else:
                        _accumulate(acc_s, st)
                if not good:
                    continue
                if src_early:
                    memcpy(&out[r, 0], acc_s, 7 * sizeof(double))
                    ok[r] = 1
                    answered += 1
                    continue
                _identity(acc_t)
                for k in range(nt):
                    code = _bgather(&tgt_links[k], t, st)
                    if code != 1:
                        good = False
                        break
                    if tgt_links[k].check_only:
                        continue
                    if k == 0:
                        memcpy(acc_t, st, 7 * sizeof(double))
                    else:
                        _accumulate(acc_t, st)
                if not good:
                    continue
                if tgt_early:
                    _identity(acc_s)
                _bfull(acc_s, acc_t, &out[r, 0])
                ok[r] = 1
                answered += 1
    finally:
        PyMem_Free(src_links)
    return answered
