"""Generated recordings for the ``tfbus view`` cloud and record tests: ``/tf``,
``/tf_static`` and ``/points`` (sensor_msgs/PointCloud2) written by rosbags' own writers
as a ROS 1 ``.bag``, a ROS 2 ``.db3`` folder or a bare ROS 2 ``.mcap`` file, with clouds
given as rosbags messages or as raw serialized bytes (to write damaged ones)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.codecs.ros1 import tf_typestore, to_rosbags

S45 = math.sqrt(0.5)


def tf(stamp: float, parent: str, child: str, xyz: tuple[float, float, float],
       q: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(stamp), parent), child,
                            Transform(Vector3(*xyz), Quaternion(*q)))


@dataclass
class Cloud:
    """A PointCloud2's fields as written (anything the message type allows)."""

    stamp: float
    frame_id: str
    fields: Sequence[tuple[str, int, int, int]]  # name, offset, datatype, count
    height: int
    width: int
    point_step: int
    row_step: int
    data: bytes
    is_bigendian: bool = False


def xyz_cloud(stamp: float, frame_id: str, points: Sequence[Sequence[float]],
              pad: int = 0) -> Cloud:
    """float32 x, y, z, then a float32 intensity (the index) and ``pad`` bytes, per point."""
    step = 16 + pad
    buf = bytearray(step * len(points))
    for k, p in enumerate(points):
        buf[k * step:k * step + 16] = np.array([*p, k], dtype="<f4").tobytes()
    fields = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)]
    return Cloud(stamp, frame_id, fields, 1, len(points), step, step * len(points),
                 bytes(buf))


def _cloud_msg(store: Any, c: Cloud, ros1: bool) -> Any:
    t = store.types
    stamp = Time.from_sec(c.stamp)
    time_ = t["builtin_interfaces/msg/Time"](sec=stamp.sec, nanosec=stamp.nanosec)
    header = t["std_msgs/msg/Header"](seq=0, stamp=time_, frame_id=c.frame_id) if ros1 \
        else t["std_msgs/msg/Header"](stamp=time_, frame_id=c.frame_id)
    fields = [t["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=k)
              for n, o, d, k in c.fields]
    return t["sensor_msgs/msg/PointCloud2"](
        header=header, height=c.height, width=c.width, fields=fields,
        is_bigendian=c.is_bigendian, point_step=c.point_step, row_step=c.row_step,
        data=np.frombuffer(c.data, dtype=np.uint8), is_dense=False)


def serialize_cloud(c: Cloud, ros1: bool) -> bytes:
    """The cloud as rosbags serializes it (ROS 1 or CDR)."""
    store = tf_typestore(ros1=ros1)
    msg = _cloud_msg(store, c, ros1)
    out = store.serialize_ros1(msg, "sensor_msgs/msg/PointCloud2") if ros1 else \
        store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2")
    return bytes(out)


def write_recording(path: Path, fmt: str,
                    items: Sequence[tuple[float, str, Any]]) -> Path:
    """Write ``items`` (record time in seconds, topic, message) and return the file to
    open: ``fmt`` ``ros1`` (``path``.bag), ``db3`` (a folder) or ``mcap`` (the bare
    ``.mcap`` file of a rosbag2 folder). A message is a list of TransformStamped (on
    ``/tf`` or ``/tf_static``), a :class:`Cloud`, or raw bytes (a cloud as written)."""
    ros1 = fmt == "ros1"
    store = tf_typestore(ros1=ros1)
    if ros1:
        from rosbags.rosbag1 import Writer as W1

        out = path.with_suffix(".bag")
        w1 = W1(out)
        w1.open()
        writer: Any = w1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        out = path
        plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(out, version=8, storage_plugin=plugin)
        writer.open()
    conns: dict[str, Any] = {}
    for topic, msgtype in (("/tf_static", "tf2_msgs/msg/TFMessage"),
                           ("/tf", "tf2_msgs/msg/TFMessage"),
                           ("/points", "sensor_msgs/msg/PointCloud2")):
        conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
    for sec, topic, msg in items:
        if isinstance(msg, bytes):
            raw = msg
        elif isinstance(msg, Cloud):
            raw = serialize_cloud(msg, ros1)
        else:
            m = to_rosbags(store, msg, ros1=ros1)
            raw = bytes(store.serialize_ros1(m, "tf2_msgs/msg/TFMessage") if ros1
                        else store.serialize_cdr(m, "tf2_msgs/msg/TFMessage"))
        writer.write(conns[topic], Time.from_sec(sec).ns, raw)
    writer.close()
    if fmt == "mcap":
        (found,) = sorted(out.glob("*.mcap"))
        return found
    return out
