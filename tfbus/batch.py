"""Batched lookups: one path, many times (issue 12).

``lookup_transforms(core, target, source, times)`` answers ``lookup_transform`` for every
time of an ``(N,)`` int64 nanosecond array in one call. The core's ``batch_lookup``
(compiled: resolves the path between the two frames once and gathers and accumulates
every link for every time in C; pure Python: the single walk per time) works in the same
arithmetic order as the single lookup (tf2 ``TimeCache::interpolate`` with tf2's clamped
slerp, then ``TransformAccum``), so each row is the single lookup's result: bit for bit,
except that the compiled core's ``lookup_transforms`` entry may take slerp's per-time
sines from libmvec's vector sin (``tfbus._ccore._batch_lookup_vector``, if
``_BATCH_VECTOR_SIN``), a few ulp from libm's (rows within ~1e-14 of the single lookup;
issue 12 allows 1e-12). Times may come in any order (the compiled core walks
unsorted times sorted and writes each row back: as fast as sorted times). Rows the
compiled plan cannot take (time 0, a link whose parent changed) go through the core's
scalar walk; for a row that cannot be answered at all, the single public
``lookup_transform`` is asked, so the exception and its message are tf2's by
construction.

:class:`BatchLookupMixin` puts these functions on :class:`tfbus.core.BufferCore` as
methods; the functions take any object with the public lookups of BufferCore (this
module does not import :mod:`tfbus.core`, which imports it). Layer 1 (sans-I/O): no
threads, no event loop; the awaitable twins are in :mod:`tfbus.batch_async`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final, Literal, Protocol, cast

import numpy as np
import numpy.typing as npt

from tfbus._backend import IMPLEMENTATION, CoreBase, batch_lookup
from tfbus.errors import TransformException
from tfbus.geometry import apply_transform
from tfbus.messages import TransformStamped
from tfbus.time import Time

#: The rows of :func:`lookup_transforms`: the compiled core's entry that may take slerp's
#: per-time sines from libmvec (within 1e-12 of the single lookup), else the core's exact
#: ``batch_lookup`` (the pure-Python core has only that one).
_lookup_rows: Final[Callable[..., int]] = getattr(
    IMPLEMENTATION, "_batch_lookup_vector", batch_lookup
)


class Lookups(Protocol):
    """What the batched lookups need of a buffer: :class:`tfbus.core.BufferCore`'s
    public single lookups (structural type, so this module needs no import of it)."""

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: Time
    ) -> TransformStamped: ...

    def try_lookup_transform(
        self, target_frame: str, source_frame: str, time: Time
    ) -> TransformStamped | TransformException: ...

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
    ) -> TransformStamped: ...

    def frame_exists(self, frame_id: str) -> bool: ...

    def invalid_frame_id(self, frame_id: str, argument: str = ...) -> Exception | None: ...


__all__ = [
    "BatchLookupMixin",
    "TransformArray",
    "as_times",
    "lookup_transforms",
    "lookup_transforms_full",
    "transform_points",
]

Errors = Literal["raise", "mask"]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]


class TransformArray:
    """N transforms between one pair of frames, one per time (the batched
    ``TransformStamped``).

    Attributes:
        stamps: ``(N,) int64`` nanoseconds, the time each row was taken at (a requested
            time 0 becomes the latest common time, as in ``lookup_transform``).
        translations: ``(N, 3) float64`` metres.
        rotations: ``(N, 4) float64`` quaternions in (x, y, z, w) order.
        frame_id: the target frame (the rows map ``child_frame_id`` data into it).
        child_frame_id: the source frame.
        valid: ``(N,) bool``; False only for rows that failed under ``errors="mask"``
            (their translation and rotation are NaN, their stamp the requested time).
    """

    __slots__ = ("child_frame_id", "frame_id", "rotations", "stamps", "translations", "valid")

    def __init__(
        self,
        stamps: _I64,
        translations: _F64,
        rotations: _F64,
        frame_id: str,
        child_frame_id: str,
        valid: npt.NDArray[np.bool_] | None = None,
    ) -> None:
        n = stamps.shape[0]
        if translations.shape != (n, 3) or rotations.shape != (n, 4):
            raise ValueError(
                f"translations must be ({n}, 3) and rotations ({n}, 4), "
                f"got {translations.shape} and {rotations.shape}"
            )
        self.stamps = stamps
        self.translations = translations
        self.rotations = rotations
        self.frame_id = frame_id
        self.child_frame_id = child_frame_id
        self.valid = np.ones(n, dtype=bool) if valid is None else valid

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    def __repr__(self) -> str:
        return (
            f"TransformArray(frame_id={self.frame_id!r}, "
            f"child_frame_id={self.child_frame_id!r}, n={len(self)}, "
            f"invalid={int(np.count_nonzero(~self.valid))})"
        )

    def as_matrices(self) -> _F64:
        """``(N, 4, 4) float64`` homogeneous matrices ``[[R, t], [0, 0, 0, 1]]`` acting on
        column vectors; R is the matrix of ``v -> q v q*`` (tf2 ``quatRotate``, exact for
        unit quaternions; for a non-unit q it scales by ``|q|²`` as tf2 does). NaN rows
        stay NaN."""
        x, y, z, w = (self.rotations[:, k] for k in range(4))
        n = len(self)
        m = np.zeros((n, 4, 4))
        m[:, 0, 0] = w * w + x * x - y * y - z * z
        m[:, 0, 1] = 2 * (x * y - w * z)
        m[:, 0, 2] = 2 * (x * z + w * y)
        m[:, 1, 0] = 2 * (x * y + w * z)
        m[:, 1, 1] = w * w - x * x + y * y - z * z
        m[:, 1, 2] = 2 * (y * z - w * x)
        m[:, 2, 0] = 2 * (x * z - w * y)
        m[:, 2, 1] = 2 * (y * z + w * x)
        m[:, 2, 2] = w * w - x * x - y * y + z * z
        m[:, :3, 3] = self.translations
        m[:, 3, 3] = 1.0
        return m

    def apply(self, points: npt.ArrayLike) -> _F64:
        """Map ``(N, 3)`` points, row i through transform i (``quatRotate(q, p) + t``,
        tf2's order), into ``frame_id``. Returns ``(N, 3) float64``.

        Raises:
            ValueError: ``points`` is not ``(N, 3)`` for this array's N.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.shape != (len(self), 3):
            raise ValueError(f"points must have shape ({len(self)}, 3), got {p.shape}")
        return apply_transform(self.translations, self.rotations, p)


def as_times(times: npt.ArrayLike | Sequence[Time] | Time | int, n: int | None = None) -> _I64:
    """``times`` as a contiguous ``(N,) int64`` array of nanoseconds.

    Accepts an integer array, a sequence of :class:`~tfbus.time.Time` or ints, or one
    Time / int (broadcast to ``n`` rows when ``n`` is given).

    Raises:
        ValueError: not one-dimensional, not integers (floats are refused: seconds near
            1.7e9 cannot hold nanoseconds), negative, or of the wrong length.
    """
    if isinstance(times, Time):
        arr = np.array([times.ns], dtype=np.int64)
    elif isinstance(times, (list, tuple)) and times and isinstance(times[0], Time):
        if not all(isinstance(t, Time) for t in times):
            raise ValueError("times mixes Time and other values")
        arr = np.fromiter((t.ns for t in cast("Sequence[Time]", times)), np.int64, len(times))
    else:
        raw = np.asarray(times)
        if raw.ndim == 0:
            raw = raw.reshape(1)
        if raw.size and raw.dtype.kind not in "iu":
            raise ValueError(
                f"times must be integer nanoseconds (or Time objects), got dtype {raw.dtype}"
            )
        if raw.dtype.kind == "u" and raw.size and int(raw.max()) > np.iinfo(np.int64).max:
            raise ValueError("times exceed the int64 nanosecond range")
        arr = raw.astype(np.int64, copy=False)
    if arr.ndim != 1:
        raise ValueError(f"times must be one-dimensional (N,), got shape {arr.shape}")
    if arr.size and int(arr.min()) < 0:
        raise ValueError(f"times must be >= 0 ns, got {int(arr.min())}")
    if n is not None and arr.shape[0] != n:
        if arr.shape[0] == 1:
            arr = np.full(n, arr[0], dtype=np.int64)
        else:
            raise ValueError(f"times has {arr.shape[0]} entries, expected {n}")
    return np.ascontiguousarray(arr)


def _check_errors(errors: str) -> None:
    if errors not in ("raise", "mask"):
        raise ValueError(f"errors must be 'raise' or 'mask', got {errors!r}")


def lookup_transforms(
    core: Lookups,
    target_frame: str,
    source_frame: str,
    times: npt.ArrayLike | Sequence[Time] | Time | int,
    *,
    errors: Errors = "raise",
) -> TransformArray:
    """``lookup_transform(target_frame, source_frame, t)`` for every t of ``times``.

    Args:
        core: the buffer to read.
        target_frame: frame to express data in.
        source_frame: frame the data is in.
        times: ``(N,) int64`` nanoseconds (or Times); 0 means latest, as in tf2.
        errors: ``"raise"`` (default) or ``"mask"``: failed rows become NaN with
            ``valid[i] = False`` and the call does not raise for missing data.

    Returns:
        A :class:`TransformArray` whose row i equals ``lookup_transform`` at ``times[i]``
        (stamp = the time used; values to the bit, or within 1e-12 where slerp's sines
        are vectorised: see the module docstring).

    Raises:
        InvalidArgumentException: a frame id is empty or starts with '/' (always, as the
            single lookup validates before looking at times).
        LookupException, ConnectivityException, ExtrapolationException: with
            ``errors="raise"``, the exception and message the single lookup raises for
            the first time that cannot be answered. With ``errors="mask"`` an unknown
            frame id still raises LookupException (no row could ever be answered).
        ValueError: ``times`` or ``errors`` is malformed.

    Source: tf2 ``BufferCore::lookupTransform`` / ``walkToTopParent`` per time.
    """
    _check_errors(errors)
    t = as_times(times)
    n = t.shape[0]
    out = np.empty((n, 7))
    stamps = t.copy()
    valid = np.ones(n, dtype=bool)
    if target_frame == source_frame:
        # The single lookup validates nothing here; time 0 is stamped with the frame's
        # newest sample: ask it once.
        out[:] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        zero = t == 0
        if zero.any():
            stamps[zero] = core.lookup_transform(target_frame, source_frame, Time()).header.stamp.ns
        return TransformArray(stamps, out[:, :3], out[:, 3:], target_frame, source_frame)
    if not isinstance(core, CoreBase):
        raise TypeError(f"core must be a tfbus BufferCore, got {type(core).__name__}")
    ok = np.empty(n, dtype=np.int8)
    answered = _lookup_rows(core, target_frame, source_frame, t, out, stamps, ok)
    if answered < 0:
        # An invalid or unknown frame id: the single lookup raises tf2's exception.
        core.lookup_transform(target_frame, source_frame, Time.from_ns(int(t[0]) if n else 0))
        raise AssertionError("lookup_transform accepted an id batch_lookup refused")
    if answered != n:
        bad = np.flatnonzero(ok == 0)
        if errors == "raise":
            core.lookup_transform(target_frame, source_frame, Time.from_ns(int(t[bad[0]])))
            raise AssertionError("lookup_transform answered a time the walk could not")
        out[bad] = math.nan
        valid[bad] = False
    return TransformArray(stamps, out[:, :3], out[:, 3:], target_frame, source_frame, valid)


def lookup_transforms_full(
    core: Lookups,
    target_frame: str,
    target_times: npt.ArrayLike | Sequence[Time] | Time | int,
    source_frame: str,
    source_times: npt.ArrayLike | Sequence[Time] | Time | int,
    fixed_frame: str,
    *,
    errors: Errors = "raise",
) -> TransformArray:
    """``lookup_transform_full`` (time travel through ``fixed_frame``) row by row.

    ``target_times`` and ``source_times`` are ``(N,)`` int64 ns (or Times); either may be
    a single time, broadcast to the other's N. Row i is
    ``lookup(target ← fixed @ target_times[i]) ∘ lookup(fixed ← source @
    source_times[i])`` through normalised rotations, exactly as
    :meth:`~tfbus.core.BufferCore.lookup_transform_full` computes it; its stamp is the
    second leg's.

    Raises:
        InvalidArgumentException, LookupException: a frame id is invalid or unknown
            (validated in the order target, source, fixed).
        ConnectivityException, ExtrapolationException: as the single call for the first
            failing row (source leg first), unless ``errors="mask"``.
        ValueError: the time arrays have different lengths, or are malformed.
    """
    _check_errors(errors)
    frames = (target_frame, source_frame, fixed_frame)
    if not all(core.invalid_frame_id(f) is None and core.frame_exists(f) for f in frames):
        # The single call validates the three ids first, in this order: let it raise.
        core.lookup_transform_full(target_frame, Time(), source_frame, Time(), fixed_frame)
    tt = as_times(target_times)
    st = as_times(source_times)
    n = max(tt.shape[0], st.shape[0])
    tt, st = as_times(tt, n), as_times(st, n)
    if errors == "raise":
        # The single call looks up leg 1 then leg 2 per time: the first failing row
        # decides, and within it the source leg.
        leg1 = lookup_transforms(core, fixed_frame, source_frame, st, errors="mask")
        leg2 = lookup_transforms(core, target_frame, fixed_frame, tt, errors="mask")
        bad = np.flatnonzero(~(leg1.valid & leg2.valid))
        if bad.size:
            i = int(bad[0])
            core.lookup_transform_full(
                target_frame,
                Time.from_ns(int(tt[i])),
                source_frame,
                Time.from_ns(int(st[i])),
                fixed_frame,
            )
            raise AssertionError("lookup_transform_full did not raise")  # pragma: no cover
    else:
        leg1 = lookup_transforms(core, fixed_frame, source_frame, st, errors="mask")
        leg2 = lookup_transforms(core, target_frame, fixed_frame, tt, errors="mask")
    x1, y1, z1 = (leg1.translations[:, k] for k in range(3))
    x2, y2, z2 = (leg2.translations[:, k] for k in range(3))
    a = leg2.rotations / np.sqrt(np.sum(leg2.rotations * leg2.rotations, axis=1))[:, None]
    b = leg1.rotations / np.sqrt(np.sum(leg1.rotations * leg1.rotations, axis=1))[:, None]
    ax, ay, az, aw = (a[:, k] for k in range(4))
    bx, by, bz, bw = (b[:, k] for k in range(4))
    # The order of BufferCore.lookup_transform_full (tf2::Transform's multiply).
    tx = aw * x1 + ay * z1 - az * y1
    ty = aw * y1 + az * x1 - ax * z1
    tz = aw * z1 + ax * y1 - ay * x1
    tw = -ax * x1 - ay * y1 - az * z1
    q = np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by + ay * bw + az * bx - ax * bz,
            aw * bz + az * bw + ax * by - ay * bx,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=1,
    )
    q /= np.sqrt(q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2] + q[:, 3] * q[:, 3])[
        :, None
    ]
    trans = np.stack(
        [
            -tw * ax + tx * aw - ty * az + tz * ay + x2,
            -tw * ay + ty * aw - tz * ax + tx * az + y2,
            -tw * az + tz * aw - tx * ay + ty * ax + z2,
        ],
        axis=1,
    )
    valid = leg1.valid & leg2.valid
    stamps = leg2.stamps.copy()
    return TransformArray(stamps, trans, q, target_frame, source_frame, valid)


