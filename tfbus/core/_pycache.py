"""Link storage in pure Python: :class:`TimeCache` (a dynamic link, tf2
``tf2/src/cache.cpp``) and :class:`StaticCache` (``static_cache.cpp``), the twins of the
compiled :mod:`tfbus.core._ccache`, with the same storage (numpy arrays ``(cap,) int64``
stamps, ``(cap, 7) float64`` rows and, once a link has had two parents, ``(cap,) int32``
parent ids, the same growth policy: ``nbytes()`` agrees) and the same results bit for bit
(the compiled twin keeps the same arrays in C buffers).
"""

from __future__ import annotations

from bisect import bisect_left
from typing import Final

import numpy as np

from tfbus.core._pymath import (
    _F64,
    _I32,
    _I64,
    _IDENTITY,
    _INT64_MAX,
    Tf7,
    _cint,
    _int64,
    _seven,
    _slerp,
)

__all__ = [
    "OK",
    "OLD_DATA",
    "REPEATED_DATA",
    "Link",
    "StaticCache",
    "TimeCache",
    "format_sec",
]

# insert outcomes (tf2 cache insertData)
OK: Final = 0
OLD_DATA: Final = 1
REPEATED_DATA: Final = 2

# outcomes of CoreBase._cwalk / _ccommon_time (tf2_msgs::TF2Error)

_G_OK: Final = 0
_G_EMPTY: Final = 1  # no samples: tf2 gives an empty detail
_G_AT: Final = 2  # a single sample, at another time
_G_FUTURE: Final = 3
_G_PAST: Final = 4
# climb outcomes

_MIN_CAPACITY: Final = 8
_GEOMETRIC_UP_TO: Final = 256  # a link's capacity doubles below this many samples

# ---------------------------------------------------------------------- messages


def format_sec(ns: int) -> str:
    """A stamp as tf2 prints it in error messages: ``%.09f`` of ``(double)sec + 1e-9*nsec``
    (``ros::Time::toSec``)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    return "%.09f" % (float(sec) + 1e-9 * float(nsec))


def _detail(code: int, requested: int, known: int) -> str:
    """tf2's extrapolation detail for a failed gather (cache.cpp
    createExtrapolationException1/2/3, with their snprintf buffer sizes)."""
    if code == _G_AT:
        return (
            f"Lookup would require extrapolation at time {format_sec(requested)}, "
            f"but only time {format_sec(known)} is in the buffer"
        )[:115]
    if code == _G_FUTURE:
        return (
            f"Lookup would require extrapolation {format_sec(requested - known)}s into the "
            f"future.  Requested time {format_sec(requested)} but the latest data is at "
            f"time {format_sec(known)}"
        )[:162]
    if code == _G_PAST:
        return (
            f"Lookup would require extrapolation {format_sec(known - requested)}s into the "
            f"past.  Requested time {format_sec(requested)} but the earliest data is at "
            f"time {format_sec(known)}"
        )[:162]
    return ""

# ---------------------------------------------------------------------- links


class Link:
    """Common base of :class:`TimeCache` and :class:`StaticCache` (tf2 ``TimeCacheInterface``)."""

    __slots__ = ()

    def _c_gather(self, time: int) -> tuple[int, int, Tf7]:
        """``(gather code, parent id, values)``; values are meaningful only for G_OK."""
        return _G_EMPTY, 0, _IDENTITY

    def _c_latest(self) -> tuple[int, int]:
        """``(newest stamp, its parent id)``; ``(0, 0)`` when empty."""
        return 0, 0

    def _c_pick(self, time: int, mode: int, before: int, after: int) -> tuple[int, int, Tf7, int]:
        """``_c_gather`` under a lookup policy (:mod:`tfbus.core.policy`):
        ``(gather code, parent id, values, stamp of the sample used)``."""
        code, parent, v = self._c_gather(time)
        return code, parent, v, time

    def _c_insert(self, stamp: int, parent: int, v: Tf7) -> int:
        return OK

    def _c_known(self, code: int) -> int:
        return 0

    def gather(self, time: int) -> tuple[int, Tf7] | str:
        """The link's transform at ``time`` (ns; 0 = newest) as ``(parent id, values)``,
        ``values`` a 7-tuple (tx, ty, tz, qx, qy, qz, qw), or tf2's extrapolation detail
        string (possibly empty) when there is no data. A parent id of 0 (tf2's
        ``NO_PARENT``) is returned as is; callers treat it as a failure with an empty
        detail, like tf2's ``gather`` (tf2 ``TimeCache::getData``)."""
        t = _int64(time)
        code, parent, v = self._c_gather(t)
        if code != _G_OK:
            return _detail(code, t, self._c_known(code))
        return parent, v

    def latest(self) -> tuple[int, int]:
        """``(newest stamp ns, its parent id)``; ``(0, 0)`` when empty
        (``getLatestTimeAndParent``)."""
        return self._c_latest()

    def insert(self, stamp: int, parent: int, values: Tf7) -> int:
        """Store one sample (stamp ns, parent id, 7 floats); returns ``OK``, ``OLD_DATA``
        or ``REPEATED_DATA`` (tf2 ``insertData``).

        Raises:
            ValueError: not 7 values. TypeError: a value is not a real number.
            OverflowError: stamp or parent beyond the C integer range.
        """
        if len(values) != 7:
            raise ValueError(f"expected 7 values, got {len(values)}")
        v = _seven(values)
        return self._c_insert(_int64(stamp), _cint(parent), v)


