"""Laser projection: LaserScan -> PointCloud2, with laser_geometry's semantics.

:class:`LaserProjection` reproduces ROS 1 laser_geometry 1.6 (``laser_geometry.cpp``,
the PointCloud2 overloads of ``projectLaser_`` and ``transformLaserScanToPointCloud_``
with a ``tf2::BufferCore``), vectorised with numpy over the beams, and is checked point
for point against the compiled library (``tests/sensors/test_laser.py``):

* beam i is kept iff ``ranges[i] < range_cutoff`` (as double; ``range_cutoff < 0`` means
  ``range_max``) and ``ranges[i] >= range_min`` (as float): NaN is always dropped, +inf
  dropped, -inf dropped unless ``range_min`` is -inf;
* its point is ``(float)(r * cos(a_i)), (float)(r * sin(a_i)), 0`` with
  ``a_i = angle_min + (double)i * angle_increment`` in double; the cos/sin table is cached
  per projector keyed by (beam count, angle_min, angle_max) — not by angle_increment,
  exactly as laser_geometry caches ``co_sine_map_``;
* channels, in this field order: ``intensity`` (float32, only if the scan has
  intensities), ``index`` (int32), ``distances`` (float32 range), ``stamps`` (float32
  ``(float)i * time_increment``), ``vp_x, vp_y, vp_z`` (viewpoint, 0 before transforming);
* transforming looks up ``target ← scan frame`` at the header stamp and at the last beam's
  time ``stamp + Duration::fromSec((float)(n - 1) * time_increment)``, and maps the point
  of beam i through ``slerp``/``setInterpolate3`` of the two at ratio
  ``i * (1 / (n - 1.0))`` (tf2 ``Quaternion::slerp``, ``Transform::setRotation``, the
  basis applied row by row), rounding the result to float32. The viewpoint becomes the
  interpolated origin.

``interpolation="per_beam"`` instead looks every beam up at its own time with
:meth:`~tfbus.core.BufferCore.lookup_transforms` (exact when the motion within a sweep is
not uniform); ``interpolation="stamp"`` uses the header stamp's transform for all beams
(what a plain ``tf2_sensor_msgs`` ``doTransform`` of the projected cloud does).
"""

from __future__ import annotations

import enum
import math
import sys
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from tfbus.buffer import Buffer
from tfbus.core import BufferCore
from tfbus.core.kernels import apply_transforms, compiled_extension, lerp_rows, slerp_rows
from tfbus.messages import Header
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField
from tfbus.time import Duration, Time

if TYPE_CHECKING:
    from tfbus._claser import Projector

__all__ = [
    "ChannelOption",
    "Interpolation",
    "LaserProjection",
    "beam_time_offsets_ns",
]

Interpolation = Literal["laser_geometry", "per_beam", "stamp"]

_F64 = npt.NDArray[np.float64]


class ChannelOption(enum.IntFlag):
    """laser_geometry ``channel_option``: which channels a projection adds."""

    NONE = 0x00
    INTENSITY = 0x01
    INDEX = 0x02
    DISTANCE = 0x04
    TIMESTAMP = 0x08
    VIEWPOINT = 0x10
    DEFAULT = 0x03  # INTENSITY | INDEX


def _from_sec_ns(d: float) -> int:
    """ros::Duration::fromSec(d) in nanoseconds (rostime ``DurationBase::fromSec``:
    sec = floor(d), nsec = round-half-away((d - sec) * 1e9), with rollover).

    Raises:
        ValueError: ``d`` is not finite or outside the int32 seconds range (rostime
            throws std::runtime_error there).
    """
    if not math.isfinite(d) or not -(2**31) <= math.floor(d) <= 2**31 - 1:
        raise ValueError(f"scan duration {d!r} s is out of ros::Duration's range")
    sec = math.floor(d)
    frac = (d - sec) * 1e9  # >= 0
    # boost::math::round (half away from zero), in its own steps: ceil, then step back.
    nsec = 0 if frac < 0.5 else math.ceil(frac)
    if nsec and nsec - frac > 0.5:
        nsec -= 1
    return sec * 1_000_000_000 + nsec