def transform_points(
    core: Lookups,
    points: npt.ArrayLike,
    target_frame: str,
    source_frame: str,
    times: npt.ArrayLike | Sequence[Time] | Time | int,
    *,
    errors: Errors = "raise",
) -> _F64:
    """Map each point of ``points`` from ``source_frame`` into ``target_frame`` at its own
    time (per-beam projection, lidar de-skewing).

    Args:
        points: ``(N, 3)`` metres in ``source_frame``.
        times: ``(N,) int64`` ns (or one time for all points).
        errors: ``"mask"`` gives NaN rows for points whose time cannot be answered.

    Returns:
        ``(N, 3) float64`` metres: row i is ``quatRotate(q_i, p_i) + t_i`` with
        ``(t_i, q_i) = lookup_transform(target_frame, source_frame, times[i])``.

    Raises:
        ValueError: ``points`` is not ``(N, 3)`` or ``times`` does not match.
        TransformException subclasses: as :func:`lookup_transforms`.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {p.shape}")
    tf = lookup_transforms(
        core, target_frame, source_frame, as_times(times, p.shape[0]), errors=errors
    )
    return tf.apply(p)


class BatchLookupMixin:
    """The batched lookups as :class:`~tfbus.core.BufferCore` methods."""

    __slots__ = ()

    def lookup_transforms(
        self,
        target_frame: str,
        source_frame: str,
        times: npt.ArrayLike | Sequence[Time] | Time | int,
        *,
        errors: Errors = "raise",
    ) -> TransformArray:
        """:func:`tfbus.batch.lookup_transforms` on this buffer (see there)."""
        return lookup_transforms(
            cast(Lookups, self), target_frame, source_frame, times, errors=errors
        )

    def lookup_transforms_full(
        self,
        target_frame: str,
        target_times: npt.ArrayLike | Sequence[Time] | Time | int,
        source_frame: str,
        source_times: npt.ArrayLike | Sequence[Time] | Time | int,
        fixed_frame: str,
        *,
        errors: Errors = "raise",
    ) -> TransformArray:
        """:func:`tfbus.batch.lookup_transforms_full` on this buffer (see there)."""
        return lookup_transforms_full(
            cast(Lookups, self),
            target_frame,
            target_times,
            source_frame,
            source_times,
            fixed_frame,
            errors=errors,
        )

    def transform_points(
        self,
        points: npt.ArrayLike,
        target_frame: str,
        source_frame: str,
        times: npt.ArrayLike | Sequence[Time] | Time | int,
        *,
        errors: Errors = "raise",
    ) -> _F64:
        """:func:`tfbus.batch.transform_points` on this buffer (see there)."""
        return transform_points(
            cast(Lookups, self), points, target_frame, source_frame, times, errors=errors
        )
