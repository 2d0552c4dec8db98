# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""Compiled link storage of the core: :class:`TimeCache` (a dynamic link) and
:class:`StaticCache` (a static one), twins of :mod:`tfbus.core._pycache`.

* :class:`TimeCache` — a dynamic link (``tf2/src/cache.cpp``):

  - ``insert``: refused as TF_OLD_DATA iff ``newest > stamp + cache_time``; refused as
    TF_REPEATED_DATA if a sample with the same stamp exists (the first one wins, whatever
    its values or parent) — except, with ``replace_repeated``, a sample at the newest
    stamp, whose values and parent it replaces; otherwise stored, then every sample older than
    ``newest - cache_time`` is dropped (``TimeCache::insertData`` / ``pruneList``).
  - ``gather(t)``: t = 0 gives the newest sample; a single sample answers only at its
    exact stamp; otherwise t must lie in [oldest, newest] (no extrapolation, not even
    1 ns); between two samples with the same parent the result is interpolated (linear
    translation, tf2 slerp rotation, ratio from integer ns), between samples with
    different parents the older one is used (``findClosest`` / ``getData`` /
    ``interpolate``).
  - Storage: C buffers (``PyMem_RawRealloc``, seen by tracemalloc) of ``cap`` int64
    stamps (ns) and ``cap`` rows of 7 doubles (tx, ty, tz, qx, qy, qz, qw), live samples
    sorted by stamp in ``[head, tail)``, plus a ``cap`` int32 parent id per sample only
    once the link has had two different parents: 64 bytes per sample. Capacity doubles
    up to 256 samples (a new link's first samples cost what later ones do: 5 reallocations
    for its first 200) and grows by 1/16 beyond (~68 bytes per sample with the slack).

* :class:`StaticCache` — a static link (``tf2/src/static_cache.cpp``): one value, valid
  at every time; each insert overwrites it; its latest stamp is 0.

* ``format_sec`` and tf2's extrapolation details (``cache.cpp``
  ``createExtrapolationException1/2/3``).
