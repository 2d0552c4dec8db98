"""PointCloud2s for ``tfbus view --cloud TOPIC``: read from a bag or received live, their
``x``, ``y``, ``z`` fields decoded (subsampled to :data:`MAX_CLOUD_POINTS`), and placed in
the fixed frame at the cloud's stamp with tf2_sensor_msgs' ``do_transform_cloud``
(:func:`tfbus.convert.do_transform_cloud`), as rviz's PointCloud2 display does.

A cloud whose fields or sizes do not describe its data (no float ``x``/``y``/``z``, a
``point_step`` shorter than its fields, ``data`` shorter than ``height x row_step``, an
undecodable message) is counted with its reason and dropped; the others are kept.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from tfbus.convert import do_transform_cloud
from tfbus.core import BufferCore
from tfbus.messages import Header
from tfbus.sensor_msgs import PointCloud2, PointField, create_cloud_xyz32, dtype_from_fields
from tfbus.time import Time

__all__ = ["MAX_CLOUDS_BACK", "MAX_CLOUD_POINTS", "MAX_REASONS", "MAX_TRACK_POINTS",
           "CloudFeed", "CloudTrack", "Counted", "cloud_from_ros", "cloud_points",
           "place_points"]

MAX_CLOUD_POINTS = 100_000
"""Points drawn of one cloud at most: a larger cloud is subsampled to every k-th point,
``k = ceil(n / MAX_CLOUD_POINTS)``."""
MAX_TRACK_POINTS = 5_000_000
"""Points (after subsampling) a bag's cloud topic keeps in memory at most (60 MB of
float32): the clouds past that are counted in :attr:`CloudTrack.not_kept`."""
MAX_CLOUDS_BACK = 10
"""How many clouds are tried, newest first, for one that can be placed in the fixed frame."""
MAX_REASONS = 20
"""Distinct reasons a topic's dropped clouds are counted under at most (the rest are
counted under ``"other"``)."""
_MAX_REASON_LENGTH = 200
_XYZ = ("x", "y", "z")
_F32 = npt.NDArray[np.float32]


def cloud_from_ros(msg: Any) -> PointCloud2:
    """A deserialised ``sensor_msgs/PointCloud2`` (rosbags, ROS 1 or ROS 2) as a
    :class:`~tfbus.sensor_msgs.PointCloud2`."""
    h = msg.header
    stamp = h.stamp
    sec = getattr(stamp, "sec", None)
    nsec = getattr(stamp, "nanosec", getattr(stamp, "nsec", None))
    return PointCloud2(
        header=Header(Time(int(sec or 0), int(nsec or 0)), str(h.frame_id)),
        height=int(msg.height), width=int(msg.width),
        fields=[PointField(str(f.name), int(f.offset), int(f.datatype), int(f.count))
                for f in msg.fields],
        is_bigendian=bool(msg.is_bigendian), point_step=int(msg.point_step),
        row_step=int(msg.row_step), data=np.asarray(msg.data, dtype=np.uint8).tobytes(),
        is_dense=bool(msg.is_dense),
    )


def cloud_points(cloud: PointCloud2, cap: int = MAX_CLOUD_POINTS) -> _F32:
    """The cloud's finite points, ``(N, 3) float32`` metres in its own frame
    (``header.frame_id``), every k-th point of its ``height x width`` (row-major) with
    ``k = ceil(n / cap)``, so that ``N <= cap``; points with a NaN or infinite coordinate
    are left out (as rviz draws none).

    The layout is read as sensor_msgs_py's ``read_points`` reads it
    (:func:`~tfbus.sensor_msgs.dtype_from_fields`), without copying the points left out.

    Raises:
        ValueError: a field ``x``, ``y`` or ``z`` is missing or not one float32/float64,
            the fields do not fit ``point_step``, ``row_step < width x point_step``, or
            ``data`` is shorter than the layout needs (each names the field and value).
    """
    if not isinstance(cloud, PointCloud2):
        raise ValueError(f"not a PointCloud2: {type(cloud).__name__}")
    for name, value in (("height", cloud.height), ("width", cloud.width),
                        ("point_step", cloud.point_step), ("row_step", cloud.row_step)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"PointCloud2.{name} must be a count, got {value!r}")
    by_name = {f.name: f for f in cloud.fields}
    for name in _XYZ:
        f = by_name.get(name)
        if f is None:
            raise ValueError(f"PointCloud2 has no field {name!r} "
                             f"(fields: {sorted(map(str, by_name))[:10]})")
        if f.datatype not in (PointField.FLOAT32, PointField.FLOAT64) or f.count != 1:
            raise ValueError(f"PointCloud2 field {name!r} must be one float32 or float64, "
                             f"got datatype {f.datatype!r}, count {f.count!r}")
    xyz = [by_name[n] for n in _XYZ]
    dtype = dtype_from_fields(xyz, int(cloud.point_step), bool(cloud.is_bigendian))
    height, width = int(cloud.height), int(cloud.width)
    step, row = int(cloud.point_step), int(cloud.row_step)
    n = height * width
    if n == 0:
        return np.zeros((0, 3), dtype=np.float32)
    data = memoryview(cloud.data).cast("B")
    need = (height - 1) * row + width * step
    if row < width * step or len(data) < need:
        raise ValueError(f"PointCloud2 data has {len(data)} bytes; height {height}, width "
                         f"{width}, row_step {row}, point_step {step} need {need}")
    rows = np.ndarray((height, width), dtype=dtype, buffer=data, strides=(row, step))
    k = -(-n // max(1, cap))
    if height == 1 or row == width * step:  # one run of points: a strided view
        flat = np.ndarray((n,), dtype=dtype, buffer=data, strides=(step,))[::k]
    else:  # padded rows: only the points kept are copied
        idx = np.arange(0, n, k)
        flat = rows[idx // width, idx % width]
    pts = np.empty((len(flat), 3), dtype=np.float32)
    for c, name in enumerate(_XYZ):
        pts[:, c] = flat[name]
    return pts[np.isfinite(pts).all(axis=1)]


def place_points(points: _F32, frame_id: str, stamp: Time, fixed_frame: str,
                 core: BufferCore) -> _F32:
    """``points`` (``(N, 3)`` metres in ``frame_id``) in ``fixed_frame`` at ``stamp``:
    ``do_transform_cloud(cloud, core.lookup_transform(fixed_frame, frame_id, stamp))``
    (tf2_sensor_msgs), ``(N, 3) float32``.

    Raises:
        TransformException: tf2's error when the cloud cannot be placed at its stamp.
    """
    transform = core.lookup_transform(fixed_frame, frame_id, stamp)
    cloud = do_transform_cloud(create_cloud_xyz32(Header(stamp, frame_id), points), transform)
    out: _F32 = np.frombuffer(cloud.data, dtype="<f4").reshape(-1, 3).astype(np.float32)
    return out


@dataclass
class Counted:
    """Clouds of one topic counted and dropped, by reason (at most :data:`MAX_REASONS`
    reasons, the rest under ``"other"``)."""

    bad: int = 0
    """Clouds dropped: not a PointCloud2, undecodable, or fields/sizes that do not fit."""
    reasons: dict[str, int] = field(default_factory=dict)
    """How many clouds were dropped for each reason (the error's text)."""

    def drop(self, reason: str) -> None:
        """Count one dropped cloud under ``reason``."""
        self.bad += 1
        reason = reason[:_MAX_REASON_LENGTH]
        if reason not in self.reasons and len(self.reasons) >= MAX_REASONS:
            reason = "other"
        self.reasons[reason] = self.reasons.get(reason, 0) + 1

    def summary(self, topic: str) -> str | None:
        """One line: the count and the most frequent reason (None: nothing dropped)."""
        if not self.bad:
            return None
        top = max(self.reasons.items(), key=lambda kv: kv[1])[0]
        return f"{topic}: {self.bad} cloud(s) dropped ({top})"


@dataclass
class CloudTrack:
    """Every PointCloud2 of one topic of a bag, by bag time, as subsampled points in the
    cloud's own frame (:func:`cloud_points`); :meth:`project_at` places the newest one
    that can be placed at a bag time."""

    topic: str
    times: list[int] = field(default_factory=list)
    """Bag (record) time of each cloud kept, nanoseconds."""
    stamps: list[Time] = field(default_factory=list)
    frames: list[str] = field(default_factory=list)
    points: list[_F32] = field(default_factory=list)
    clouds: list[PointCloud2] = field(default_factory=list)
    """Each cloud kept, as the subsampled xyz cloud drawn (what a recording writes)."""
    dropped: Counted = field(default_factory=Counted)
    not_kept: int = 0
    """Valid clouds past :data:`MAX_TRACK_POINTS` points, not kept."""

    @classmethod
    def read(cls, path: Path, topic: str, *, cap: int = MAX_CLOUD_POINTS,
             budget: int = MAX_TRACK_POINTS) -> CloudTrack:
        """Read ``topic``'s PointCloud2s (rosbags' AnyReader: ROS 1 ``.bag``, ROS 2 bag
        folders, ``.db3`` and ``.mcap`` files), each subsampled to ``cap`` points; a
        cloud that cannot be decoded is counted in :attr:`dropped` with its reason.

        Raises:
            ValueError: the bag has no ``sensor_msgs/PointCloud2`` topic of that name
                (the message names the topic and lists the cloud topics it has).
        """
        from tfbus.view.scans import bag_topic_messages

        track = cls(topic)
        total = 0
        for t, decode in bag_topic_messages(path, topic, "PointCloud2", "--cloud", "cloud"):
            try:
                cloud = cloud_from_ros(decode())
                pts = cloud_points(cloud, cap)
            except Exception as err:  # an undecodable message or a bad layout
                track.dropped.drop(f"{type(err).__name__}: {err}")
                continue
            if total + len(pts) > budget:
                track.not_kept += 1
                continue
            total += len(pts)
            track._keep(t, cloud.header, pts)
        return track

    def _keep(self, t: int, header: Header, pts: _F32) -> None:
        self.times.append(t)
        self.stamps.append(header.stamp)
        self.frames.append(header.frame_id)
        self.points.append(pts)
        self.clouds.append(create_cloud_xyz32(header, pts))

    def problem(self) -> str | None:
        """One line on the clouds dropped or not kept (None: every cloud kept)."""
        parts = [s for s in (self.dropped.summary(self.topic),) if s]
        if self.not_kept:
            parts.append(f"{self.topic}: {self.not_kept} cloud(s) past "
                         f"{MAX_TRACK_POINTS} points not kept")
        return "   ".join(parts) or None

    def project_at(self, t: Time, fixed_frame: str, core: BufferCore
                   ) -> tuple[_F32 | None, str | None]:
        """The points of the newest cloud recorded at or before ``t`` that ``core`` can
        place in ``fixed_frame`` at its stamp (going back at most
        :data:`MAX_CLOUDS_BACK` clouds): ``(points, None)``, or ``(None, why)`` with
        tf2's message for the newest cloud."""
        i = bisect.bisect_right(self.times, t.ns)
        if not i:
            return None, f"{self.topic}: no cloud yet"
        first_error: str | None = None
        for k in range(i - 1, max(-1, i - 1 - MAX_CLOUDS_BACK), -1):
            try:
                return place_points(self.points[k], self.frames[k], self.stamps[k],
                                    fixed_frame, core), None
            except Exception as err:  # tf2's TransformException
                if first_error is None:
                    first_error = f"{self.topic}: {err}"
        return None, first_error


@dataclass
class CloudFeed:
    """One ``--cloud`` topic of a live bus: counters, the newest clouds decoded (at most
    :data:`MAX_CLOUDS_BACK`, as subsampled points in their own frame) and what is drawn."""

    topic: str
    received: int = 0
    """Messages received on the topic."""
    dropped: Counted = field(default_factory=Counted)
    drawn: int = 0
    """Clouds placed and drawn (at most one per redraw, only when a newer one arrived or
    the fixed frame changed)."""
    error: str | None = None
    """Why nothing is drawn now (tf2's message, no cloud yet), else None."""
    ready: deque[tuple[int, Header, _F32]] = field(
        default_factory=lambda: deque(maxlen=MAX_CLOUDS_BACK))
    """``(number, header, points)`` of the newest valid clouds, newest last."""
    _shown: tuple[int, str] | None = None

    def take(self, msg: object, cap: int = MAX_CLOUD_POINTS) -> PointCloud2 | None:
        """Decode one received message (:func:`cloud_points`) and keep it; a message
        that is not a valid PointCloud2 is counted in :attr:`dropped` with its reason.
        Returns the subsampled xyz cloud kept (what a recording writes), else None."""
        self.received += 1
        try:
            if not isinstance(msg, PointCloud2):
                raise ValueError(f"not a PointCloud2: {type(msg).__name__}")
            if not isinstance(msg.header, Header) or not isinstance(msg.header.stamp, Time):
                raise ValueError("PointCloud2.header must be a Header with a Time stamp")
            pts = cloud_points(msg, cap)
        except Exception as err:  # hostile layouts, wrong types: counted, dropped
            self.dropped.drop(f"{type(err).__name__}: {err}")
            return None
        header = Header(msg.header.stamp, str(msg.header.frame_id))
        self.ready.append((self.received, header, pts))
        return create_cloud_xyz32(header, pts)

    def project(self, fixed: str | None, core: BufferCore) -> tuple[_F32 | None, bool]:
        """The newest cloud placeable in ``fixed`` at its stamp (``(points, True)``),
        ``(None, True)`` when none of the last :data:`MAX_CLOUDS_BACK` can be
        (:attr:`error` says why), or ``(None, False)`` when the one drawn is still the
        newest placeable (nothing placed again; newer ones are tried at each redraw
        until their transforms arrive)."""
        if fixed is None or not self.ready:
            self.error = f"{self.topic}: no cloud yet"
            return None, True
        first_error: str | None = None
        for number, header, pts in reversed(self.ready):
            if (number, fixed) == self._shown:  # drawn already; newer ones not placeable
                self.error = None
                return None, False
            try:
                out = place_points(pts, header.frame_id, header.stamp, fixed, core)
            except Exception as err:  # tf2's TransformException: tried at the next redraw
                if first_error is None:
                    first_error = f"{self.topic}: {err}"
                continue
            self._shown = (number, fixed)
            self.error = None
            self.drawn += 1
            return out, True
        self._shown = None
        self.error = first_error
        return None, True
