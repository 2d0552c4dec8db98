"""``tf2_sensor_msgs.do_transform_cloud`` on tfbus: :func:`tfbus.convert.do_transform_cloud`
(x, y, z found by name, float32/float64, every other field carried; numpy). The result is
in the type of the cloud given: a rospy or rclpy ``sensor_msgs/PointCloud2`` in, the same
class out (mutable, publishable), as tf2_sensor_msgs returns; a tfbus cloud in, a tfbus
cloud out."""

from __future__ import annotations

from typing import Any

from tfbus.compat._args import to_transform_stamped
from tfbus.compat._types import stamped_out
from tfbus.convert import do_transform_cloud as _cloud

__all__ = ["do_transform_cloud"]


def do_transform_cloud(cloud: Any, transform: Any) -> Any:
    """``do_transform_cloud(cloud, transform)``: :func:`tfbus.convert.do_transform_cloud`
    (``transform`` any TransformStamped flavour, read by its fields); the result in the
    type of ``cloud`` (its header the transform's, the stamp in the cloud's time type).

    Raises:
        InvalidArgumentException: no float32/float64 x, y or z field (named).
        ValueError: ``data`` does not fit the layout.
    """
    return stamped_out(_cloud(cloud, to_transform_stamped(transform)), cloud)
