"""The batched lookups' values: one path, many times.

:meth:`BufferCore.lookup_transforms <tfbus.core.BufferCore.lookup_transforms>` answers
``lookup_transform`` for every time of an ``(N,)`` int64 nanosecond array in one call and
returns a :class:`TransformArray`; ``lookup_transforms_full`` composes two such arrays
with :func:`compose_rows`. The core's ``batch_lookup`` (compiled: resolves the path
between the two frames once and gathers and accumulates every link for every time in C;
pure Python: the single walk per time) works in the same arithmetic order as the single
lookup (tf2 ``TimeCache::interpolate`` with tf2's clamped slerp, then ``TransformAccum``),
so each row is the single lookup's result: bit for bit, except that the compiled core's
``lookup_rows`` may take slerp's per-time sines from libmvec's vector sin (rows within
~1e-14 of the single lookup; the tolerance is 1e-12). Times may come in any order. For a
row that cannot be answered at all, the single public ``lookup_transform`` is asked, so
the exception and its message are tf2's by construction.

No threads, no event loop; the awaitable twins are methods of :class:`tfbus.buffer.Buffer`.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Literal, TypeAlias, cast

import numpy as np
import numpy.typing as npt

from tfbus.core.policy import PolicyReport
from tfbus.errors import TransformException, tf2_error_of
from tfbus.messages import TransformStamped
from tfbus.time import Time

__all__ = [
    "Errors",
    "TimesLike",
    "TransformArray",
    "as_times",
    "check_errors",
    "compose_rows",
    "quat_rotate_rows",
    "single_lookups",
]

Errors: TypeAlias = Literal["raise", "mask"]
"""What a batched lookup does with a row it cannot answer: raise tf2's exception or
mask the row (NaN, ``valid[i] = False``)."""

TimesLike: TypeAlias = npt.ArrayLike | Sequence[Time] | Time | int
"""What the batched lookups take as times: ``(N,)`` int64 ns, Times, or one of either."""

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
        error_codes: ``(N,) uint8``, each row's ROS 2 tf2 error code
            (:class:`~tfbus.errors.TF2Error`): 0 for an answered row, else the code of the
            exception the single ``lookup_transform`` raised for that row when the batch
            was looked up (1 lookup, 2 connectivity, 4 invalid argument, 7 backward, 8
            forward, 9 no data for extrapolation). :meth:`error` and
            :meth:`error_message` give a row's exception and message.
        reports: for a lookup under a non-exact policy (:mod:`tfbus.core.policy`), each
            row's :class:`~tfbus.core.policy.PolicyReport` (None for a masked row);
            None for an exact lookup.
        max_abs_delta_ns: with ``reports``, ``(N,) int64``: each row's largest
            ``|sample stamp - time|`` in ns (-1 for a masked row); else None.
    """

    __slots__ = (
        "_errors",
        "child_frame_id",
        "frame_id",
        "max_abs_delta_ns",
        "reports",
        "rotations",
        "stamps",
        "translations",
        "valid",
    )

    def __init__(
        self,
        stamps: _I64,
        translations: _F64,
        rotations: _F64,
        frame_id: str,
        child_frame_id: str,
        valid: npt.NDArray[np.bool_] | None = None,
        *,
        reports: Sequence[PolicyReport | None] | None = None,
        errors: Mapping[int, TransformException] | None = None,
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
        self._errors: dict[int, TransformException] = dict(errors) if errors else {}
        self.reports: tuple[PolicyReport | None, ...] | None = None
        self.max_abs_delta_ns: _I64 | None = None
        if reports is not None:
            if len(reports) != n:
                raise ValueError(f"reports must have {n} entries, got {len(reports)}")
            self.reports = tuple(reports)
            self.max_abs_delta_ns = np.array(
                [-1 if r is None else r.max_abs_delta_ns for r in self.reports], dtype=np.int64
            )

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    @property
    def error_codes(self) -> npt.NDArray[np.uint8]:
        """``(N,) uint8``: each row's :class:`~tfbus.errors.TF2Error` code, 0 where the
        row was answered (see the class's attributes)."""
        codes = np.zeros(len(self), dtype=np.uint8)
        for i, exc in self._errors.items():
            codes[i] = tf2_error_of(exc)
        return codes

    def error(self, i: int) -> TransformException | None:
        """The exception row ``i`` failed with under ``errors="mask"`` (the one the single
        ``lookup_transform`` raised for it: class and message), None for an answered row.

        Raises:
            IndexError: ``i`` is not a row (negative indices count from the end).
        """
        n = len(self)
        k = operator.index(i)
        if not -n <= k < n:
            raise IndexError(f"row {i!r} is out of range for {n} rows")
        return self._errors.get(k % n)

    def error_message(self, i: int) -> str | None:
        """The message of row ``i``'s exception (:meth:`error`), None for an answered row.

        Raises:
            IndexError: ``i`` is not a row.
        """
        exc = self.error(i)
        return None if exc is None else str(exc)

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
        rotated: _F64 = quat_rotate_rows(self.rotations, p) + self.translations
        return rotated


def quat_rotate_rows(q: _F64, v: _F64) -> _F64:
    """tf2's ``quatRotate(q, v)`` = ``q ⊗ (v, 0) ⊗ q*`` element-wise over rows, in
    ``_cmath.quat_rotate``'s evaluation order (bit for bit the scalar kernel's numbers;
    a non-unit ``q`` scales ``v`` by ``|q|²``, as tf2's does). ``q``: ``(..., 4)``
    (x, y, z, w); ``v``: ``(..., 3)`` metres, broadcast against ``q``. Returns
    ``(..., 3) float64``. Source: ``tf2/LinearMath/Quaternion.h`` ``quatRotate``."""
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx = qw * vx + qy * vz - qz * vy
    ty = qw * vy + qz * vx - qx * vz
    tz = qw * vz + qx * vy - qy * vx
    tw = -qx * vx - qy * vy - qz * vz
    out: _F64 = np.stack(
        [
            -tw * qx + tx * qw - ty * qz + tz * qy,
            -tw * qy + ty * qw - tz * qx + tx * qz,
            -tw * qz + tz * qw - tx * qy + ty * qx,
        ],
        axis=-1,
    )
    return out


def as_times(times: TimesLike, n: int | None = None) -> _I64:
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


def check_errors(errors: str) -> None:
    """Raise ValueError unless ``errors`` is ``"raise"`` or ``"mask"``."""
    if errors not in ("raise", "mask"):
        raise ValueError(f"errors must be 'raise' or 'mask', got {errors!r}")


def compose_rows(leg2: TransformArray, leg1: TransformArray) -> TransformArray:
    """Row by row ``leg2 ∘ leg1`` through normalised rotations, in the arithmetic order of
    :meth:`~tfbus.core.BufferCore.lookup_transform_full` (tf2::Transform's multiply):
    the rows of ``lookup_transforms_full``. The stamps are ``leg2``'s, a row is valid
    where both legs are; the frames are ``leg2.frame_id`` and ``leg1.child_frame_id``.
    """
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
    # A row failing on both legs keeps the source leg's exception: the single
    # lookup_transform_full looks that leg up first.
    errors = {**leg2._errors, **leg1._errors}
    return TransformArray(stamps, trans, q, leg2.frame_id, leg1.child_frame_id, valid,
                          errors=errors)


def single_lookups(
    lookup: Callable[[str, str, Time], TransformStamped],
    target_frame: str,
    source_frame: str,
    times: _I64,
    rows: Iterable[int],
) -> Iterator[tuple[int, TransformStamped | TransformException]]:
    """For each row of ``rows`` (indices into ``(N,) int64`` ns ``times``), what
    ``lookup(target_frame, source_frame, Time(times[row]))`` returns or raises (tf2's
    exception and message by construction), asked once per distinct time: how a batch
    tells why the rows its kernel could not answer failed."""
    seen: dict[int, TransformStamped | TransformException] = {}
    for i in rows:
        ns = int(times[i])
        found = seen.get(ns)
        if found is None:
            try:
                found = lookup(target_frame, source_frame, Time.from_ns(ns))
            except TransformException as exc:
                found = exc
            seen[ns] = found
        yield i, found