class TimeCache(Link):
    """The time-indexed samples of one dynamic link (child frame → parent frame)
    (tf2 ``tf2/src/cache.cpp``).

    Args:
        cache_time_ns: how far back from the newest sample data is kept, nanoseconds
            (values beyond int64 keep everything).
        replace_repeated: a sample whose stamp equals the newest one replaces it (values
            and parent) instead of being refused as TF_REPEATED_DATA.

    Storage: ``(cap,) int64`` stamps and ``(cap, 7) float64`` rows, live samples sorted
    by stamp in ``[head, tail)``, plus ``(cap,) int32`` parent ids only once the link has
    had two different parents.
    """

    __slots__ = ("_cap", "_ct", "_head", "_pa", "_parent", "_replace", "_st", "_tail", "_va")

    _st: _I64
    _va: _F64
    _pa: _I32 | None

    def __init__(self, cache_time_ns: int, replace_repeated: bool = False) -> None:
        self._ct = _int64(min(cache_time_ns, _INT64_MAX))
        self._replace = bool(replace_repeated)
        self._alloc(_MIN_CAPACITY)
        self._head = 0
        self._tail = 0
        self._parent = 0
        self._pa = None

    @property
    def cache_time_ns(self) -> int:
        """How far back from the newest sample data is kept, ns (read-only)."""
        return self._ct

    @property
    def replace_repeated(self) -> bool:
        """Whether a sample at the newest stamp replaces it (read-only)."""
        return self._replace

    @property
    def is_static(self) -> bool:
        """False: a dynamic link."""
        return False

    def _alloc(self, cap: int) -> None:
        self._st = np.empty(cap, dtype=np.int64)
        self._va = np.empty((cap, 7), dtype=np.float64)
        self._cap = cap

    def _alloc_parents(self, cap: int) -> None:
        self._pa = np.full(cap, self._parent, dtype=np.int32)

    def __len__(self) -> int:
        return self._tail - self._head

    def nbytes(self) -> int:
        """Bytes held by this link's sample arrays (capacity, not just live samples)."""
        n = self._st.nbytes + self._va.nbytes
        return n + (self._pa.nbytes if self._pa is not None else 0)

    def stamps(self) -> _I64:
        """Stored stamps, oldest first, ``(N,) int64`` nanoseconds (a copy)."""
        return self._st[self._head : self._tail].copy()  # type: ignore[no-any-return]

    def values(self) -> _F64:
        """Stored samples, oldest first, ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz,
        qw) (a copy)."""
        return self._va[self._head : self._tail].copy()  # type: ignore[no-any-return]

    def latest_stamp(self) -> int:
        """Newest stamp in ns, 0 when empty (``getLatestTimestamp``)."""
        return int(self._st.item(self._tail - 1)) if self._tail != self._head else 0

    def oldest_stamp(self) -> int:
        """Oldest stamp in ns, 0 when empty (``getOldestTimestamp``)."""
        return int(self._st.item(self._head)) if self._tail != self._head else 0

    def clear(self) -> None:
        """Drop every sample (``clearList``); capacity is released."""
        self._alloc(_MIN_CAPACITY)
        self._head = 0
        self._tail = 0
        self._pa = None

    def _c_latest(self) -> tuple[int, int]:
        tail = self._tail
        if tail == self._head:
            return 0, 0
        pa = self._pa
        return int(self._st.item(tail - 1)), self._parent if pa is None else int(pa.item(tail - 1))

    def _c_known(self, code: int) -> int:
        # The stamp named by a gather failure: the newest one, or the oldest for G_PAST.
        if self._tail == self._head:
            return 0
        return int(self._st.item(self._head if code == _G_PAST else self._tail - 1))

    def _c_insert(self, stamp: int, parent: int, v: Tf7) -> int:
        # tf2 TimeCache::insertData, then pruneList.
        head = self._head
        tail = self._tail
        st = self._st
        if tail != head:
            newest = int(st.item(tail - 1))
            # newest > stamp + cache_time, without overflow (stamps are >= 0).
            if newest - self._ct > stamp:
                return OLD_DATA
            if stamp > newest:
                pos = tail
            else:
                pos = bisect_left(st, stamp, head, tail)
                if st.item(pos) == stamp:
                    if self._replace and pos == tail - 1:
                        return self._replace_newest(parent, v)
                    return REPEATED_DATA
        else:
            pos = tail
        if parent != self._parent and self._pa is None:
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
        va = self._va
        pa = self._pa
        if pos != tail:  # out-of-order insert: shift the newer samples up by one
            st[pos + 1 : tail + 1] = st[pos:tail]
            va[pos + 1 : tail + 1] = va[pos:tail]
            if pa is not None:
                pa[pos + 1 : tail + 1] = pa[pos:tail]
        st[pos] = stamp
        va[pos] = v
        if pa is not None:
            pa[pos] = parent
        tail += 1
        self._tail = tail
        # pruneList: drop samples older than newest - cache_time (strict comparison).
        horizon = int(st.item(tail - 1)) - self._ct
        if st.item(head) < horizon:
            self._head = bisect_left(st, horizon, head, tail)
        return OK

    def _replace_newest(self, parent: int, v: Tf7) -> int:
        """The newest sample takes ``v`` and ``parent`` (its stamp kept; nothing to prune:
        the newest stamp is unchanged)."""
        pos = self._tail - 1
        self._va[pos] = v
        pa = self._pa
        if pa is not None:
            pa[pos] = parent
        elif parent != self._parent:
            if pos == self._head:  # the only sample: the link's one parent changes
                self._parent = parent
            else:
                self._alloc_parents(self._cap)
                assert self._pa is not None
                self._pa[pos] = parent
        return OK

    def _make_room(self) -> None:
        """Storage is full at the top: slide the live samples down if at least 1/16 of the
        capacity is free below them, else grow: double up to 256 samples, then by 1/16
        (as the compiled core: the same capacities, ``nbytes()`` agrees)."""
        head, tail, cap = self._head, self._tail, self._cap
        n = tail - head
        if head >= cap // 16 and head > 0:
            self._st[:n] = self._st[head:tail]
            self._va[:n] = self._va[head:tail]
            if self._pa is not None:
                self._pa[:n] = self._pa[head:tail]
        else:
            grow = n if n < _GEOMETRIC_UP_TO else n // 16
            new_cap = max(_MIN_CAPACITY, n + max(grow, 4))
            old_st, old_va, old_pa = self._st, self._va, self._pa
            self._alloc(new_cap)
            self._st[:n] = old_st[head:tail]
            self._va[:n] = old_va[head:tail]
            if old_pa is not None:
                self._alloc_parents(new_cap)
                assert self._pa is not None
                self._pa[:n] = old_pa[head:tail]
        self._head = 0
        self._tail = n

    def _c_gather(self, time: int) -> tuple[int, int, Tf7]:
        # tf2 TimeCache::getData: findClosest, then interpolate (same parent) or the older
        # sample (different parents).
        head, tail = self._head, self._tail
        if tail == head:
            return _G_EMPTY, 0, _IDENTITY
        st = self._st
        pa = self._pa
        if time == 0:
            i = tail - 1
        else:
            newest = st.item(tail - 1)
            if time == newest:
                i = tail - 1
            elif tail - head == 1:
                return _G_AT, 0, _IDENTITY
            elif time > newest:
                return _G_FUTURE, 0, _IDENTITY
            else:
                i = bisect_left(st, time, head, tail)
                if st.item(i) != time:
                    if i == head:
                        return _G_PAST, 0, _IDENTITY
                    # Between samples i-1 (older) and i (newer).
                    i0 = i - 1
                    p0 = self._parent if pa is None else int(pa.item(i0))
                    a = self._va[i0].tolist()
                    if pa is not None and pa.item(i) != p0:
                        return _G_OK, p0, tuple(a)
                    b = self._va[i].tolist()
                    # TimeCache::interpolate; the ratio is correctly rounded from integer
                    # ns (int / int is, and so is double / double below 2**53).
                    t0 = int(st.item(i0))
                    r = (time - t0) / (int(st.item(i)) - t0)
                    s = 1.0 - r
                    qx, qy, qz, qw = _slerp(a[3], a[4], a[5], a[6], b[3], b[4], b[5], b[6], r)
                    return (
                        _G_OK,
                        p0,
                        (s * a[0] + r * b[0], s * a[1] + r * b[1], s * a[2] + r * b[2],
                         qx, qy, qz, qw),
                    )  # fmt: skip
        parent = self._parent if pa is None else int(pa.item(i))
        return _G_OK, parent, tuple(self._va[i].tolist())


    def _c_pick(self, time: int, mode: int, before: int, after: int) -> tuple[int, int, Tf7, int]:
        # A lookup policy's sample (tfbus.core.policy): mode 1 nearest within before (=
        # after), 2 the edge sample within before / after beyond the data, 3 the last at
        # or before the time. Where it picks none: tf2's gather at the time.
        head, tail = self._head, self._tail
        if tail != head and time != 0:
            st = self._st
            newest = int(st.item(tail - 1))
            oldest = int(st.item(head))
            k = -1
            if mode == 3:
                if time >= newest:
                    k = tail - 1
                elif time >= oldest:
                    k = bisect_left(st, time, head, tail)
                    if st.item(k) != time:
                        k -= 1
            elif mode == 1:
                if time >= newest:
                    k = tail - 1
                elif time <= oldest:
                    k = head
                else:
                    k = bisect_left(st, time, head, tail)
                    if st.item(k) != time and time - int(st.item(k - 1)) <= int(st.item(k)) - time:
                        k -= 1
                d = int(st.item(k)) - time
                if d > before or -d > before:
                    k = -1
            elif time > newest:
                if time - newest <= after:
                    k = tail - 1
            elif time < oldest and oldest - time <= before:
                k = head
            if k >= 0:
                pa = self._pa
                parent = self._parent if pa is None else int(pa.item(k))
                return _G_OK, parent, tuple(self._va[k].tolist()), int(st.item(k))
        code, parent, v = self._c_gather(time)
        return code, parent, v, time


