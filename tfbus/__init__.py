"""tfbus: ROS tf2's coordinate-frame machinery for plain async Python.

Layers (each imports only those below it; see docs/architecture.md):

* values — :class:`Time`, message types (x, y, z, w quaternions), :mod:`tfbus.geometry`;
* :class:`BufferCore` — tf2's transform buffer, synchronous and sans-I/O;
* :class:`Bus`, clocks (:mod:`tfbus.clock`) — topics with bounded queues and latching;
* :class:`Buffer`, :class:`TransformListener`, broadcasters — awaitable lookups;
* :mod:`tfbus.bag`, :mod:`tfbus.transports`, the ``tfbus`` command line.
"""

from tfbus._version import __version__ as __version__
from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus, Subscription, Transport
from tfbus.clock import Clock, ManualClock, SimClock, SystemClock, every
from tfbus.core import BufferCore, SetResult
from tfbus.core.batch import TransformArray
from tfbus.errors import (
    BackwardExtrapolationException,
    BufferClosedException,
    ConnectivityException,
    ExtrapolationException,
    ForwardExtrapolationException,
    InvalidArgumentException,
    LookupException,
    NoDataForExtrapolationException,
    TfbusError,
    TimeoutException,
    TransformException,
    TransportError,
)
from tfbus.filters import MessageFilter
from tfbus.laser import LaserProjection
from tfbus.listener import TransformListener
from tfbus.messages import (
    Header,
    Point,
    Point32,
    PointStamped,
    Polygon,
    PolygonStamped,
    Pose,
    PoseStamped,
    PoseWithCovariance,
    PoseWithCovarianceStamped,
    Quaternion,
    Stamped,
    TFMessage,
    Transform,
    TransformStamped,
    Twist,
    TwistStamped,
    Vector3,
    Vector3Stamped,
    VelocityStamped,
    Wrench,
    WrenchStamped,
)
from tfbus.sensor_msgs import LaserScan, PointCloud2, PointField
from tfbus.session import TransformSession as TransformSession
from tfbus.session import open_session as open_session
from tfbus.time import Duration, Time
from tfbus.transports.memory import MemoryTransport

__all__ = [
    "BackwardExtrapolationException",
    "Buffer",
    "BufferClosedException",
    "BufferCore",
    "Bus",
    "Clock",
    "ConnectivityException",
    "Duration",
    "ExtrapolationException",
    "ForwardExtrapolationException",
    "Header",
    "InvalidArgumentException",
    "LaserProjection",
    "LaserScan",
    "LookupException",
    "ManualClock",
    "MemoryTransport",
    "MessageFilter",
    "NoDataForExtrapolationException",
    "Point",
    "Point32",
    "PointCloud2",
    "PointField",
    "PointStamped",
    "Polygon",
    "PolygonStamped",
    "Pose",
    "PoseStamped",
    "PoseWithCovariance",
    "PoseWithCovarianceStamped",
    "Quaternion",
    "SetResult",
    "SimClock",
    "Stamped",
    "StaticTransformBroadcaster",
    "Subscription",
    "SystemClock",
    "TFMessage",
    "TfbusError",
    "Time",
    "TimeoutException",
    "Transform",
    "TransformArray",
    "TransformBroadcaster",
    "TransformException",
    "TransformListener",
    "TransformSession",
    "TransformStamped",
    "Transport",
    "TransportError",
    "Twist",
    "TwistStamped",
    "Vector3",
    "Vector3Stamped",
    "VelocityStamped",
    "Wrench",
    "WrenchStamped",
    "every",
    "open_session",
]