def beam_time_offsets_ns(
    scan: LaserScan, indices: npt.ArrayLike | None = None
) -> npt.NDArray[np.int64]:
    """Time of beam i after the header stamp, ns, computed as laser_geometry computes the
    last beam's: ``Duration::fromSec((float)i * time_increment)`` (float32 product, then
    rostime's rounding, see :func:`_from_sec_ns`), vectorised.

    Returns:
        ``(M,) int64`` for the given beam indices (all beams when None).

    Raises:
        ValueError: a product is not finite or out of ros::Duration's range.
    """
    idx = np.arange(len(scan.ranges)) if indices is None else np.asarray(indices)
    with np.errstate(all="ignore"):
        d = (idx.astype(np.float32) * np.float32(scan.time_increment)).astype(np.float64)
        sec = np.floor(d)
        if d.size and not (np.isfinite(d).all() and sec.min() >= -(2.0**31)
                           and sec.max() <= 2.0**31 - 1):  # fmt: skip
            raise ValueError("a beam's time offset is out of ros::Duration's range")
        frac = (d - sec) * 1e9
        nsec = np.where(frac < 0.5, 0.0, np.ceil(frac))
        nsec -= (nsec != 0) & (nsec - frac > 0.5)
    offsets: npt.NDArray[np.int64] = sec.astype(np.int64) * 1_000_000_000 + nsec.astype(np.int64)
    return offsets


def _end_time(scan: LaserScan) -> Time:
    n = len(scan.ranges)
    if n == 0:
        return scan.header.stamp
    d = float(np.float32(n - 1) * np.float32(scan.time_increment))
    return Time.from_ns(scan.header.stamp.ns + _from_sec_ns(d))


_INTENSITY, _INDEX, _DISTANCE, _TIMESTAMP, _VIEWPOINT = 0x01, 0x02, 0x04, 0x08, 0x10
_FIELDS: dict[tuple[str, ...], list[PointField]] = {}  # PointField lists by layout
_CHANNELS = _INTENSITY | _INDEX | _DISTANCE | _TIMESTAMP | _VIEWPOINT
# (fields, point step) by channel flags (at most 32 entries: the flags above only)
_LAYOUT_OF: dict[int, tuple[list[PointField], int]] = {}


def _compiled_projector() -> type[Projector] | None:
    """The compiled projection (:mod:`tfbus._claser`, where
    :func:`~tfbus.core.kernels.compiled_extension` finds it) on a little-endian machine (it
    writes the cloud's bytes in native order), else None: the numpy path."""
    module = compiled_extension("tfbus._claser") if sys.byteorder == "little" else None
    if module is None:
        return None
    compiled: type[Projector] = module.Projector
    return compiled


_PROJECTOR = _compiled_projector()


def _layout(opts: int) -> tuple[str, ...]:
    """The cloud's field names for the channel flags ``opts`` (laser_geometry's order)."""
    names = ["x", "y", "z"]
    if opts & _INTENSITY:
        names.append("intensity")
    if opts & _INDEX:
        names.append("index")
    if opts & _DISTANCE:
        names.append("distances")
    if opts & _TIMESTAMP:
        names.append("stamps")
    if opts & _VIEWPOINT:
        names += ["vp_x", "vp_y", "vp_z"]
    return tuple(names)


def _fields_of(names: tuple[str, ...]) -> list[PointField]:
    """The PointFields of a cloud of 4-byte ``names`` (``index`` int32, the rest float32),
    kept in ``_FIELDS``."""
    fields = _FIELDS.get(names)
    if fields is None:
        fields = _FIELDS[names] = [
            PointField(name, 4 * k, PointField.INT32 if name == "index" else PointField.FLOAT32)
            for k, name in enumerate(names)
        ]
    return fields


