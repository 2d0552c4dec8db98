"""``tf2_sensor_msgs.do_transform_cloud`` on tfbus: :func:`tfbus.convert.do_transform_cloud`
(x, y, z found by name, float32/float64, every other field carried; numpy)."""

from __future__ import annotations

from typing import Any

from tfbus.compat._args import to_transform_stamped
from tfbus.convert import do_transform_cloud as _cloud
from tfbus.sensor_msgs import PointCloud2

__all__ = ["do_transform_cloud"]


def do_transform_cloud(cloud: PointCloud2, transform: Any) -> PointCloud2:
    """``do_transform_cloud(cloud, transform)``: :func:`tfbus.convert.do_transform_cloud`
    (``transform`` any TransformStamped flavour, read by its fields)."""
    return _cloud(cloud, to_transform_stamped(transform))
