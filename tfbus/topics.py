"""The topic names tfbus speaks, in one place (ROS's names, with the leading slash).

Every module that publishes, subscribes, latches, records or maps a tf topic imports its
name from here; a transport that renames topics for its middleware (ROS 2's ``rt/tf``
DDS topic, Zenoh's key expressions) maps these names.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "CLOCK_TOPIC",
    "DEFAULT_CLOCK_HZ",
    "JOINT_STATES_TOPIC",
    "MAX_CLOCK_HZ",
    "PEERS_TOPIC",
    "SCAN_TOPIC",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "TF_TOPICS",
]

TF_TOPIC: Final = "/tf"
"""Dynamic transforms (``tf2_msgs/TFMessage``): tf2_ros ``TransformBroadcaster``'s topic."""

TF_STATIC_TOPIC: Final = "/tf_static"
"""Static transforms, latched (``tf2_msgs/TFMessage``): ``StaticTransformBroadcaster``'s
topic; a late subscriber receives every static transform sent so far."""

TF_TOPICS: Final = (TF_TOPIC, TF_STATIC_TOPIC)
"""Both tf topics, dynamic first: what a transport or a recording carries by default."""

JOINT_STATES_TOPIC: Final = "/joint_states"
"""``sensor_msgs/JointState``: what robot_state_publisher reads and joint_state_publisher
sends."""

SCAN_TOPIC: Final = "/scan"
"""``sensor_msgs/LaserScan``: the laser demo's scans (the conventional ROS name)."""

PEERS_TOPIC: Final = "/tfbus/peers"
"""Local bus topic on which a peer-aware transport delivers
:class:`~tfbus.transports._base.PeerEvent` messages (nodes appearing and leaving); never
sent to other processes."""

CLOCK_TOPIC: Final = "/clock"
"""``rosgraph_msgs/Clock``: simulated time, published by a simulator or ``rosbag play
--clock`` and followed by nodes with ``use_sim_time`` (:class:`tfbus.clock.SimClock`)."""

DEFAULT_CLOCK_HZ: Final = 100.0
"""``/clock`` messages per second a replay publishes by default (:func:`tfbus.bag.replay`'s
``publish_clock``, ``tfbus replay --clock``): ROS 1 ``rosbag play --clock``'s
``--hz`` default (``rosbag/src/rosbag/rosbag_main.py``: ``default=100``); ``ros2 bag play
--clock`` defaults to 40 Hz instead (``ros2bag/verb/play.py``)."""

MAX_CLOCK_HZ: Final = 10_000.0
"""The highest ``publish_clock`` rate accepted, Hz."""
