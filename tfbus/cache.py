"""Per-link transform storage: ``TimeCache`` (dynamic) and ``StaticCache`` (static).

Semantics are tf2's (geometry2 0.7.6, ``tf2/src/cache.cpp`` and ``static_cache.cpp``):

* ``insert``: refused as TF_OLD_DATA iff ``newest > stamp + cache_time``; refused as
  TF_REPEATED_DATA if a sample with the same stamp exists (the first one wins, whatever its
  values or parent); otherwise stored, then every sample older than
  ``newest - cache_time`` is dropped (``TimeCache::insertData`` / ``pruneList``).
* ``gather(t)``: t = 0 gives the newest sample; a single sample answers only at its exact
  stamp; otherwise t must lie in [oldest, newest] (no extrapolation, not even 1 ns);
  between two samples with the same parent the result is interpolated (linear
  translation, tf2 slerp rotation, ratio from integer ns), between samples with
  different parents the older one is used (``TimeCache::findClosest`` / ``getData`` /
  ``interpolate``).
* A static link holds one value, valid at every time; each insert overwrites it.

Storage of a dynamic link: contiguous numpy arrays — stamps ``(cap,) int64`` (ns) and
values ``(cap, 7) float64`` (tx, ty, tz, qx, qy, qz, qw) — holding the live samples
sorted by stamp in ``[head, tail)``, plus a parent id per sample only once the link has
had two different parents (64 bytes per sample otherwise). Lookups binary-search the
stamps through a ``memoryview`` (C ``bisect`` without numpy scalar overhead) and read a
row with ``struct``.
"""

from __future__ import annotations

import struct
from bisect import bisect_left
from math import acos, nan, sin, sqrt
from typing import Final

import numpy as np
import numpy.typing as npt

from tfbus._tf2math import Tf7

__all__ = ["OK", "OLD_DATA", "REPEATED_DATA", "StaticCache", "TimeCache", "format_sec"]

OK: Final = 0
OLD_DATA: Final = 1
REPEATED_DATA: Final = 2

_ROW = struct.Struct("7d")
_ROW_BYTES: Final = 56
_MIN_CAPACITY: Final = 8