class StaticCache(Link):
    """The single value of a static link, valid at every time (``tf2::StaticCache``,
    ``tf2/src/static_cache.cpp``).

    ``insert`` always overwrites (last wins, stamp ignored); ``latest()`` reports stamp 0,
    so static links never limit tf2's latest common time; ``clear()`` keeps the value.
    """

    __slots__ = ("_parent", "_stamp", "_v")

    def __init__(self) -> None:
        self._v: Tf7 = _IDENTITY
        self._parent = 0
        self._stamp = 0

    @property
    def is_static(self) -> bool:
        """True: a static link."""
        return True

    @property
    def cache_time_ns(self) -> int:
        """0: a static link keeps no history."""
        return 0

    def __len__(self) -> int:
        return 1

    def nbytes(self) -> int:
        """Bytes of sample storage (one row of 7 doubles)."""
        return 7 * 8

    def latest_stamp(self) -> int:
        """Always 0 (``StaticCache::getLatestTimestamp``)."""
        return 0

    def oldest_stamp(self) -> int:
        """Always 0 (``StaticCache::getOldestTimestamp``)."""
        return 0

    def stamp_sent(self) -> int:
        """Stamp (ns) of the last message that set this static value (informational)."""
        return self._stamp

    def clear(self) -> None:
        """No-op: ``BufferCore.clear()`` keeps static transforms, as in tf2."""

    def _c_latest(self) -> tuple[int, int]:
        return 0, self._parent

    def _c_insert(self, stamp: int, parent: int, v: Tf7) -> int:
        self._parent = parent
        self._v = v
        self._stamp = stamp
        return OK

    def _c_gather(self, time: int) -> tuple[int, int, Tf7]:
        return _G_OK, self._parent, self._v
