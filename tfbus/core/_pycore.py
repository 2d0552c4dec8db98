"""The pure-Python core: everything :mod:`tfbus.core._ccore` (Cython) exports, same behaviour.

Loaded instead of the compiled core when it was not built (no C compiler, or
``TFBUS_NO_EXTENSIONS=1`` at install) or when ``TFBUS_PURE_PYTHON=1`` is set at import
(:mod:`tfbus.core._select` chooses; ``tfbus.core.COMPILED`` says which one is loaded).

Same behaviour means the same results **bit for bit**, the same return values, the same
exceptions and messages (checked side by side in ``tests/core/test_pycore.py`` and by the tf2
conformance corpus run against this core). That holds because:

* every formula is the compiled core's, term for term and in the same order: Python
  floats are IEEE doubles, each ``+ - * /`` is one separately rounded operation (the
  extension is built with ``-ffp-contract=off``: no fused multiply-add), and
  ``math.sin`` / ``math.acos`` / ``math.sqrt`` are the C library's functions the
  extension calls;
* where Python raises and C does not (a division by zero, ``sin(±inf)``), the IEEE
  result is produced instead (:func:`_div`, :func:`_sin`); the sign and payload of a NaN
  are not part of the contract (IEEE 754 leaves them unspecified, and the compiled
  core's depend on the operand order its C compiler picks);
* storage is the same: numpy arrays ``(cap,) int64`` stamps (ns), ``(cap, 7) float64``
  rows (tx, ty, tz, qx, qy, qz, qw) and, once a link has had two parents, ``(cap,)
  int32`` parent ids, with the same growth policy (so ``nbytes()`` agrees);
* scalar paths read plain floats (``ndarray.item`` / ``tolist``), never numpy scalars;
  the row functions use numpy where every element is one IEEE operation
  (:func:`apply_transforms`, :func:`lerp_rows`) and ``math.sin`` per row where the
  compiled core calls ``sin`` (:func:`slerp_rows`).

Semantics are tf2's (geometry2 0.7.6); each function names the tf2 source it follows.
A transform is a 7-tuple ``(tx, ty, tz, qx, qy, qz, qw)``: metres, quaternion (x, y, z,
w), never normalised unless said so. Times are int nanoseconds.

Known difference: the compiled ``compose`` / ``inverse`` / ``compose_full`` read their
7-sequences without bounds checks (a shorter tuple is undefined behaviour there); here a
short sequence raises IndexError.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Iterable, Sequence
from typing import Any, Final, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from tfbus.errors import InvalidArgumentException
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

__all__ = [
    "CONNECTIVITY_ERROR",
    "EXTRAPOLATION_ERROR",
    "INVALID",
    "INVALID_ARGUMENT",
    "LOOKUP_ERROR",
    "MAX_GRAPH_DEPTH",
    "NO_ERROR",
    "OK",
    "OLD_DATA",
    "REPEATED_DATA",
    "UNKNOWN_FRAME",
    "CoreBase",
    "Link",
    "StaticCache",
    "TimeCache",
    "apply_transforms",
    "batch_lookup",
    "compose",
    "compose_full",
    "format_sec",
    "inverse",
    "lerp_rows",
    "lookup_rows",
    "quat_multiply",
    "quat_rotate",
    "slerp",
    "slerp_rows",
]

Tf7 = tuple[float, float, float, float, float, float, float]
_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_I32 = npt.NDArray[np.int32]

# insert outcomes (tf2 cache insertData)
OK: Final = 0
OLD_DATA: Final = 1
REPEATED_DATA: Final = 2

# outcomes of CoreBase._cwalk / _ccommon_time (tf2_msgs::TF2Error)
NO_ERROR: Final = 0
LOOKUP_ERROR: Final = 1
CONNECTIVITY_ERROR: Final = 2
EXTRAPOLATION_ERROR: Final = 3

MAX_GRAPH_DEPTH: Final = 1000
"""Walks longer than this are taken to be loops (tf2 ``MAX_GRAPH_DEPTH``)."""

INVALID: Final = 3
"""``CoreBase._store``: the transform breaks one of tf2's rules (setTransformImpl)."""

# Query failures beyond tf2's codes: a bad argument (empty or '/'-prefixed id).
INVALID_ARGUMENT: Final = 4
UNKNOWN_FRAME: Final = 5

# gather outcomes
_G_OK: Final = 0
_G_EMPTY: Final = 1  # no samples: tf2 gives an empty detail
_G_AT: Final = 2  # a single sample, at another time
_G_FUTURE: Final = 3
_G_PAST: Final = 4
# climb outcomes
_CLIMB_STOPPED: Final = 0  # reached the stop frame, or a frame without a link
_CLIMB_EARLY: Final = 1  # reached the other frame of the lookup
_CLIMB_FAILED: Final = 2  # a link had no data at the time
_CLIMB_LOOP: Final = 3  # longer than MAX_GRAPH_DEPTH

_MIN_CAPACITY: Final = 8
_MEMO_SIZE: Final = 64
_INT64_MAX: Final = 2**63 - 1
_INT64_MIN: Final = -(2**63)
_INT_MAX: Final = 2**31 - 1
_INT_MIN: Final = -(2**31)
_IDENTITY: Final[Tf7] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
_INF: Final = math.inf
_new: Final = tuple.__new__  # a NamedTuple without its Python-level __new__


# ---------------------------------------------------------------------- C semantics


def _c_int(value: Any, lo: int, hi: int, ctype: str) -> int:
    """``value`` converted as Cython converts an argument to a C integer: ints as they
    are, other numbers truncated by ``__int__`` / ``__index__``, OverflowError outside
    [lo, hi], TypeError for anything else."""
    if type(value) is not int:
        cls = type(value)
        if isinstance(value, (str, bytes, bytearray)) or not (
            hasattr(cls, "__int__") or hasattr(cls, "__index__")
        ):
            raise TypeError(f"'{cls.__name__}' object cannot be interpreted as an integer")
        value = int(value)
    if not lo <= value <= hi:
        if ctype == "int":
            raise OverflowError("value too large to convert to int")
        raise OverflowError(f"Python int too large to convert to C {ctype}")
    return int(value)


def _int64(value: Any) -> int:
    return _c_int(value, _INT64_MIN, _INT64_MAX, "long")


def _cint(value: Any) -> int:
    return _c_int(value, _INT_MIN, _INT_MAX, "int")