class LaserProjection:
    """Projects LaserScans to PointCloud2s (laser_geometry ``LaserProjection``).

    One instance keeps laser_geometry's cos/sin table of the last scan layout seen; use
    one per scan source, as in ROS. Not thread-safe.
    """

    def __init__(self) -> None:
        self._key: tuple[int, float, float] | None = None  # beams, angle_min, increment
        self._cos = np.zeros(0)
        self._sin = np.zeros(0)
        self._projector = _PROJECTOR() if _PROJECTOR is not None else None

    # ------------------------------------------------------------------ projection

    def _table(self, scan: LaserScan) -> tuple[_F64, _F64]:
        n = len(scan.ranges)
        key = (n, scan.angle_min, scan.angle_increment)  # what the angles depend on
        if key != self._key:
            angles = scan.angle_min + np.arange(n, dtype=np.float64) * scan.angle_increment
            self._cos, self._sin = np.cos(angles), np.sin(angles)
            self._key = key
        return self._cos, self._sin

    def _project(
        self, scan: LaserScan, range_cutoff: float, opts: int
    ) -> tuple[list[str], npt.NDArray[np.int64], npt.NDArray[np.float32]]:
        """laser_geometry ``projectLaser_`` (PointCloud2): the field names, the kept beam
        indices and the points as a ``(kept, fields)`` float32 matrix in the cloud's
        layout (the ``index`` column holds int32 bits)."""
        ranges = scan.ranges
        n = len(ranges)
        has_intensity = bool(opts & _INTENSITY) and len(scan.intensities) > 0
        if has_intensity and len(scan.intensities) < n:
            raise ValueError(
                f"LaserScan.intensities has {len(scan.intensities)} values for {n} ranges"
            )
        names = list(_layout(opts if has_intensity else opts & ~_INTENSITY))
        cos, sin = self._table(scan)
        r64 = ranges.astype(np.float64)
        cutoff = float(scan.range_max) if range_cutoff < 0 else float(range_cutoff)
        # (callers hold np.errstate(all="ignore"): NaN / inf beams as in C++)
        keep = np.flatnonzero((r64 < cutoff) & (ranges >= np.float32(scan.range_min)))
        cols = np.zeros((keep.shape[0], len(names)), dtype=np.float32)
        if keep.shape[0] == n:  # every beam kept (the usual case): no gathers
            cols[:, 0] = r64 * cos
            cols[:, 1] = r64 * sin
        else:
            rk = r64[keep]
            cols[:, 0] = rk * cos[keep]
            cols[:, 1] = rk * sin[keep]
        k = 3
        if has_intensity:
            cols[:, k] = scan.intensities[keep]
            k += 1
        if opts & _INDEX:
            cols.view(np.int32)[:, k] = keep
            k += 1
        if opts & _DISTANCE:
            cols[:, k] = ranges[keep]
            k += 1
        if opts & _TIMESTAMP:
            cols[:, k] = keep.astype(np.float32) * np.float32(scan.time_increment)
        return names, keep, cols

    @staticmethod
    def _cloud(header: Header, names: list[str], cols: npt.NDArray[np.float32]) -> PointCloud2:
        data = cols.astype("<f4", copy=False).tobytes()
        return LaserProjection._cloud_bytes(header, tuple(names), cols.shape[0], data)

    @staticmethod
    def _cloud_bytes(
        header: Header, names: tuple[str, ...], width: int, data: bytes
    ) -> PointCloud2:
        fields = _FIELDS.get(names) or _fields_of(names)
        step = 4 * len(names)
        # PointCloud2's fields in order: header, height, width, fields, is_bigendian,
        # point_step, row_step, data, is_dense (positional: half the keyword call's time)
        return PointCloud2(header, 1, width, list(fields), False, step, step * width, data,
                           False)

    @staticmethod
    def _layout_of(opts: int) -> tuple[list[PointField], int]:
        """The cloud's fields and point step for the channel flags ``opts``."""
        found = _LAYOUT_OF.get(opts)
        if found is None:
            names = _layout(opts)
            found = _LAYOUT_OF[opts] = (_fields_of(names), 4 * len(names))
        return found

    def project_laser(
        self,
        scan: LaserScan,
        range_cutoff: float = -1.0,
        channel_options: int = ChannelOption.DEFAULT,
    ) -> PointCloud2:
        """Project a scan into its own frame (laser_geometry ``projectLaser`` to
        PointCloud2).

        Args:
            scan: the scan; its header is copied to the cloud.
            range_cutoff: metres; beams at or beyond it are dropped (< 0: ``range_max``).
            channel_options: OR of :class:`ChannelOption` flags.

        Returns:
            An unordered (height 1) little-endian cloud of float32 ``x, y, z`` (metres)
            plus the requested channels, one point per kept beam in beam order.

        Raises:
            ValueError: the scan has intensities, fewer than its ranges (laser_geometry
                would read out of bounds).
        """
        opts = int(channel_options)
        projector = self._projector
        if projector is not None:  # the same bytes, in one compiled pass
            cos, sin = self._table(scan)
            if projector.key is not self._key:
                projector.set_table(self._key, cos, sin)
            ranges, intensities = scan.ranges, scan.intensities
            n = len(ranges)
            if not (opts & _INTENSITY and len(intensities) > 0):
                opts &= ~_INTENSITY
            elif len(intensities) < n:
                raise ValueError(
                    f"LaserScan.intensities has {len(intensities)} values for {n} ranges"
                )
            cutoff = float(scan.range_max) if range_cutoff < 0 else float(range_cutoff)
            data, kept = projector.project(ranges, intensities, opts, cutoff,
                                           scan.range_min, scan.time_increment)  # fmt: skip
            layout = _LAYOUT_OF.get(opts & _CHANNELS)
            fields, step = layout if layout is not None else self._layout_of(opts & _CHANNELS)
            return PointCloud2(scan.header, 1, kept, list(fields), False, step, step * kept,
                               data, False)  # positional, as in _cloud_bytes
        with np.errstate(all="ignore"):
            names, _, cols = self._project(scan, range_cutoff, opts)
        return self._cloud(scan.header, names, cols)

    # ------------------------------------------------------------------ transforming

    def transform_laser_scan_to_point_cloud(
        self,
        target_frame: str,
        scan: LaserScan,
        buffer: BufferCore,
        range_cutoff: float = -1.0,
        channel_options: int = ChannelOption.DEFAULT,
        *,
        interpolation: Interpolation = "laser_geometry",
        fixed_frame: str | None = None,
    ) -> PointCloud2:
        """Project a scan and express it in ``target_frame``, correcting for the sensor's
        motion during the sweep (laser_geometry ``transformLaserScanToPointCloud`` with a
        ``tf2::BufferCore``).

        Args:
            target_frame: frame of the output cloud.
            scan: ``header.stamp`` is the first beam's time; beam i was taken
                ``i * time_increment`` seconds later.
            buffer: where transforms are looked up.
            range_cutoff, channel_options: as :meth:`project_laser`.
            interpolation: ``"laser_geometry"`` (look up the first and last beam, slerp
                between them per beam), ``"per_beam"`` (look up every kept beam at its
                own time) or ``"stamp"`` (the header stamp's transform for every beam).
            fixed_frame: with ``"laser_geometry"``, laser_geometry's fixed-frame overload:
                the end transform is ``lookup_transform_full(target @ stamp, scan frame @
                end, fixed_frame)``.

        Returns:
            A cloud like :meth:`project_laser`'s with ``header.frame_id = target_frame``
            and float32 points (and viewpoint) in that frame.

        Raises:
            LookupException, ConnectivityException, ExtrapolationException,
            InvalidArgumentException: from the lookups (tf2's messages).
            ValueError: bad ``interpolation`` or malformed scan.
        """
        with np.errstate(all="ignore"):  # NaN / inf beams propagate as in C++
            return self._transform(
                target_frame, scan, buffer, range_cutoff, int(channel_options), interpolation,
                fixed_frame,
            )  # fmt: skip

    def _transform(
        self,
        target_frame: str,
        scan: LaserScan,
        buffer: BufferCore,
        range_cutoff: float,
        opts: int,
        interpolation: Interpolation,
        fixed_frame: str | None,
    ) -> PointCloud2:
        frame = scan.header.frame_id
        start = scan.header.stamp
        names, keep, cols = self._project(scan, range_cutoff, opts | _INDEX)
        n = len(scan.ranges)
        p = cols[:, :3].astype(np.float64)  # (kept, 3), the float32 points
        q: _F64
        v: _F64
        if interpolation == "laser_geometry":
            end = _end_time(scan)
            ts0 = buffer.lookup_transform(target_frame, frame, start)
            if fixed_frame is None:
                ts1 = buffer.lookup_transform(target_frame, frame, end)
            else:
                ts1 = buffer.lookup_transform_full(target_frame, start, frame, end, fixed_frame)
            # n = 1: 1 / 0 = inf and a NaN ratio, as in C++
            ratio = keep * (np.float64(1.0) / np.float64(float(n) - 1.0))
            v = np.empty((ratio.shape[0], 3))
            lerp_rows(ts0.transform.translation, ts1.transform.translation, ratio, v)
            q = np.empty((ratio.shape[0], 4))
            slerp_rows(ts0.transform.rotation, ts1.transform.rotation, ratio, q)
        elif interpolation == "per_beam":
            times = start.ns + beam_time_offsets_ns(scan, keep)
            arr = buffer.lookup_transforms(target_frame, frame, times)
            v, q = arr.translations, arr.rotations
        elif interpolation == "stamp":
            ts0 = buffer.lookup_transform(target_frame, frame, start)
            v = np.array([ts0.transform.translation])
            q = np.array([ts0.transform.rotation])
        else:
            raise ValueError(
                "interpolation must be 'laser_geometry', 'per_beam' or 'stamp', "
                f"got {interpolation!r}"
            )
        out = np.empty_like(p)
        apply_transforms(np.ascontiguousarray(q), np.ascontiguousarray(v), p, out)
        cols[:, :3] = out
        if opts & _VIEWPOINT:
            apply_transforms(
                np.ascontiguousarray(q), np.ascontiguousarray(v), np.zeros_like(p), out
            )
            cols[:, -3:] = out
        if not opts & _INDEX:
            j = names.index("index")
            names = names[:j] + names[j + 1 :]
            cols = np.delete(cols, j, axis=1)
        return self._cloud(Header(start, target_frame), names, cols)

    async def transform_laser_scan_to_point_cloud_async(
        self,
        target_frame: str,
        scan: LaserScan,
        buffer: Buffer,
        range_cutoff: float = -1.0,
        channel_options: int = ChannelOption.DEFAULT,
        *,
        interpolation: Interpolation = "laser_geometry",
        fixed_frame: str | None = None,
        timeout: float | Duration | None = None,
    ) -> PointCloud2:
        """:meth:`transform_laser_scan_to_point_cloud`, first waiting (on a
        :class:`~tfbus.buffer.Buffer`, event-driven) until the last beam's transform
        can be looked up.

        Raises:
            TimeoutException: the transforms did not arrive within ``timeout`` seconds of
                the buffer's clock.
            TransformException subclasses: as the synchronous method.
        """
        frame = scan.header.frame_id
        # The last beam is the newest time needed; data up to it covers the first beam
        # too, unless that has fallen out of the cache (then the lookup below raises).
        await buffer.wait_for_transform(target_frame, frame, _end_time(scan), timeout)
        return self.transform_laser_scan_to_point_cloud(
            target_frame, scan, buffer, range_cutoff, channel_options,
            interpolation=interpolation, fixed_frame=fixed_frame,
        )  # fmt: skip
