"""tfbus: ROS tf2's coordinate-frame machinery for plain async Python."""

from tfbus.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TimeoutException,
    TransformException,
)
from tfbus.messages import (
    Header,
    Point,
    PointStamped,
    Pose,
    PoseStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)
from tfbus.time import Duration, Time

__all__ = [
    "ConnectivityException",
    "Duration",
    "ExtrapolationException",
    "Header",
    "InvalidArgumentException",
    "LookupException",
    "Point",
    "PointStamped",
    "Pose",
    "PoseStamped",
    "Quaternion",
    "TFMessage",
    "Time",
    "TimeoutException",
    "Transform",
    "TransformException",
    "TransformStamped",
    "Vector3",
    "Vector3Stamped",
]
