"""Laser projection: LaserScan -> PointCloud2, with laser_geometry's semantics.

:class:`LaserProjection` reproduces ROS 1 laser_geometry 1.6 (``laser_geometry.cpp``,
the PointCloud2 overloads of ``projectLaser_`` and ``transformLaserScanToPointCloud_``
with a ``tf2::BufferCore``), vectorised with numpy over the beams, and is checked point
for point against the compiled library (``tests/test_laser.py``):

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
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore
from tfbus.messages import Header
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField
from tfbus.time import Duration, Time

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
    last beam's: ``Duration::fromSec((float)i * time_increment)`` (float32 product).

    Returns:
        ``(M,) int64`` for the given beam indices (all beams when None).
    """
    idx = np.arange(len(scan.ranges)) if indices is None else np.asarray(indices)
    prod = idx.astype(np.float32) * np.float32(scan.time_increment)
    return np.array([_from_sec_ns(float(v)) for v in prod.tolist()], dtype=np.int64)


def _end_time(scan: LaserScan) -> Time:
    n = len(scan.ranges)
    if n == 0:
        return scan.header.stamp
    d = float(np.float32(n - 1) * np.float32(scan.time_increment))
    return Time.from_ns(scan.header.stamp.ns + _from_sec_ns(d))


def _slerp_ratio(q1: tuple[float, ...], q2: tuple[float, ...], t: _F64) -> _F64:
    """tf2 ``Quaternion::slerp(q1, q2, t)`` for many t (``angleShortestPath`` with
    ``tf2Acos``'s clamp; q1 returned unchanged for a zero angle). Returns ``(N, 4)``."""
    x1, y1, z1, w1 = q1
    x2, y2, z2, w2 = q2
    dot = x1 * x2 + y1 * y2 + z1 * z2 + w1 * w2
    s = math.sqrt((x1 * x1 + y1 * y1 + z1 * z1 + w1 * w1) * (x2 * x2 + y2 * y2 + z2 * z2 + w2 * w2))
    c = (-dot) / s if dot < 0 else dot / s
    c = -1.0 if c < -1.0 else (1.0 if c > 1.0 else c)
    theta = (2.0 * math.acos(c)) / 2.0 if not math.isnan(c) else math.nan
    out = np.empty((t.shape[0], 4))
    if theta == 0.0:
        out[:] = q1
        return out
    d = 1.0 / math.sin(theta) if not math.isnan(theta) else math.nan
    s0 = np.sin((1.0 - t) * theta)
    s1 = np.sin(t * theta)
    sign = -1.0 if dot < 0 else 1.0
    out[:, 0] = (x1 * s0 + (sign * x2) * s1) * d
    out[:, 1] = (y1 * s0 + (sign * y2) * s1) * d
    out[:, 2] = (z1 * s0 + (sign * z2) * s1) * d
    out[:, 3] = (w1 * s0 + (sign * w2) * s1) * d
    return out


