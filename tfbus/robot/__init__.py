"""Robots: URDF descriptions, ROS's robot_state_publisher and an animated joint-state source.

* :mod:`tfbus.robot.urdf` — :func:`load_urdf` reads a URDF into a validated
  :class:`RobotModel` (the ``robot`` extra: urdfdom-py);
* :mod:`tfbus.robot.state_publisher` — :class:`RobotStatePublisher`: a model and
  JointStates become ``/tf`` and ``/tf_static`` (ROS 1 robot_state_publisher 1.15);
* :mod:`tfbus.robot.joint_states` — :func:`publish_joint_states`: joint_state_publisher
  without a GUI, animated.

The ``tfbus robot-state-publisher`` and ``tfbus joint-states`` commands (:mod:`tfbus.cli`)
run these on a bus.
"""

from tfbus._extras import require

require(__name__, "urdf_parser_py", "lxml")

from tfbus.errors import JointStateError, URDFError
from tfbus.robot.joint_states import publish_joint_states, sinusoidal_joint_state
from tfbus.robot.state_publisher import RobotStatePublisher, RobotStateStatistics
from tfbus.robot.urdf import JOINT_TYPES, JointInfo, Mimic, RobotModel, load_urdf
from tfbus.topics import JOINT_STATES_TOPIC

__all__ = [
    "JOINT_STATES_TOPIC",
    "JOINT_TYPES",
    "JointInfo",
    "JointStateError",
    "Mimic",
    "RobotModel",
    "RobotStatePublisher",
    "RobotStateStatistics",
    "URDFError",
    "load_urdf",
    "publish_joint_states",
    "sinusoidal_joint_state",
]