def _double(value: Any) -> float:
    """``value`` converted as Cython converts an argument to a C double
    (``PyFloat_AsDouble``: ``__float__``, else ``__index__``; no strings)."""
    if type(value) is float:
        return value
    cls = type(value)
    if isinstance(value, float) or (
        hasattr(cls, "__float__") and not isinstance(value, (str, bytes, bytearray))
    ):
        return float(value)
    if hasattr(cls, "__index__"):
        return float(value.__index__())
    raise TypeError(f"must be real number, not {cls.__name__}")


def _tp_name(value: object) -> str:
    """The C ``tp_name`` of ``value``'s type, as Cython's argument errors print it:
    ``module.name`` for a static (C) type outside builtins, the bare name otherwise."""
    cls = type(value)
    if cls.__flags__ & (1 << 9) or cls.__module__ == "builtins":  # Py_TPFLAGS_HEAPTYPE
        return cls.__name__
    return f"{cls.__module__}.{cls.__name__}"


def _div(a: float, b: float) -> float:
    """``a / b`` with C's IEEE semantics: a zero divisor gives ±inf or NaN, not
    ZeroDivisionError."""
    if b != 0.0 or b != b:
        return a / b
    if a != a:
        return a + b  # NaN
    if a == 0.0:
        return _INF - _INF  # 0/0: NaN
    return math.copysign(_INF, a) * math.copysign(1.0, b)


def _sin(x: float) -> float:
    """C ``sin``: ``sin(±inf)`` is NaN (math.sin raises)."""
    if x == _INF or x == -_INF:
        return x - x
    return math.sin(x)


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


# ---------------------------------------------------------------------- scalar math
#
# The scalar transform arithmetic of tf2 (``tf2/LinearMath/Quaternion.h``, ``Vector3.h``;
# ``buffer_core.cpp`` ``TransformAccum``) in tf2's evaluation order, as in _ccore.pyx.