def format_sec(ns: int) -> str:
    """A stamp as tf2 prints it in error messages: ``%.09f`` of ``(double)sec + 1e-9*nsec``
    (``ros::Time::toSec``)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    return "%.09f" % (float(sec) + 1e-9 * float(nsec))


def _extrapolation_at(requested: int, only: int) -> str:
    # cache.cpp createExtrapolationException1: snprintf into char[116].
    return (
        f"Lookup would require extrapolation at time {format_sec(requested)}, "
        f"but only time {format_sec(only)} is in the buffer"
    )[:115]


def _extrapolation_future(requested: int, latest: int) -> str:
    # cache.cpp createExtrapolationException2: snprintf into char[163].
    return (
        f"Lookup would require extrapolation {format_sec(requested - latest)}s into the future."
        f"  Requested time {format_sec(requested)} but the latest data is at time "
        f"{format_sec(latest)}"
    )[:162]


def _extrapolation_past(requested: int, earliest: int) -> str:
    # cache.cpp createExtrapolationException3: snprintf into char[163].
    return (
        f"Lookup would require extrapolation {format_sec(earliest - requested)}s into the past."
        f"  Requested time {format_sec(requested)} but the earliest data is at time "
        f"{format_sec(earliest)}"
    )[:162]


class TimeCache:
    """The time-indexed samples of one dynamic link (child frame → parent frame).

    Args:
        cache_time_ns: how far back from the newest sample data is kept, nanoseconds.
    """

    __slots__ = (
        "_cap",
        "_head",
        "_parent",
        "_parents",
        "_smv",
        "_stamps",
        "_tail",
        "_values",
        "_vmv",
        "cache_time_ns",
    )

    is_static: Final = False

    def __init__(self, cache_time_ns: int) -> None:
        self.cache_time_ns = cache_time_ns
        self._alloc(_MIN_CAPACITY)
        self._head = 0
        self._tail = 0
        self._parent = 0  # the parent of every sample while _parents is None
        self._parents: npt.NDArray[np.int32] | None = None

    def _alloc(self, cap: int) -> None:
        self._cap = cap
        self._stamps: npt.NDArray[np.int64] = np.empty(cap, dtype=np.int64)
        self._values: npt.NDArray[np.float64] = np.empty((cap, 7), dtype=np.float64)
        self._smv = self._stamps.data
        self._vmv = self._values.data

    # -- size and introspection ------------------------------------------------------

    def __len__(self) -> int:
        return self._tail - self._head

    def nbytes(self) -> int:
        """Bytes held by this link's sample arrays (capacity, not just live samples)."""
        n = self._stamps.nbytes + self._values.nbytes
        return n + (self._parents.nbytes if self._parents is not None else 0)

    def stamps(self) -> npt.NDArray[np.int64]:
        """Stored stamps, oldest first, ``(N,) int64`` nanoseconds (a copy)."""
        return self._stamps[self._head : self._tail].copy()

    def values(self) -> npt.NDArray[np.float64]:
        """Stored samples, oldest first, ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz, qw)
        (a copy)."""
        return self._values[self._head : self._tail].copy()

    def latest(self) -> tuple[int, int]:
        """``(newest stamp ns, its parent id)``, or ``(0, 0)`` when empty
        (``TimeCache::getLatestTimeAndParent``)."""
        tail = self._tail
        if tail == self._head:
            return 0, 0
        parents = self._parents
        return self._smv[tail - 1], self._parent if parents is None else int(parents[tail - 1])

    def latest_stamp(self) -> int:
        """Newest stamp in ns, 0 when empty (``TimeCache::getLatestTimestamp``)."""
        return self._smv[self._tail - 1] if self._tail != self._head else 0

    def oldest_stamp(self) -> int:
        """Oldest stamp in ns, 0 when empty (``TimeCache::getOldestTimestamp``)."""
        return self._smv[self._head] if self._tail != self._head else 0

    def parent_at(self, index: int) -> int:
        """Parent id of the sample at absolute storage index ``index``."""
        parents = self._parents
        return self._parent if parents is None else int(parents[index])

    def clear(self) -> None:
        """Drop every sample (``TimeCache::clearList``); capacity is released."""
        self._alloc(_MIN_CAPACITY)
        self._head = self._tail = 0
        self._parents = None

    # -- insert --------------------------------------------------------------------

    def insert(self, stamp: int, parent: int, values: Tf7) -> int:
        """Store one sample; returns ``OK``, ``OLD_DATA`` or ``REPEATED_DATA`` (tf2's
        ``TimeCache::insertData``, with ``pruneList`` after a successful insert)."""
        head, tail = self._head, self._tail
        smv = self._smv
        if tail != head:
            newest = smv[tail - 1]
            if newest > stamp + self.cache_time_ns:
                return OLD_DATA
            if stamp > newest:
                pos = tail
            else:
                pos = bisect_left(smv, stamp, head, tail)
                if smv[pos] == stamp:
                    return REPEATED_DATA
        else:
            pos = tail
        if parent != self._parent and self._parents is None:
            if tail == head:
                self._parent = parent
            else:
                self._parents = np.full(self._cap, self._parent, dtype=np.int32)
        if tail == self._cap:
            self._make_room()
            pos += self._head - head
            head, tail = self._head, self._tail
        if pos != tail:  # out-of-order insert: shift the newer samples up by one
            self._stamps[pos + 1 : tail + 1] = self._stamps[pos:tail]
            self._values[pos + 1 : tail + 1] = self._values[pos:tail]
            if self._parents is not None:
                self._parents[pos + 1 : tail + 1] = self._parents[pos:tail]
        smv = self._smv
        smv[pos] = stamp
        _ROW.pack_into(self._vmv, pos * _ROW_BYTES, *values)
        if self._parents is not None:
            self._parents[pos] = parent
        tail += 1
        self._tail = tail
        # pruneList: drop samples older than newest - cache_time (strict comparison).
        horizon = smv[tail - 1] - self.cache_time_ns
        if smv[head] < horizon:
            self._head = bisect_left(smv, horizon, head, tail)
        return OK

    def _make_room(self) -> None:
        """Storage is full at the top: slide the live samples down if at least 1/16 of the
        capacity is free below them, else grow by 1/16 (amortised O(1) inserts; a steady
        stream settles at ~7 % slack, i.e. ~68 bytes per sample)."""
        head, tail, cap = self._head, self._tail, self._cap
        n = tail - head
        if head >= cap // 16 and head > 0:
            self._stamps[:n] = self._stamps[head:tail]
            self._values[:n] = self._values[head:tail]
            if self._parents is not None:
                self._parents[:n] = self._parents[head:tail]
        else:
            new_cap = max(_MIN_CAPACITY, n + max(n // 16, 4))
            stamps, values, parents = self._stamps, self._values, self._parents
            self._alloc(new_cap)
            self._stamps[:n] = stamps[head:tail]
            self._values[:n] = values[head:tail]
            if parents is not None:
                self._parents = np.empty(new_cap, dtype=np.int32)
                self._parents[:n] = parents[head:tail]
        self._head, self._tail = 0, n

    # -- query ---------------------------------------------------------------------

    def gather(self, time: int) -> tuple[int, Tf7] | str:
        """The link's transform at ``time`` (ns; 0 = newest) as ``(parent id, values)``,
        or the tf2 extrapolation detail string (possibly empty) when there is no data.

        A parent id of 0 (tf2's ``NO_PARENT``) is returned as is; callers treat it as a
        failure with an empty detail, like tf2's ``gather``.
        """
        head, tail = self._head, self._tail
        if tail == head:
            return ""
        smv = self._smv
        vmv = self._vmv
        parents = self._parents
        if time == 0:
            i = tail - 1
        else:
            newest = smv[tail - 1]
            if time == newest:
                i = tail - 1
            elif tail - head == 1:
                return _extrapolation_at(time, newest)
            elif time > newest:
                return _extrapolation_future(time, newest)
            else:
                i = bisect_left(smv, time, head, tail)
                if smv[i] != time:
                    if i == head:
                        return _extrapolation_past(time, smv[head])
                    # Between samples i-1 (older) and i (newer).
                    i0 = i - 1
                    p0 = self._parent if parents is None else int(parents[i0])
                    if parents is not None and int(parents[i]) != p0:
                        return p0, _ROW.unpack_from(vmv, i0 * _ROW_BYTES)
                    t0 = smv[i0]
                    ax, ay, az, aqx, aqy, aqz, aqw, bx, by, bz, bqx, bqy, bqz, bqw = (
                        _ROW.unpack_from(vmv, i0 * _ROW_BYTES)
                        + _ROW.unpack_from(vmv, i * _ROW_BYTES)
                    )
                    # TimeCache::interpolate. The ratio is correctly rounded from integer
                    # ns (tf2 divides double seconds; the two differ by < 1e-15 relative).
                    r = (time - t0) / (smv[i] - t0)
                    s = 1.0 - r
                    # tf2 slerp (Quaternion.h), inlined: this is the lookup hot path.
                    dot = aqx * bqx + aqy * bqy + aqz * bqz + aqw * bqw
                    if dot < 0.0:
                        dot = -dot
                        bqx, bqy, bqz, bqw = -bqx, -bqy, -bqz, -bqw
                    c = dot / sqrt(
                        (aqx * aqx + aqy * aqy + aqz * aqz + aqw * aqw)
                        * (bqx * bqx + bqy * bqy + bqz * bqz + bqw * bqw)
                    )
                    if c == 1.0:  # acos(c) == 0: tf2 returns the older rotation unchanged
                        return p0, (s * ax + r * bx, s * ay + r * by, s * az + r * bz,
                                    aqx, aqy, aqz, aqw)
                    theta = acos(c) if c < 1.0 else nan  # C acos gives NaN above 1
                    d = 1.0 / sin(theta)
                    s0 = sin(s * theta) * d
                    s1 = sin(r * theta) * d
                    return p0, (
                        s * ax + r * bx,
                        s * ay + r * by,
                        s * az + r * bz,
                        aqx * s0 + bqx * s1,
                        aqy * s0 + bqy * s1,
                        aqz * s0 + bqz * s1,
                        aqw * s0 + bqw * s1,
                    )
        return (
            self._parent if parents is None else int(parents[i]),
            _ROW.unpack_from(vmv, i * _ROW_BYTES),
        )

    def sample_at(self, index: int) -> Tf7:
        """The stored values at absolute storage index ``index``."""
        return _ROW.unpack_from(self._vmv, index * _ROW_BYTES)


class StaticCache:
    """The single value of a static link, valid at every time (``tf2::StaticCache``).

    ``insert`` always overwrites (last wins, stamp ignored); ``latest()`` reports stamp 0,
    so static links never limit tf2's latest common time; ``clear()`` keeps the value.
    """

    __slots__ = ("_parent", "_stamp", "_values")

    is_static: Final = True
    cache_time_ns: Final = 0

    def __init__(self) -> None:
        self._parent = 0
        self._values: Tf7 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        self._stamp = 0

    def __len__(self) -> int:
        return 1

    def nbytes(self) -> int:
        """Bytes of sample storage (one 7-tuple of floats)."""
        return 7 * 8

    def insert(self, stamp: int, parent: int, values: Tf7) -> int:
        """Overwrite the value; always ``OK`` (``StaticCache::insertData``)."""
        self._parent = parent
        self._values = values
        self._stamp = stamp
        return OK

    def gather(self, time: int) -> tuple[int, Tf7] | str:
        """``(parent id, values)`` at any time (``StaticCache::getData``)."""
        return self._parent, self._values

    def latest(self) -> tuple[int, int]:
        """``(0, parent id)``: a static link has no time (``getLatestTimeAndParent``)."""
        return 0, self._parent

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