def _apply_tf2(q: _F64, v: _F64, p: _F64) -> _F64:
    """tf2::Transform with ``setRotation(q)`` (its basis, in tf2's order) applied to
    points: ``p.dot3(row0, row1, row2) + origin``. q ``(N, 4)``, v and p ``(N, 3)``."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    d = x * x + y * y + z * z + w * w
    s = 2.0 / d
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    px, py, pz = p[:, 0], p[:, 1], p[:, 2]
    out = np.empty_like(p)
    out[:, 0] = (px * (1.0 - (yy + zz)) + py * (xy - wz) + pz * (xz + wy)) + v[:, 0]
    out[:, 1] = (px * (xy + wz) + py * (1.0 - (xx + zz)) + pz * (yz - wx)) + v[:, 1]
    out[:, 2] = (px * (xz - wy) + py * (yz + wx) + pz * (1.0 - (xx + yy))) + v[:, 2]
    return out


class LaserProjection:
    """Projects LaserScans to PointCloud2s (laser_geometry ``LaserProjection``).

    One instance keeps laser_geometry's cos/sin table of the last scan layout seen; use
    one per scan source, as in ROS. Not thread-safe.
    """

    def __init__(self) -> None:
        self._key: tuple[int, float, float] | None = None
        self._cos = np.zeros(0)
        self._sin = np.zeros(0)

    # ------------------------------------------------------------------ projection

    def _table(self, scan: LaserScan) -> tuple[_F64, _F64]:
        n = len(scan.ranges)
        key = (n, scan.angle_min, scan.angle_max)
        if key != self._key:
            angles = scan.angle_min + np.arange(n, dtype=np.float64) * scan.angle_increment
            self._cos, self._sin = np.cos(angles), np.sin(angles)
            self._key = key
        return self._cos, self._sin

    def _project(
        self, scan: LaserScan, range_cutoff: float, channel_options: int
    ) -> tuple[list[PointField], np.ndarray[Any, np.dtype[np.void]]]:
        """laser_geometry ``projectLaser_`` (PointCloud2): the fields and the kept
        points as a structured array (native little-endian float32 / int32)."""
        ranges = scan.ranges
        n = len(ranges)
        opts = int(channel_options)
        has_intensity = bool(opts & ChannelOption.INTENSITY) and len(scan.intensities) > 0
        if has_intensity and len(scan.intensities) < n:
            raise ValueError(
                f"LaserScan.intensities has {len(scan.intensities)} values for {n} ranges"
            )
        names = ["x", "y", "z"]
        if has_intensity:
            names.append("intensity")
        if opts & ChannelOption.INDEX:
            names.append("index")
        if opts & ChannelOption.DISTANCE:
            names.append("distances")
        if opts & ChannelOption.TIMESTAMP:
            names.append("stamps")
        if opts & ChannelOption.VIEWPOINT:
            names += ["vp_x", "vp_y", "vp_z"]
        fields = [
            PointField(name, 4 * k, PointField.INT32 if name == "index" else PointField.FLOAT32)
            for k, name in enumerate(names)
        ]
        dtype = np.dtype([(name, "<i4" if name == "index" else "<f4") for name in names])
        cos, sin = self._table(scan)
        r64 = ranges.astype(np.float64)
        cutoff = float(scan.range_max) if range_cutoff < 0 else float(range_cutoff)
        with np.errstate(invalid="ignore"):
            keep = np.flatnonzero((r64 < cutoff) & (ranges >= np.float32(scan.range_min)))
        pts = np.zeros(keep.shape[0], dtype=dtype)
        rk = r64[keep]
        with np.errstate(invalid="ignore", over="ignore"):
            pts["x"] = rk * cos[keep]
            pts["y"] = rk * sin[keep]
        if has_intensity:
            pts["intensity"] = scan.intensities[keep]
        if "index" in names:
            pts["index"] = keep
        if "distances" in names:
            pts["distances"] = ranges[keep]
        if "stamps" in names:
            with np.errstate(over="ignore", invalid="ignore"):
                pts["stamps"] = keep.astype(np.float32) * np.float32(scan.time_increment)
        return fields, pts

    @staticmethod
    def _cloud(header: Header, fields: list[PointField], pts: np.ndarray[Any, Any]) -> PointCloud2:
        step = 4 * len(fields)
        return PointCloud2(
            header=header, height=1, width=len(pts), fields=fields, is_bigendian=False,
            point_step=step, row_step=step * len(pts), data=pts.tobytes(), is_dense=False,
        )  # fmt: skip

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
        fields, pts = self._project(scan, range_cutoff, channel_options)
        return self._cloud(scan.header, fields, pts)

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
        frame = scan.header.frame_id
        start = scan.header.stamp
        requested_index = bool(int(channel_options) & ChannelOption.INDEX)
        fields, pts = self._project(scan, range_cutoff, int(channel_options) | ChannelOption.INDEX)
        n = len(scan.ranges)
        idx = pts["index"].astype(np.float64)
        p = np.stack(
            [pts["x"].astype(np.float64), pts["y"].astype(np.float64),
             pts["z"].astype(np.float64)], axis=1,
        )  # fmt: skip
        if interpolation == "laser_geometry":
            end = _end_time(scan)
            ts0 = buffer.lookup_transform(target_frame, frame, start)
            if fixed_frame is None:
                ts1 = buffer.lookup_transform(target_frame, frame, end)
            else:
                ts1 = buffer.lookup_transform_full(target_frame, start, frame, end, fixed_frame)
            o0 = np.array(ts0.transform.translation)
            o1 = np.array(ts1.transform.translation)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = idx * (np.float64(1.0) / np.float64(float(n) - 1.0))  # n = 1: inf, as C++
                s = 1.0 - ratio
                v = s[:, None] * o0[None, :] + ratio[:, None] * o1[None, :]
                q = _slerp_ratio(
                    tuple(ts0.transform.rotation), tuple(ts1.transform.rotation), ratio
                )
        elif interpolation == "per_beam":
            times = start.ns + beam_time_offsets_ns(scan, pts["index"])
            arr = buffer.lookup_transforms(target_frame, frame, times)
            v, q = arr.translations, arr.rotations
        elif interpolation == "stamp":
            ts0 = buffer.lookup_transform(target_frame, frame, start)
            v = np.broadcast_to(np.array(ts0.transform.translation), p.shape)
            q = np.broadcast_to(np.array(ts0.transform.rotation), (p.shape[0], 4))
        else:
            raise ValueError(
                "interpolation must be 'laser_geometry', 'per_beam' or 'stamp', "
                f"got {interpolation!r}"
            )
        with np.errstate(invalid="ignore", over="ignore"):
            out = _apply_tf2(q, v, p)
            pts["x"], pts["y"], pts["z"] = out[:, 0], out[:, 1], out[:, 2]
            if "vp_x" in (pts.dtype.names or ()):
                vp = _apply_tf2(q, v, np.zeros_like(p))
                pts["vp_x"], pts["vp_y"], pts["vp_z"] = vp[:, 0], vp[:, 1], vp[:, 2]
        if not requested_index:
            keep = [f.name for f in fields if f.name != "index"]
            fields = [
                PointField(name, 4 * k, f.datatype)
                for k, (name, f) in enumerate((f.name, f) for f in fields if f.name != "index")
            ]
            pts = np.ascontiguousarray(pts[keep]).astype(
                np.dtype([(name, pts.dtype[name]) for name in keep])
            )
        return self._cloud(Header(start, target_frame), fields, pts)

    async def transform_laser_scan_to_point_cloud_async(
        self,
        target_frame: str,
        scan: LaserScan,
        buffer: Any,
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
