"""ROS 1 geometry2's ``tf2_sensor_msgs/test/test_tf2_sensor_msgs.py`` (both classes:
xyz, and xyz plus an int32 ``index`` channel), written again against
``tfbus.compat.tf2_sensor_msgs`` (our code: the same clouds, transform and assertions).
``sensor_msgs.point_cloud2`` is ``tfbus.sensor_msgs`` (``read_points`` gives a numpy
structured array: its rows are compared as tuples, as upstream compares its list).

Not rewritten: ROS 1 ``test_tf2/test/test_convert.py`` (converts through PyKDL with
``tf2_kdl``, which tfbus does not provide) and ``test_buffer_client.py`` (a remote
buffer over actionlib, a separate feature).
"""

from __future__ import annotations

import struct

from tfbus.compat import tf2_ros
from tfbus.compat.tf2_sensor_msgs import do_transform_cloud
from tfbus.sensor_msgs import PointCloud2, PointField, read_points


def _rows(cloud: PointCloud2) -> list[tuple[float, ...]]:
    return [tuple(p) for p in read_points(cloud).tolist()]


def _translate_300() -> tf2_ros.TransformStamped:
    from tfbus import Quaternion, Transform, Vector3

    return tf2_ros.TransformStamped(
        transform=Transform(Vector3(300, 300, 300), Quaternion(0, 0, 0, 1))
    )


def _cloud(fields: list[PointField], step: int, data: bytes) -> PointCloud2:
    return PointCloud2(height=1, width=2, fields=fields, point_step=step, row_step=step * 2,
                       data=data)


def test_simple_transform() -> None:
    cloud = _cloud([PointField("x", 0, PointField.FLOAT32, 1),
                    PointField("y", 4, PointField.FLOAT32, 1),
                    PointField("z", 8, PointField.FLOAT32, 1)],
                   12, struct.pack("6f", 1, 2, 0, 10, 20, 30))
    assert _rows(cloud) == [(1.0, 2.0, 0.0), (10.0, 20.0, 30.0)]
    old = cloud.data
    out = do_transform_cloud(cloud, _translate_300())
    k = 300
    assert _rows(out) == [(1 + k, 2 + k, 0 + k), (10 + k, 20 + k, 30 + k)]
    assert cloud.data == old  # the input cloud is not modified


def test_simple_transform_multichannel() -> None:
    cloud = _cloud([PointField("x", 0, PointField.FLOAT32, 1),
                    PointField("y", 4, PointField.FLOAT32, 1),
                    PointField("z", 8, PointField.FLOAT32, 1),
                    PointField("index", 12, PointField.INT32, 1)],
                   16, struct.pack("3fi3fi", 1, 2, 0, 123, 10, 20, 30, 456))
    assert _rows(cloud) == [(1.0, 2.0, 0.0, 123), (10.0, 20.0, 30.0, 456)]
    old = cloud.data
    out = do_transform_cloud(cloud, _translate_300())
    k = 300
    # the index channel (123, 456) is kept
    assert _rows(out) == [(1 + k, 2 + k, 0 + k, 123), (10 + k, 20 + k, 30 + k, 456)]
    assert cloud.data == old