"""

__all__ = [
    "OK",
    "OLD_DATA",
    "REPEATED_DATA",
    "Link",
    "StaticCache",
    "TimeCache",
    "format_sec",
]

import numpy as np

from cpython.mem cimport PyMem_RawFree, PyMem_RawMalloc, PyMem_RawRealloc
from libc.stdint cimport INT64_MAX, int32_t, int64_t
from libc.string cimport memcpy, memmove

from tfbus.core._cmath cimport EXACT_SPAN, _bisect_left, _search_left, _slerp

cdef extern from *:
    """
    /* The last interval found is shared by every link (read and written with the GIL
       held); a free-threaded build does not keep it (each gather searches). */
    #ifdef Py_GIL_DISABLED
    #define TFBUS_FOUND_HINT 0
    #else
    #define TFBUS_FOUND_HINT 1
    #endif
    """
    const bint TFBUS_FOUND_HINT

cdef Py_ssize_t _found = 0
"""How many samples from its link's newest one (1: the newest) the newer sample of the
interval the last ``TimeCache.c_gather`` search found lies: a hint for the next search,
checked against the samples before use."""


# insert outcomes (tf2 cache insertData)
OK = 0
OLD_DATA = 1
REPEATED_DATA = 2


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

    cdef int c_pick(self, int64_t time, int mode, int64_t before, int64_t after, double* out,
                    int* parent, int64_t* used) except -1:
        """``c_gather`` under a lookup policy (:mod:`tfbus.core.policy`); ``used`` = the
        stamp of the sample used (the time itself for an interpolation or a static
        link)."""
        used[0] = time
        return self.c_gather(time, out, parent)

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
        replace_repeated: a sample whose stamp equals the newest one replaces it (values
            and parent) instead of being refused as TF_REPEATED_DATA.
    """


    def __cinit__(self, cache_time_ns, replace_repeated=False):
        self.cache_time_ns = min(cache_time_ns, INT64_MAX)
        self.replace_repeated = replace_repeated
        self._st = NULL
        self._va = NULL
        self._pa = NULL
        self._cap = 0
        self._head = 0
        self._tail = 0
        self._parent = 0
        self._resize(MIN_CAPACITY)

    def __dealloc__(self):
        PyMem_RawFree(self._st)
        PyMem_RawFree(self._va)
        PyMem_RawFree(self._pa)

    @property
    def is_static(self):
        """False: a dynamic link."""
        return False

    cdef int _resize(self, Py_ssize_t cap) except -1:
        """Capacity ``cap`` samples, keeping the first ``min(cap, old capacity)`` of each
        buffer (the live samples must start at 0); MemoryError leaves the link as it was."""
        cdef int64_t* st = <int64_t*>PyMem_RawRealloc(self._st, cap * sizeof(int64_t))
        if st == NULL:
            raise MemoryError(f"cannot grow a link to {cap} samples")
        self._st = st
        cdef double* va = <double*>PyMem_RawRealloc(self._va, cap * 7 * sizeof(double))
        if va == NULL:
            raise MemoryError(f"cannot grow a link to {cap} samples")
        self._va = va
        cdef int32_t* pa
        if self._pa != NULL:
            pa = <int32_t*>PyMem_RawRealloc(self._pa, cap * sizeof(int32_t))
            if pa == NULL:
                raise MemoryError(f"cannot grow a link to {cap} samples")
            self._pa = pa
        self._cap = cap
        return 0

    cdef int _alloc_parents(self, Py_ssize_t cap) except -1:
        cdef Py_ssize_t k
        cdef int32_t* pa = <int32_t*>PyMem_RawMalloc(cap * sizeof(int32_t))
        if pa == NULL:
            raise MemoryError(f"cannot store parents of {cap} samples")
        for k in range(cap):
            pa[k] = self._parent
        self._pa = pa
        return 0

    def __len__(self):
        return self._tail - self._head

    def nbytes(self):
        """Bytes held by this link's sample buffers (capacity, not just live samples)."""
        return self._cap * (sizeof(int64_t) + 7 * sizeof(double) + (
            sizeof(int32_t) if self._pa != NULL else 0))

    def stamps(self):
        """Stored stamps, oldest first, ``(N,) int64`` nanoseconds (a copy)."""
        cdef Py_ssize_t n = self._tail - self._head
        out = np.empty(n, dtype=np.int64)
        cdef int64_t[::1] o = out
        if n:
            memcpy(&o[0], &self._st[self._head], n * sizeof(int64_t))
        return out

    def values(self):
        """Stored samples, oldest first, ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz,
        qw) (a copy)."""
        cdef Py_ssize_t n = self._tail - self._head
        out = np.empty((n, 7), dtype=np.float64)
        cdef double[:, ::1] o = out
        if n:
            memcpy(&o[0, 0], &self._va[self._head * 7], n * 7 * sizeof(double))
        return out

    def latest_stamp(self):
        """Newest stamp in ns, 0 when empty (``getLatestTimestamp``)."""
        return self._st[self._tail - 1] if self._tail != self._head else 0

    def oldest_stamp(self):
        """Oldest stamp in ns, 0 when empty (``getOldestTimestamp``)."""
        return self._st[self._head] if self._tail != self._head else 0

    def clear(self):
        """Drop every sample (``clearList``); capacity is released."""
        PyMem_RawFree(self._pa)
        self._pa = NULL
        self._head = 0
        self._tail = 0
        self._resize(MIN_CAPACITY)

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
                    if self.replace_repeated and pos == tail - 1:
                        return self._replace_newest(parent, v)
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
        # A steady stream drops one sample per insert: the next one is tried before the
        # bisection (the same index: the first stamp >= horizon; st[tail - 1] is one).
        horizon = st[tail - 1] - self.cache_time_ns
        if st[head] < horizon:
            if st[head + 1] >= horizon:
                self._head = head + 1
            else:
                self._head = _bisect_left(st, horizon, head + 1, tail)
        return C_OK

    cdef int _replace_newest(self, int parent, const double* v) except -1:
        """The newest sample takes ``v`` and ``parent`` (its stamp kept; nothing to prune:
        the newest stamp is unchanged)."""
        cdef Py_ssize_t pos = self._tail - 1
        memcpy(&self._va[pos * 7], v, 7 * sizeof(double))
        if self._pa != NULL:
            self._pa[pos] = parent
        elif parent != self._parent:
            if pos == self._head:  # the only sample: the link's one parent changes
                self._parent = parent
            else:
                self._alloc_parents(self._cap)
                self._pa[pos] = parent
        return C_OK

    cdef int _make_room(self) except -1:
        """Storage is full at the top: slide the live samples down if at least 1/16 of the
        capacity is free below them, else grow: double up to 256 samples, then by 1/16
        (amortised O(1) inserts; a steady stream settles at ~7 % slack, i.e. ~68 bytes per
        sample; a new link reaches 200 samples in 5 reallocations)."""
        cdef Py_ssize_t head = self._head, tail = self._tail, cap = self._cap
        cdef Py_ssize_t n = tail - head
        if head > 0:
            memmove(self._st, &self._st[head], n * sizeof(int64_t))
            memmove(self._va, &self._va[head * 7], n * 7 * sizeof(double))
            if self._pa != NULL:
                memmove(self._pa, &self._pa[head], n * sizeof(int32_t))
            self._head = 0
            self._tail = n
        if head < cap // 16 or head == 0:
            self._resize(max(MIN_CAPACITY, n + max(n if n < GEOMETRIC_UP_TO else n // 16, 4)))
        return 0

    cdef int c_gather(self, int64_t time, double* out, int* parent) except -1:
        global _found
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
                # The interval the last search of any link found (counted from the
                # link's newest sample), if it holds the time: the links of a tree
                # published together share their stamps, so a walk finds each link after
                # the first in two compares; else a search (_search_left: bisect_left's
                # index, found from where the time would lie at a steady rate).
                i = tail - _found
                if not (i > head and i < tail and st[i - 1] < time and time <= st[i]):
                    i = _search_left(st, time, head, tail)
                    if TFBUS_FOUND_HINT:
                        _found = tail - i
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


    cdef int c_pick(self, int64_t time, int mode, int64_t before, int64_t after, double* out,
                    int* parent, int64_t* used) except -1:
        # A lookup policy's sample (tfbus.core.policy): mode 1 nearest within before (=
        # after), 2 the edge sample within before / after beyond the data, 3 the last at
        # or before the time. Where it picks none: tf2's gather at the time.
        cdef Py_ssize_t head = self._head, tail = self._tail, k = -1
        cdef const int64_t* st = self._st
        cdef int64_t newest, oldest, d
        if tail != head and time != 0:
            newest = st[tail - 1]
            oldest = st[head]
            if mode == 3:
                if time >= newest:
                    k = tail - 1
                elif time >= oldest:
                    k = _bisect_left(st, time, head, tail)
                    if st[k] != time:
                        k -= 1
            elif mode == 1:
                if time >= newest:
                    k = tail - 1
                elif time <= oldest:
                    k = head
                else:
                    k = _bisect_left(st, time, head, tail)
                    if st[k] != time and time - st[k - 1] <= st[k] - time:
                        k -= 1
                d = st[k] - time
                if d > before or -d > before:
                    k = -1
            elif time > newest:
                if time - newest <= after:
                    k = tail - 1
            elif time < oldest and oldest - time <= before:
                k = head
            if k >= 0:
                parent[0] = self._parent if self._pa == NULL else self._pa[k]
                memcpy(out, &self._va[k * 7], 7 * sizeof(double))
                used[0] = st[k]
                return G_OK
        used[0] = time
        return self.c_gather(time, out, parent)


cdef class StaticCache(Link):
    """The single value of a static link, valid at every time (``tf2::StaticCache``).

    ``insert`` always overwrites (last wins, stamp ignored); ``latest()`` reports stamp 0,
    so static links never limit tf2's latest common time; ``clear()`` keeps the value.
    """


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