def _qrot(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    # tf2 quatRotate: q ⊗ (v, 0) ⊗ conj(q), vector part.
    tx = qw * vx + qy * vz - qz * vy
    ty = qw * vy + qz * vx - qx * vz
    tz = qw * vz + qx * vy - qy * vx
    tw = -qx * vx - qy * vy - qz * vz
    return (
        -tw * qx + tx * qw - ty * qz + tz * qy,
        -tw * qy + ty * qw - tz * qx + tx * qz,
        -tw * qz + tz * qw - tx * qy + ty * qx,
    )


def _qmul(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    # Quaternion.h operator*: Hamilton product a ⊗ b.
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by + ay * bw + az * bx - ax * bz,
        aw * bz + az * bw + ax * by - ay * bx,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _compose(a: Sequence[float], b: Sequence[float]) -> Tf7:
    # a ∘ b (apply b, then a): t = quatRotate(qa, tb) + ta, q = qa ⊗ qb (TransformAccum).
    ax, ay, az, aqx, aqy, aqz, aqw = a[0], a[1], a[2], a[3], a[4], a[5], a[6]
    rx, ry, rz = _qrot(aqx, aqy, aqz, aqw, b[0], b[1], b[2])
    qx, qy, qz, qw = _qmul(aqx, aqy, aqz, aqw, b[3], b[4], b[5], b[6])
    return (rx + ax, ry + ay, rz + az, qx, qy, qz, qw)


def _slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    r: float,
) -> tuple[float, float, float, float]:
    # Quaternion.h slerp / angleShortestPath; tf2Acos's clamp makes a cosine >= 1 a zero
    # angle, for which tf2 returns a unchanged.
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        dot = -dot
        bx = -bx
        by = -by
        bz = -bz
        bw = -bw
    c = _div(
        dot,
        math.sqrt(
            (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
        ),
    )
    if c >= 1.0:
        return (ax, ay, az, aw)
    theta = math.acos(c)  # c is in [0, 1) or NaN here: NaN only for NaN input, as in tf2
    d = _div(1.0, math.sin(theta))
    s0 = _sin((1.0 - r) * theta)
    s1 = _sin(r * theta)
    return (
        (ax * s0 + bx * s1) * d,
        (ay * s0 + by * s1) * d,
        (az * s0 + bz * s1) * d,
        (aw * s0 + bw * s1) * d,
    )


def quat_multiply(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    """Hamilton product ``a ⊗ b`` of two (x, y, z, w) quaternions, as ``(x, y, z, w)``
    (tf2 ``Quaternion.h`` ``operator*``).

    Raises:
        TypeError: an argument is not a real number.
    """
    return _qmul(
        _double(ax), _double(ay), _double(az), _double(aw),
        _double(bx), _double(by), _double(bz), _double(bw),
    )  # fmt: skip


def quat_rotate(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """Vector ``(vx, vy, vz)`` rotated by quaternion q (x, y, z, w) as ``q ⊗ (v, 0) ⊗
    conj(q)`` (tf2 ``quatRotate``); scaled by ``|q|²`` for a non-unit q, exactly as tf2.

    Raises:
        TypeError: an argument is not a real number.
    """
    return _qrot(
        _double(qx), _double(qy), _double(qz), _double(qw),
        _double(vx), _double(vy), _double(vz),
    )  # fmt: skip


def _seven(values: Sequence[float]) -> Tf7:
    return (
        _double(values[0]), _double(values[1]), _double(values[2]), _double(values[3]),
        _double(values[4]), _double(values[5]), _double(values[6]),
    )  # fmt: skip


def compose(a: Sequence[float], b: Sequence[float]) -> Tf7:
    """``a ∘ b`` of two 7-tuples ``(tx, ty, tz, qx, qy, qz, qw)`` (metres; x, y, z, w):
    apply b, then a (tf2 ``TransformAccum::accum``).

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    x = _seven(a)
    y = _seven(b)
    return _compose(x, y)


def inverse(a: Sequence[float]) -> Tf7:
    """tf2's inverse of a 7-tuple: rotation ``conj(q)``, translation ``quatRotate(conj(q),
    -t)`` (``TransformAccum::finalize``); exact for unit quaternions.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    # As compiled: the rotation part is returned as ``-a[k]`` / ``a[6]`` of the objects
    # given (an int stays an int), the translation computed in doubles.
    rx, ry, rz = _qrot(
        _double(-a[3]), _double(-a[4]), _double(-a[5]), _double(a[6]),
        _double(-a[0]), _double(-a[1]), _double(-a[2]),
    )  # fmt: skip
    return (rx, ry, rz, -a[3], -a[4], -a[5], a[6])


def slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    ratio: float,
) -> tuple[float, float, float, float]:
    """tf2's shortest-path spherical interpolation from a (ratio 0) to b (ratio 1) of two
    (x, y, z, w) quaternions, not normalised (Quaternion.h ``slerp``): half-angle
    ``acos(|a·b| / sqrt(|a|²|b|²))``, towards ``-b`` when ``a·b < 0``, ``a`` unchanged
    when the cosine rounds to 1 or above.

    Raises:
        TypeError: an argument is not a real number.
    """
    return _slerp(
        _double(ax), _double(ay), _double(az), _double(aw),
        _double(bx), _double(by), _double(bz), _double(bw), _double(ratio),
    )  # fmt: skip


def compose_full(leg2: Sequence[float], leg1: Sequence[float]) -> Tf7:
    """tf2's time-travel composition ``leg2 ∘ leg1`` of two 7-tuples
    (``lookupTransform`` with a fixed frame): both rotations are normalised first, as
    ``tf2::Transform`` keeps a normalised rotation matrix, and so is the result's.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    a = list(_seven(leg2))
    b = list(_seven(leg1))
    n = math.sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
    for k in range(3, 7):
        a[k] = _div(a[k], n)
    n = math.sqrt(b[3] * b[3] + b[4] * b[4] + b[5] * b[5] + b[6] * b[6])
    for k in range(3, 7):
        b[k] = _div(b[k], n)
    c = _compose(a, b)
    n = math.sqrt(c[3] * c[3] + c[4] * c[4] + c[5] * c[5] + c[6] * c[6])
    return (c[0], c[1], c[2], _div(c[3], n), _div(c[4], n), _div(c[5], n), _div(c[6], n))


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

    Storage: ``(cap,) int64`` stamps and ``(cap, 7) float64`` rows, live samples sorted
    by stamp in ``[head, tail)``, plus ``(cap,) int32`` parent ids only once the link has
    had two different parents.
    """

    __slots__ = ("_cap", "_ct", "_head", "_pa", "_parent", "_st", "_tail", "_va")

    _st: _I64
    _va: _F64
    _pa: _I32 | None

    def __init__(self, cache_time_ns: int) -> None:
        self._ct = _int64(min(cache_time_ns, _INT64_MAX))
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

    def _make_room(self) -> None:
        """Storage is full at the top: slide the live samples down if at least 1/16 of the
        capacity is free below them, else grow by 1/16 (as the compiled core)."""
        head, tail, cap = self._head, self._tail, self._cap
        n = tail - head
        if head >= cap // 16 and head > 0:
            self._st[:n] = self._st[head:tail]
            self._va[:n] = self._va[head:tail]
            if self._pa is not None:
                self._pa[:n] = self._pa[head:tail]
        else:
            new_cap = max(_MIN_CAPACITY, n + max(n // 16, 4))
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


# ---------------------------------------------------------------------- the core


def _link(caches: list[Link | None], frame: int) -> Link | None:
    """The link of ``frame``, or None; an id outside the table (only reachable by writing
    bogus parent ids into a cache by hand) counts as a frame without a link."""
    if frame < 0 or frame >= len(caches):
        return None
    return caches[frame]


def _climb(
    caches: list[Link | None], frame: int, stop: int, early: int, time: int
) -> tuple[int, int, Tf7]:
    """One half of tf2's ``walkToTopParent``: walk up from ``frame`` gathering each link
    at ``time`` and accumulating ``frame -> current``.

    Returns ``(outcome, reached, acc)``: stops at ``stop`` (not gathered), at a frame
    without a link, at a link with no data (CLIMB_FAILED, reached = the failing frame),
    or at ``early`` once its link gathered (CLIMB_EARLY; that link is not accumulated).
    """
    acc = _IDENTITY
    depth = 0
    first = True
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        code, parent, st = obj._c_gather(time)
        if code != _G_OK or parent == 0:
            return _CLIMB_FAILED, frame, acc
        if frame == early:
            return _CLIMB_EARLY, frame, acc
        if first:
            acc = st
            first = False
        else:
            acc = _compose(st, acc)  # TransformAccum::accum: acc = link ∘ acc
        frame = parent
        depth += 1
        if depth > MAX_GRAPH_DEPTH:
            return _CLIMB_LOOP, frame, acc
    return _CLIMB_STOPPED, frame, acc


def _stamped(stamp: Time, target: str, source: str, v: Sequence[float]) -> TransformStamped:
    """The lookup result: ``TransformStamped(Header(stamp, target), source,
    Transform(Vector3(v[0:3]), Quaternion(v[3:7])))``."""
    return _new(
        TransformStamped,
        (
            _new(Header, (stamp, target)),
            source,
            _new(
                Transform,
                (_new(Vector3, (v[0], v[1], v[2])), _new(Quaternion, (v[3], v[4], v[5], v[6]))),
            ),
        ),
    )


def _time_of(ns: int) -> Time:
    """``Time.from_ns(ns)`` for a valid ns, without re-validating it."""
    t = Time.__new__(Time)
    t._ns = ns
    return t


def _as_str(value: object) -> str | None:
    """A frame id as the exact ``str`` it is (``numpy.str_`` or any ``str`` subclass is
    accepted as its string value); None for anything that is not a string."""
    if type(value) is str:
        return value
    if isinstance(value, str):
        return str.__str__(value)
    return None


def _show(value: object) -> str:
    """``repr`` of a bad value for an error message, bounded in length."""
    try:
        text = repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 80 else text[:77] + "..."


def _number(value: object, field: str) -> float:
    """A transform component as a float; anything but a real number (bool, None, str, an
    int beyond double range, ...) is an InvalidArgumentException naming the field."""
    if type(value) is float:
        return value
    if not isinstance(value, (bool, np.bool_, str, bytes, complex)) and value is not None:
        try:
            return float(value)  # type: ignore[arg-type]
        except (OverflowError, TypeError, ValueError):
            pass
    raise InvalidArgumentException(f"{field} must be a real number, got {_show(value)}")


_FIELDS: Final = (
    "transform.translation.x",
    "transform.translation.y",
    "transform.translation.z",
    "transform.rotation.x",
    "transform.rotation.y",
    "transform.rotation.z",
    "transform.rotation.w",
)


def _bad_id(frame_id: str, which: int) -> tuple[int, int]:
    """The failure tuple of a query argument that is not a known frame (tf2
    ``validateFrameId``): empty or '/'-prefixed ids are invalid, others unknown."""
    if not frame_id or frame_id[0] == "/":
        return (INVALID_ARGUMENT, which)
    return (UNKNOWN_FRAME, which)


_Core = TypeVar("_Core", bound="CoreBase")


class CoreBase:
    """Frame table and hot paths of :class:`tfbus.core.BufferCore` (which subclasses it).

    Nothing here calls into the subclass: inserts and queries return codes and data, and
    ``tfbus.core`` turns them into tf2's messages, exceptions and log lines.

    Internals (for white-box tests, never written from outside): ``_frame_ids`` (frame
    id → int id; 0 is tf2's ``NO_PARENT``), ``_frame_names`` (int id → frame id),
    ``_caches`` (int id → link or None), ``_authority`` (int id → authority of its last
    stored transform) and ``_generation`` (bumped by every insert attempt and by
    ``clear``). Python code uses the public methods: ``clear``, ``get_frame_names``,
    ``frame_exists``, ``parent_of``, ``link_info``, ``extrapolation_detail``,
    ``common_time``.

    The state is set up in ``__new__`` (the compiled core's ``__cinit__``), so a
    subclass's ``__init__`` need not call this one.
    """

    __slots__ = (
        "_authority",
        "_cache_ns",
        "_caches",
        "_frame_ids",
        "_frame_names",
        "_generation",
        "_last_child",
        "_last_parent",
        "_last_relinked",
        "_last_stamp",
        "_last_values",
        "_memo",
        "_memo_generation",
    )

    _frame_ids: dict[str, int]
    _frame_names: list[str]
    _caches: list[Link | None]
    _authority: dict[int, str]
    _generation: int
    _cache_ns: int
    _memo: dict[tuple[str, str, int], TransformStamped]
    _memo_generation: int
    # What the last ``_insert_one`` did, beyond its code (read by ``_store`` and
    # ``_store_one`` right after it): the stripped ids, the stamp, the values (for
    # INVALID only) and whether the tree's shape may have changed.
    _last_parent: str
    _last_child: str
    _last_stamp: int
    _last_values: Tf7
    _last_relinked: bool

    def __new__(cls: type[_Core], *args: Any, **kwargs: Any) -> _Core:
        self = super().__new__(cls)
        self._frame_ids = {"NO_PARENT": 0}
        self._frame_names = ["NO_PARENT"]
        self._caches = [None]
        self._authority = {}
        self._generation = 0
        self._cache_ns = 0
        self._memo = {}
        self._memo_generation = -1
        self._last_parent = self._last_child = ""
        self._last_stamp = 0
        self._last_values = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        self._last_relinked = False
        return self

    @property
    def cache_time_ns(self) -> int:
        """The history kept per dynamic link, nanoseconds (the one copy: every link is
        created with it; read-only)."""
        return self._cache_ns

    def _set_cache_time_ns(self, ns: int) -> None:
        """Set the cache time (ns); only before the first insert (``BufferCore.__init__``).

        Raises:
            RuntimeError: frames are already registered.
        """
        if len(self._frame_names) > 1:
            raise RuntimeError("cache_time is fixed once transforms are stored")
        self._cache_ns = _int64(min(ns, _INT64_MAX))

    def _register(self, frame_id: str) -> int:
        fid = len(self._frame_names)
        self._frame_ids[frame_id] = fid
        self._frame_names.append(frame_id)
        self._caches.append(None)
        return fid

    # ------------------------------------------------------------------ insert

    def _insert_one(self, ts: TransformStamped, authority: str, is_static: bool) -> int:
        """``BufferCore::setTransformImpl``: check, register frames, store.

        Returns OK / OLD_DATA / REPEATED_DATA, or INVALID (a tf2 rule is broken). What it
        did beyond the code is left in ``_last_parent``, ``_last_child`` (stripped ids),
        ``_last_stamp`` (ns; not for INVALID), ``_last_values`` (INVALID only) and
        ``_last_relinked``. A field of the wrong type raises InvalidArgumentException
        naming it; nothing is stored or registered before every check has passed."""
        header = ts[0]
        tf = ts[2]
        if not isinstance(header, Header):
            raise InvalidArgumentException(f"header must be a Header, got {_show(header)}")
        if not isinstance(tf, Transform):
            raise InvalidArgumentException(f"transform must be a Transform, got {_show(tf)}")
        tr = tf[0]
        rot = tf[1]
        if not (isinstance(tr, tuple) and len(tr) == 3):
            raise InvalidArgumentException(
                f"transform.translation must be a Vector3, got {_show(tr)}"
            )
        if not (isinstance(rot, tuple) and len(rot) == 4):
            raise InvalidArgumentException(
                f"transform.rotation must be a Quaternion, got {_show(rot)}"
            )
        parent = _as_str(header[1])
        if parent is None:
            raise InvalidArgumentException(f"header.frame_id must be a str, got {_show(header[1])}")
        child = _as_str(ts[1])
        if child is None:
            raise InvalidArgumentException(f"child_frame_id must be a str, got {_show(ts[1])}")
        stamp_obj = header[0]
        if not isinstance(stamp_obj, Time):
            raise InvalidArgumentException(f"header.stamp must be a Time, got {_show(stamp_obj)}")
        v: Tf7 = (
            _number(tr[0], _FIELDS[0]),
            _number(tr[1], _FIELDS[1]),
            _number(tr[2], _FIELDS[2]),
            _number(rot[0], _FIELDS[3]),
            _number(rot[1], _FIELDS[4]),
            _number(rot[2], _FIELDS[5]),
            _number(rot[3], _FIELDS[6]),
        )
        if len(parent) and parent[0] == "/":
            parent = parent[1:]
        if len(child) and child[0] == "/":
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
            or not abs(norm2 - 1.0) < 0.01
        ):
            self._last_values = v
            return INVALID
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
        _, old_parent = cache._c_latest()
        code = cache._c_insert(stamp, pid, v)
        # The tree's shape may have changed: a new or emptied link, another parent, or a
        # link that keeps one parent per sample.
        self._last_relinked = False
        if code == OK:
            self._last_relinked = old_parent != pid or (
                isinstance(cache, TimeCache) and cache._pa is not None
            )
            self._authority[cid] = authority
        return code

    def _store(
        self, transforms: Iterable[Any], authority: str, is_static: bool
    ) -> tuple[
        int,
        int,
        list[tuple[int, Exception | tuple[str, str, Tf7]]],
        set[str],
        bool,
        list[tuple[int, str, int]],
    ]:
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

        Raises:
            TypeError: ``authority`` is not a str (nor None).
        """
        if authority is not None and type(authority) is not str:
            raise TypeError(
                f"Argument 'authority' has incorrect type (expected str, got {_tp_name(authority)})"
            )
        is_static = bool(is_static)
        stored = 0
        refusals: list[tuple[int, str, int]] = []
        errors: list[tuple[int, Exception | tuple[str, str, Tf7]]] = []
        touched: set[str] = set()
        relinked = False
        for i, ts in enumerate(transforms):
            try:
                if not isinstance(ts, TransformStamped):
                    raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                code = self._insert_one(ts, authority, is_static)
            except Exception as exc:
                errors.append((i, exc))
            else:
                if code == OK:
                    stored += 1
                    touched.add(self._last_child)
                    touched.add(self._last_parent)
                    if self._last_relinked:
                        relinked = True
                elif code == INVALID:
                    errors.append((i, (self._last_parent, self._last_child, self._last_values)))
                else:
                    refusals.append((code, self._last_child, self._last_stamp))
        return stored, len(refusals), errors, touched, relinked, refusals

    def _store_one(
        self, ts: Any, authority: str, is_static: bool
    ) -> Literal[True] | tuple[int, str, int] | tuple[int, str, str, Tf7]:
        """One transform, as ``_store`` would store it (``BufferCore.set_transform``'s
        path). Calls nothing back.

        Returns True when stored; else what ``_store`` reports for it: ``(OLD_DATA |
        REPEATED_DATA, child, stamp ns)`` for a refusal by the cache, ``(INVALID, parent,
        child, values)`` for a transform that breaks a tf2 rule.

        Raises:
            TypeError: ``ts`` is not a TransformStamped, or ``authority`` not a str.
            InvalidArgumentException: a field of the wrong type (named).
        """
        if authority is not None and type(authority) is not str:
            raise TypeError(
                f"Argument 'authority' has incorrect type (expected str, got {_tp_name(authority)})"
            )
        if not isinstance(ts, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
        code = self._insert_one(ts, authority, bool(is_static))
        if code == OK:
            return True
        if code == INVALID:
            return (INVALID, self._last_parent, self._last_child, self._last_values)
        return (code, self._last_child, self._last_stamp)

    def _last_touched(self) -> tuple[str, str, bool]:
        """``(child, parent, relinked)`` of the transform ``_store_one`` last stored: the
        (stripped) ids whose lookups may have changed and whether the tree's shape may
        have (what ``_store`` reports per batch); read by ``tfbus.buffer.Buffer`` when
        waits are pending."""
        return self._last_child, self._last_parent, self._last_relinked

    # ------------------------------------------------------------------ queries

    def _id_status(self, frame_id: object) -> int:
        """0 for a known, queryable frame id; else INVALID_ARGUMENT (not a string, empty,
        '/'-prefixed) or UNKNOWN_FRAME (tf2 ``validateFrameId``)."""
        name = _as_str(frame_id)
        if name is None:
            return INVALID_ARGUMENT
        if self._frame(name) >= 0:
            return 0
        return _bad_id(name, 0)[0]

    def _frame(self, frame_id: Any) -> int:
        """Id of a known, queryable frame, or -1 (empty, '/'-prefixed, unknown)."""
        fid = self._frame_ids.get(frame_id)
        if fid is None or fid == 0:
            return -1
        if type(frame_id) is not str or not len(frame_id) or frame_id[0] == "/":
            return -1
        return fid

    def _query(self, target: str, source: str, time: Time) -> TransformStamped | tuple[int, ...]:
        """``lookupTransform(target, source, time)`` in one call: the TransformStamped
        (built here, memoised until the next insert or clear), or a failure tuple:

        * ``(INVALID_ARGUMENT, 0 | 1)`` / ``(UNKNOWN_FRAME, 0 | 1)``: the target (0) or
          source (1) id is empty / '/'-prefixed, or unknown;
        * ``(LOOKUP_ERROR, 0)``: a loop; ``(CONNECTIVITY_ERROR, 0)``: two trees;
        * ``(EXTRAPOLATION_ERROR, frame id, time ns, expired)``: the link of that frame has
          no data at the time; ``expired`` when the time is older than the path's latest
          common time minus cache_time (tf2's transformable-request test), i.e. waiting
          cannot help.

        Source: tf2 ``BufferCore::lookupTransform`` / ``walkToTopParent``.
        """
        t = _int64(time._ns)
        if type(target) is not str:
            name = _as_str(target)
            if name is None:
                return (INVALID_ARGUMENT, 0)
            target = name
        if type(source) is not str:
            name = _as_str(source)
            if name is None:
                return (INVALID_ARGUMENT, 1)
            source = name
        key = (target, source, t)
        if self._memo_generation == self._generation:
            hit = self._memo.get(key)
            if hit is not None:
                return hit
        else:
            self._memo.clear()
            self._memo_generation = self._generation
        if target == source:
            if t == 0:
                # tf2 stamps the identity with the frame's newest sample; an unknown id
                # maps to frame 0 (NO_PARENT), whose link exists only if "NO_PARENT" was
                # stored as a child (lookupFrameNumber / getFrame).
                cache = self._caches[self._frame_ids.get(target, 0)]
                if cache is not None:
                    t = cache._c_latest()[0]
            return _stamped(_time_of(t) if t != time._ns else time, target, source, _IDENTITY)
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(source, 1)
        err, v, where, used = self._walk(target_id, source_id, t)
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = self._caches[where]
            assert link is not None
            gcode = link._c_gather(used)[0]
            if gcode != _G_FUTURE:
                cerr, lct = self._common(target_id, source_id)
                if cerr == NO_ERROR:
                    expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        out = _stamped(time if used == t and t != 0 else _time_of(used), target, source, v)
        if len(self._memo) >= _MEMO_SIZE:
            self._memo.clear()
        self._memo[key] = out
        return out

    def _chain(self, target_frame: str, source_frame: str, time: Time | None = None) -> list[str]:
        """The frames an answer for ``lookup_transform(target_frame, source_frame, time)``
        depends on, now and as data arrives: both ids, and the ancestors of each by its
        link's newest parent and, for a time other than 0, by its parent at ``time`` (a
        link re-parented over time), at most ``MAX_GRAPH_DEPTH + 1`` per chain (a longer
        walk is tf2's loop error). Unknown ids are included as given (they may arrive).
        Like tf2's ``_chainAsVector``, but as a set and for both parentage rules.

        Returns:
            A list of frame ids (no duplicates, in discovery order).
        """
        t = 0 if time is None else _int64(time._ns)
        names = self._frame_names
        caches = self._caches
        seen: set[str] = set()
        out: list[str] = []
        todo: list[str] = [target_frame, source_frame]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            out.append(name)
            fid = self._frame_ids.get(name)
            if fid is None:
                continue
            frame = fid
            depth = 0
            while frame != 0 and depth <= MAX_GRAPH_DEPTH:
                obj = _link(caches, frame)
                if obj is None:
                    break
                if t != 0:
                    code, p2, _ = obj._c_gather(t)
                    if code == _G_OK and p2 != 0 and names[p2] not in seen:
                        todo.append(names[p2])
                _, parent = obj._c_latest()
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

    def _common(self, target: int, source: int) -> tuple[int, int]:
        """tf2 ``getLatestCommonTime``: ``(NO_ERROR, time ns)`` or ``(error code, 0)``."""
        caches = self._caches
        if source == target:
            obj = _link(caches, source)
            return NO_ERROR, obj._c_latest()[0] if obj is not None else 0
        # Walk up from the source, remembering (stamp, parent) of each link.
        lct_stamp: list[int] = []
        lct_parent: list[int] = []
        frame = source
        common = _INT64_MAX
        have = False
        depth = 0
        while frame != 0:
            obj = _link(caches, frame)
            if obj is None:
                break
            stamp, parent = obj._c_latest()
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            lct_stamp.append(stamp)
            lct_parent.append(parent)
            frame = parent
            if frame == target:
                return NO_ERROR, common if have else 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return LOOKUP_ERROR, 0
        # Walk up from the target until a parent seen on the source side.
        frame = target
        depth = 0
        have = False
        common = _INT64_MAX
        common_parent = 0
        while True:
            obj = _link(caches, frame)
            if obj is None:
                break
            stamp, parent = obj._c_latest()
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if parent in lct_parent:
                common_parent = parent
                break
            frame = parent
            if frame == source:
                return NO_ERROR, common if have else 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return LOOKUP_ERROR, 0
        if common_parent == 0:
            return CONNECTIVITY_ERROR, 0
        for k in range(len(lct_parent)):
            stamp = lct_stamp[k]
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if lct_parent[k] == common_parent:
                break
        return NO_ERROR, common if have else 0

    def _ccommon_time(self, target_id: int, source_id: int) -> tuple[int, int]:
        """``(NO_ERROR, time ns)``, or ``(LOOKUP_ERROR (loop) | CONNECTIVITY_ERROR, 0)``
        (tf2 ``getLatestCommonTime``)."""
        err, t = self._common(_cint(target_id), _cint(source_id))
        return err, (t if err == NO_ERROR else 0)

    # ------------------------------------------------------------------ public state

    def clear(self) -> None:
        """Drop every stored sample, keeping the frames and their links (tf2
        ``BufferCore::clear``). As in tf2, the reserved frame 0 (``NO_PARENT``) is
        skipped: a link stored with child ``"NO_PARENT"`` keeps its samples."""
        self._generation += 1
        caches: list[Any] = self._caches  # TimeCache / StaticCache (Link's subclasses)
        for cache in caches[1:]:
            if cache is not None:
                cache.clear()

    def get_frame_names(self) -> list[str]:
        """Every known frame id (children and parents), in registration order."""
        return self._frame_names[1:]

    def frame_exists(self, frame_id: str) -> bool:
        """Whether ``frame_id`` is known (tf2 ``_frameExists``)."""
        return self._frame_ids.get(frame_id, 0) != 0

    def parent_of(self, frame_id: str, time_ns: int) -> str | None:
        """The parent id of ``frame_id`` at ``time_ns`` (0 = latest), or None for a root,
        an unknown frame or a time its link has no data for (tf2 ``_getParent``)."""
        time_ns = _int64(time_ns)
        fid = self._frame_ids.get(frame_id, 0)
        cache = self._caches[fid] if fid else None
        if cache is None:
            return None
        r = cache.gather(time_ns)
        if isinstance(r, str) or r[0] == 0:
            return None
        return self._frame_names[r[0]]

    def link_info(self) -> list[tuple[str, str, str, bool, int, int, int]]:
        """Per linked frame, in registration order, ``(child, parent, authority,
        is_static, samples, oldest_ns, newest_ns)``; the parent of an emptied link is
        ``NO_PARENT``, a link with no recorded authority says so."""
        names = self._frame_names
        caches: list[Any] = self._caches  # TimeCache / StaticCache (Link's subclasses)
        out = []
        for fid in range(1, len(caches)):
            cache = caches[fid]
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
            ))  # fmt: skip
        return out

    def extrapolation_detail(self, where: int, used: int) -> str:
        """tf2's extrapolation text of the link of frame ``where`` (the int id a failed
        query reported) at ``used`` ns: ``"Lookup would require extrapolation ..."``;
        ``""`` for no link or a link that can answer that time."""
        where, used = _cint(where), _int64(used)
        cache = self._caches[where] if 0 < where < len(self._caches) else None
        detail = cache.gather(used) if cache is not None else ""
        return detail if isinstance(detail, str) else ""

    def common_time(self, target_frame: str, source_frame: str) -> tuple[int, int]:
        """tf2 ``getLatestCommonTime`` for two known frame ids: ``(NO_ERROR, time ns)``,
        or ``(LOOKUP_ERROR (a loop) | CONNECTIVITY_ERROR, 0)``.

        Raises:
            KeyError: an id is unknown (validate first).
        """
        return self._ccommon_time(self._frame_ids[target_frame], self._frame_ids[source_frame])

    def _walk(self, target_id: int, source_id: int, time: int) -> tuple[int, Tf7, int, int]:
        """tf2 ``walkToTopParent`` with ``TransformAccum``: ``(code, v, where, time
        used)``, ``v`` the transform mapping source coordinates into target coordinates at
        the time used (``time`` 0 = the latest common time). ``code`` is NO_ERROR,
        LOOKUP_ERROR (a loop), CONNECTIVITY_ERROR, or EXTRAPOLATION_ERROR with ``where``
        = the frame whose link had no data."""
        caches = self._caches
        if source_id == target_id:
            return NO_ERROR, _IDENTITY, 0, time
        if time == 0:
            err, time = self._common(target_id, source_id)
            if err:
                return err, _IDENTITY, 0, time

        # Source side: source -> top. A failure here is only remembered: the path may
        # still close below it (only links between the two frames must be valid).
        outcome, top, src = _climb(caches, source_id, 0, target_id, time)
        if outcome == _CLIMB_EARLY:  # TargetParentOfSource
            return NO_ERROR, src, 0, time
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time
        failed = outcome == _CLIMB_FAILED
        src_failed_at = top if failed else 0

        # Target side: target -> top. A failure here is reported at once.
        outcome, frame, tgt = _climb(caches, target_id, top, source_id, time)
        if outcome == _CLIMB_FAILED:
            return EXTRAPOLATION_ERROR, _IDENTITY, frame, time
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time
        if outcome == _CLIMB_EARLY:  # SourceParentOfTarget: the source side is unused
            src = _IDENTITY
        elif frame != top:
            if failed:
                return EXTRAPOLATION_ERROR, _IDENTITY, src_failed_at, time
            return CONNECTIVITY_ERROR, _IDENTITY, 0, time

        # FullPath: inv(target -> top) ∘ (source -> top), inv = (conj q, conj q * (-t)):
        # conj(q) applied to (s - g), then conj(q) ⊗ q_s.
        iqx, iqy, iqz, iqw = -tgt[3], -tgt[4], -tgt[5], tgt[6]
        rx, ry, rz = _qrot(iqx, iqy, iqz, iqw, src[0] - tgt[0], src[1] - tgt[1], src[2] - tgt[2])
        qx, qy, qz, qw = _qmul(iqx, iqy, iqz, iqw, src[3], src[4], src[5], src[6])
        return NO_ERROR, (rx, ry, rz, qx, qy, qz, qw), 0, time

    def _cwalk(
        self, target_id: int, source_id: int, time: int
    ) -> tuple[int, Tf7 | int | None, int]:
        """tf2 ``walkToTopParent`` with ``TransformAccum`` (see ``_walk``).

        Returns ``(NO_ERROR, 7-tuple, time used)``, ``(EXTRAPOLATION_ERROR, id of the
        frame whose link had no data, time)``, ``(CONNECTIVITY_ERROR, None, 0)`` or
        ``(LOOKUP_ERROR, None, 0)`` (a loop).
        """
        err, v, where, used = self._walk(_cint(target_id), _cint(source_id), _int64(time))
        if err == NO_ERROR:
            return NO_ERROR, v, used
        if err == EXTRAPOLATION_ERROR:
            return err, where, used
        return err, None, 0


# ---------------------------------------------------------------------- arrays
#
# The compiled functions below take typed memoryviews; these checks give the same
# exception types (and Cython's messages) for arrays of the wrong kind.

_C_NAMES: Final = {
    ("f", 8): "double",
    ("f", 4): "float",
    ("f", 2): "half",
    ("i", 8): "long",
    ("i", 4): "int",
    ("i", 2): "short",
    ("i", 1): "signed char",
    ("u", 8): "unsigned long",
    ("u", 4): "unsigned int",
    ("u", 2): "unsigned short",
    ("u", 1): "unsigned char",
    ("b", 1): "bool",
}


def _view(obj: object, kind: str, size: int, ctype: str, ndim: int, writable: bool) -> Any:
    """``obj`` as a C-contiguous ndarray of ``ndim`` dimensions of one C type (kind and
    item size), as a Cython typed memoryview argument accepts it."""
    if isinstance(obj, np.ndarray):
        arr = obj
    else:
        try:
            arr = np.asarray(memoryview(obj))  # type: ignore[arg-type]
        except TypeError:
            raise TypeError(
                f"a bytes-like object is required, not '{type(obj).__name__}'"
            ) from None
    if writable and not arr.flags.writeable:
        raise ValueError("buffer source array is read-only")
    if not arr.flags.c_contiguous:
        raise ValueError("ndarray is not C-contiguous")
    if arr.ndim != ndim:
        raise ValueError(f"Buffer has wrong number of dimensions (expected {ndim}, got {arr.ndim})")
    if (arr.dtype.kind, arr.dtype.itemsize) != (kind, size):
        got = _C_NAMES.get((arr.dtype.kind, arr.dtype.itemsize), arr.dtype.str)
        raise ValueError(f"Buffer dtype mismatch, expected '{ctype}' but got '{got}'")
    return arr


def batch_lookup(
    core: CoreBase,
    target_frame: str,
    source_frame: str,
    times: _I64,
    out: _F64,
    stamps: _I64,
    ok: npt.NDArray[np.int8],
) -> int:
    """``lookupTransform(target_frame, source_frame, t)`` for every t of ``times``, into
    caller-owned arrays (the entry of :func:`tfbus.core.batch.lookup_transforms`).

    Args:
        core: the buffer (a CoreBase of this module).
        times: ``(N,) int64`` ns, C-contiguous.
        out: ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz, qw), written for rows
            answered.
        stamps: ``(N,) int64``, filled by the caller with ``times``; a row at time 0 gets
            the time used.
        ok: ``(N,) int8``, set to 1 for each row answered, 0 otherwise.

    Returns:
        The number of rows answered (each bit-for-bit ``lookup_transform``'s result), or
        -1 when a frame id is not a known, queryable id, or both ids are equal (then no
        row is answered: the caller asks the single lookup).

    Raises:
        TypeError: ``core`` is not a CoreBase; an array is not a buffer.
        ValueError: an array has the wrong dtype, layout or shape.

    Each row is the single walk (tf2 ``walkToTopParent`` per time); the compiled core's
    resolve-once plan gives the same numbers, faster.
    """
    if not isinstance(core, CoreBase):
        raise TypeError(
            "Argument 'core' has incorrect type (expected tfbus.core._pycore.CoreBase, got "
            f"{_tp_name(core)})"
        )
    t = _view(times, "i", 8, "const int64_t", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    s = _view(stamps, "i", 8, "int64_t", 1, True)
    k = _view(ok, "i", 1, "signed char", 1, True)
    n_rows = t.shape[0]
    if o.shape[0] != n_rows or o.shape[1] != 7 or k.shape[0] != n_rows or s.shape[0] != n_rows:
        raise ValueError("batch_lookup: out must be (N, 7), stamps and ok (N,) for N times")
    k[:] = 0
    target_id = core._frame(target_frame)
    source_id = core._frame(source_frame)
    if target_id < 0 or source_id < 0 or target_id == source_id:
        return -1
    answered = 0
    walk = core._walk
    for r, requested in enumerate(t.tolist()):
        err, v, _, used = walk(target_id, source_id, requested)
        if err == NO_ERROR:
            o[r] = v
            s[r] = used
            k[r] = 1
            answered += 1
    return answered


lookup_rows = batch_lookup
"""The rows of :meth:`tfbus.core.BufferCore.lookup_transforms`: the compiled core's may
take slerp's per-time sines from libmvec; the pure-Python core has no vector sine, so its
``lookup_rows`` is :func:`batch_lookup`, bit for bit the single lookup."""


# ----- per-point tf2 math for sensor data (laser projection)


def slerp_rows(a: Sequence[float], b: Sequence[float], ratios: _F64, out: _F64) -> None:
    """tf2 ``Quaternion::slerp(a, b, r)`` for every r of ``ratios`` (``(N,) float64``)
    into ``out`` (``(N, 4) float64``, x, y, z, w): the angle (``angleShortestPath``,
    ``tf2Acos``'s clamp) and ``1/sin`` are computed once, each row as :func:`slerp`
    computes it (a zero angle returns ``a``; laser_geometry
    ``transformLaserScanToPointCloud_`` calls this per beam).

    Raises:
        ValueError: ``out`` is not ``(N, 4)``, or an array has the wrong dtype/layout.
    """
    rs = _view(ratios, "f", 8, "const double", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = rs.shape[0]
    if o.shape[0] != n or o.shape[1] != 4:
        raise ValueError("slerp_rows: out must be (N, 4) for N ratios")
    ax, ay, az, aw = _double(a[0]), _double(a[1]), _double(a[2]), _double(a[3])
    bx, by, bz, bw = _double(b[0]), _double(b[1]), _double(b[2]), _double(b[3])
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        dot = -dot
        bx, by, bz, bw = -bx, -by, -bz, -bw
    c = _div(
        dot,
        math.sqrt(
            (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
        ),
    )
    if c >= 1.0:
        o[:] = (ax, ay, az, aw)
        return
    theta = math.acos(c)
    d = _div(1.0, math.sin(theta))
    rows = []
    for r in rs.tolist():
        s0 = _sin((1.0 - r) * theta)
        s1 = _sin(r * theta)
        rows.append(
            ((ax * s0 + bx * s1) * d, (ay * s0 + by * s1) * d,
             (az * s0 + bz * s1) * d, (aw * s0 + bw * s1) * d)
        )  # fmt: skip
    if rows:
        o[:] = rows


def apply_transforms(q: _F64, v: _F64, p: _F64, out: _F64) -> None:
    """Point i mapped by the tf2::Transform with rotation ``q[i]`` (x, y, z, w) and origin
    ``v[i]`` (metres), as tf2 computes it: ``Matrix3x3::setRotation`` (its basis, which
    normalises q) then ``Transform::operator()`` (``p.dot3(row0, row1, row2) +
    origin``), in tf2's evaluation order (each numpy operation below is one IEEE
    operation per element). ``q`` (N, 4) or (1, 4), ``v`` (N, 3) or (1, 3), ``p`` and
    ``out`` (N, 3) float64; a single row is used for every point.

    Raises:
        ValueError: shapes other than those, or an array of the wrong dtype/layout.
    """
    qa = _view(q, "f", 8, "const double", 2, False)
    va = _view(v, "f", 8, "const double", 2, False)
    pa = _view(p, "f", 8, "const double", 2, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = pa.shape[0]
    one_q = qa.shape[0] == 1
    one_v = va.shape[0] == 1
    if (
        pa.shape[1] != 3
        or o.shape[0] != n
        or o.shape[1] != 3
        or qa.shape[1] != 4
        or va.shape[1] != 3
        or not (one_q or qa.shape[0] == n)
        or not (one_v or va.shape[0] == n)
    ):
        raise ValueError("apply_transforms: q (N|1, 4), v (N|1, 3), p and out (N, 3)")
    if n == 0:
        return
    x, y, z, w = qa[:, 0], qa[:, 1], qa[:, 2], qa[:, 3]
    with np.errstate(all="ignore"):  # C: IEEE results, no warnings
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
        p0, p1, p2 = pa[:, 0], pa[:, 1], pa[:, 2]
        o[:, 0] = ((m00 * p0 + m01 * p1) + m02 * p2) + va[:, 0]
        o[:, 1] = ((m10 * p0 + m11 * p1) + m12 * p2) + va[:, 1]
        o[:, 2] = ((m20 * p0 + m21 * p1) + m22 * p2) + va[:, 2]


def lerp_rows(a: Sequence[float], b: Sequence[float], ratios: _F64, out: _F64) -> None:
    """``(1 - r) * a + r * b`` per component for every r of ``ratios`` (``(N,)
    float64``) into ``out`` (``(N, 3) float64``): tf2 ``lerp`` of two origins (metres),
    as laser_geometry interpolates the viewpoint between the first and last beam.

    Raises:
        ValueError: ``out`` is not ``(N, 3)``, or an array of the wrong dtype/layout.
    """
    rs = _view(ratios, "f", 8, "const double", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = rs.shape[0]
    if o.shape[0] != n or o.shape[1] != 3:
        raise ValueError("lerp_rows: out must be (N, 3) for N ratios")
    va = (_double(a[0]), _double(a[1]), _double(a[2]))
    vb = (_double(b[0]), _double(b[1]), _double(b[2]))
    with np.errstate(all="ignore"):
        s = 1.0 - rs
        for k in range(3):
            o[:, k] = s * va[k] + rs * vb[k]
