"""LaserScans for ``tfbus view --scan TOPIC``: read from a bag, projected into the fixed
frame with tfbus's own :class:`~tfbus.laser.LaserProjection` (laser_geometry's
``transformLaserScanToPointCloud``), as a point cloud the page draws."""

from __future__ import annotations

import bisect
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore
from tfbus.laser import LaserProjection
from tfbus.messages import Header
from tfbus.sensor_msgs import LaserScan, read_points
from tfbus.time import Time

__all__ = [
    "MAX_SCANS_BACK", "ScanTrack", "bag_topic_messages", "project_scan", "scan_from_ros",
]

MAX_SCANS_BACK = 10
"""How many scans :meth:`ScanTrack.project_at` goes back for one it can place."""


def scan_from_ros(msg: Any) -> LaserScan:
    """A deserialised ``sensor_msgs/LaserScan`` (rosbags, ROS 1 or ROS 2) as a
    :class:`~tfbus.sensor_msgs.LaserScan`."""
    h = msg.header
    stamp = h.stamp
    sec = getattr(stamp, "sec", None)
    nsec = getattr(stamp, "nanosec", None)
    return LaserScan(
        header=Header(Time(int(sec or 0), int(nsec or 0)), str(h.frame_id)),
        angle_min=float(msg.angle_min), angle_max=float(msg.angle_max),
        angle_increment=float(msg.angle_increment), time_increment=float(msg.time_increment),
        scan_time=float(msg.scan_time), range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        ranges=np.asarray(msg.ranges, dtype=np.float32),
        intensities=np.asarray(msg.intensities, dtype=np.float32),
    )


def project_scan(projector: LaserProjection, scan: LaserScan, fixed_frame: str,
                 core: BufferCore) -> npt.NDArray[np.float32]:
    """The scan's points in ``fixed_frame``, ``(N, 3) float32`` metres:
    ``projector.transform_laser_scan_to_point_cloud(fixed_frame, scan, core)``'s x, y, z.

    Raises:
        TransformException: tf2's error when the scan cannot be placed.
    """
    cloud = projector.transform_laser_scan_to_point_cloud(fixed_frame, scan, core)
    pts = read_points(cloud, ["x", "y", "z"])
    return np.stack([pts["x"], pts["y"], pts["z"]], axis=1).astype(np.float32)


@dataclass
class ScanTrack:
    """Every scan of one topic of a bag, by bag time; :meth:`at` is the latest scan at or
    before a bag time."""

    topic: str
    times: list[int] = field(default_factory=list)
    scans: list[LaserScan] = field(default_factory=list)

    @classmethod
    def read(cls, path: Path, topic: str) -> ScanTrack:
        """Read ``topic``'s LaserScans (rosbags' AnyReader: ROS 1 and ROS 2 bags).

        Raises:
            ValueError: the bag has no ``sensor_msgs/LaserScan`` topic of that name
                (the message names the topic and lists the scan topics it has).
        """
        track = cls(topic)
        for t, decode in bag_topic_messages(path, topic, "LaserScan", "--scan", "scan"):
            track.times.append(t)
            track.scans.append(scan_from_ros(decode()))
        return track

    def at(self, t: Time) -> LaserScan | None:
        """The last scan recorded at or before bag time ``t`` (None before the first)."""
        i = bisect.bisect_right(self.times, t.ns)
        return self.scans[i - 1] if i else None

    def project_at(self, t: Time, fixed_frame: str, core: BufferCore,
                   projector: LaserProjection) -> tuple[
                       npt.NDArray[np.float32] | None, LaserScan | None, str | None]:
        """The points of the newest scan at or before ``t`` that ``core`` can place in
        ``fixed_frame`` (going back at most :data:`MAX_SCANS_BACK` scans, as rviz's
        message filter shows a scan once its transforms arrived): ``(points, scan, None)``,
        or ``(None, None, why)`` with tf2's message for the newest scan."""
        i = bisect.bisect_right(self.times, t.ns)
        if not i:
            return None, None, f"{self.topic}: no scan yet"
        first_error: str | None = None
        for k in range(i - 1, max(-1, i - 1 - MAX_SCANS_BACK), -1):
            scan = self.scans[k]
            try:
                return project_scan(projector, scan, fixed_frame, core), scan, None
            except Exception as err:  # tf2's TransformException (or a malformed scan)
                if first_error is None:
                    first_error = f"{self.topic}: {err}"
        return None, None, first_error


def bag_topic_messages(path: Path, topic: str, msgtype: str, option: str, kind: str
                       ) -> Iterator[tuple[int, Any]]:
    """``(record time ns, decode)`` for each ``topic`` message of a ``*/msgtype`` type in
    the bag at ``path`` (rosbags' AnyReader: ROS 1 ``.bag``, ROS 2 bag folders, ``.db3``
    and ``.mcap`` files), in record order; ``decode()`` deserialises it (and raises what
    rosbags raises for a damaged message, left to the caller).

    Raises:
        ValueError: the bag has no such topic of that type: names ``option``, the topic
            and the ``kind`` topics the bag has.
    """
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections
                 if c.topic == topic and c.msgtype.endswith(msgtype)]
        if not conns:
            have = sorted({c.topic for c in reader.connections if c.msgtype.endswith(msgtype)})
            raise ValueError(f"{option} {topic!r}: no {msgtype} topic of that name in "
                             f"{path} ({kind} topics: {', '.join(have) or 'none'})")
        for conn, t, raw in reader.messages(connections=conns):
            yield int(t), lambda raw=raw, msgtype=conn.msgtype: reader.deserialize(raw, msgtype)
