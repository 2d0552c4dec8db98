"""ROS 2's ``tf2_msgs/msg/TFMessage`` and ``rosgraph_msgs/msg/Clock`` as DDS sees them:
topic and type names, the ``IdlStruct`` types Cyclone announces, and the Cyclone DDS
configuration.

Synchronous and free of I/O, so it is unit-testable alone; the transport that uses it is
:class:`tfbus.transports.ros2.Ros2Transport`.

**Names.** ROS 2 maps topic ``/tf`` to the DDS topic ``rt/tf`` and message
``tf2_msgs/msg/TFMessage`` to the DDS type ``tf2_msgs::msg::dds_::TFMessage_``
(``rmw_dds_common``/``rosidl_generator_dds_idl`` naming: package ``::msg::dds_::``
type plus a trailing underscore). The nested types are
``geometry_msgs::msg::dds_::TransformStamped_``, ``std_msgs::msg::dds_::Header_``,
``builtin_interfaces::msg::dds_::Time_`` (``int32 sec``, ``uint32 nanosec``),
``geometry_msgs::msg::dds_::Transform_``, ``Vector3_`` (x, y, z metres) and
``Quaternion_`` (x, y, z, w). ``/clock`` is the DDS topic ``rt/clock`` of type
``rosgraph_msgs::msg::dds_::Clock_`` (one ``Time_ clock``). The ``LookupTransform``
action's request, reply and topic types (:mod:`tfbus.transports.ros2.action`) follow. They
are declared below as
cyclonedds ``IdlStruct``s so that Cyclone announces the right type name and type
information during discovery.

The samples themselves are (de)serialised by :mod:`tfbus.codecs.cdr` (XCDR1, as rmw
sends them), about 9x faster than cyclonedds-python's own serializer.
"""

# No ``from __future__ import annotations``: cyclonedds reads the IdlStruct annotations
# at runtime and cannot resolve them from strings.
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import (
    array,
    float64,
    int8,
    int32,
    int64,
    sequence,
    uint8,
    uint32,
    uint64,
)

from tfbus.transports._base import DOMAIN_ID_MAX

__all__ = [
    "CLOCK_TOPIC_DDS",
    "DOMAIN_ID_MAX",
    "TF_STATIC_TOPIC_DDS",
    "TF_TOPIC_DDS",
    "CancelGoalRequest_",
    "CancelGoalResponse_",
    "Clock_",
    "FeedbackMessage_",
    "GetResultRequest_",
    "GetResultResponse_",
    "GoalStatusArray_",
    "SendGoalRequest_",
    "SendGoalResponse_",
    "TFMessage_",
    "TransformStamped_",
    "cyclone_config",
    "dds_topic_name",
]

TF_TOPIC_DDS: Final = "rt/tf"
"""The DDS topic ROS 2 uses for ``/tf`` (``rt/`` is rmw's prefix for ROS topics)."""
TF_STATIC_TOPIC_DDS: Final = "rt/tf_static"
"""The DDS topic ROS 2 uses for ``/tf_static``."""
CLOCK_TOPIC_DDS: Final = "rt/clock"
"""The DDS topic ROS 2 uses for ``/clock`` (simulated time)."""


# -- the ROS 2 types, as Cyclone announces them --------------------------------------------


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    """``builtin_interfaces/msg/Time``: seconds (int32) and nanoseconds (uint32)."""

    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    """``std_msgs/msg/Header``: stamp and frame_id."""

    stamp: Time_ = field(default_factory=Time_)
    frame_id: str = ""


@dataclass
class Vector3_(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    """``geometry_msgs/msg/Vector3``, metres."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion_(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    """``geometry_msgs/msg/Quaternion`` in (x, y, z, w) order."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Transform_(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    """``geometry_msgs/msg/Transform``: translation then rotation."""

    translation: Vector3_ = field(default_factory=Vector3_)
    rotation: Quaternion_ = field(default_factory=Quaternion_)


@dataclass
class TransformStamped_(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    """``geometry_msgs/msg/TransformStamped``: header, child_frame_id, transform."""

    header: Header_ = field(default_factory=Header_)
    child_frame_id: str = ""
    transform: Transform_ = field(default_factory=Transform_)


@dataclass
class TFMessage_(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    """``tf2_msgs/msg/TFMessage``: the sequence of transforms on ``/tf`` and ``/tf_static``."""

    # cyclonedds' ``sequence[T]`` is typed through its mypy plugin, which tfbus does not load
    transforms: sequence[TransformStamped_] = field(default_factory=list)  # type: ignore[type-arg,assignment]


@dataclass
class Clock_(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    """``rosgraph_msgs/msg/Clock``: the simulated time on ``/clock``."""

    clock: Time_ = field(default_factory=Time_)


# -- tf2_msgs/action/LookupTransform (tfbus.transports.ros2.action): names as
# rosidl_generator_dds_idl makes them; the service request and reply types begin with
# rmw_cyclonedds_cpp's request header (uint64 guid, int64 seq), as their samples do -------


@dataclass
class UUID_(IdlStruct, typename="unique_identifier_msgs::msg::dds_::UUID_"):
    """``unique_identifier_msgs/msg/UUID``: 16 octets."""

    uuid: array[uint8, 16] = field(default_factory=lambda: [0] * 16)  # type: ignore[valid-type,type-arg,assignment]


@dataclass
class Duration_(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    """``builtin_interfaces/msg/Duration``: seconds (int32) and nanoseconds (uint32)."""

    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class GoalInfo_(IdlStruct, typename="action_msgs::msg::dds_::GoalInfo_"):
    """``action_msgs/msg/GoalInfo``."""

    goal_id: UUID_ = field(default_factory=UUID_)
    stamp: Time_ = field(default_factory=Time_)


@dataclass
class GoalStatus_(IdlStruct, typename="action_msgs::msg::dds_::GoalStatus_"):
    """``action_msgs/msg/GoalStatus``."""

    goal_info: GoalInfo_ = field(default_factory=GoalInfo_)
    status: int8 = 0


@dataclass
class GoalStatusArray_(IdlStruct, typename="action_msgs::msg::dds_::GoalStatusArray_"):
    """``action_msgs/msg/GoalStatusArray`` (the action's ``status`` topic)."""

    status_list: sequence[GoalStatus_] = field(default_factory=list)  # type: ignore[type-arg,assignment]


@dataclass
class LookupTransform_Goal_(IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_Goal_"):
    """``tf2_msgs/action/LookupTransform`` goal."""

    target_frame: str = ""
    source_frame: str = ""
    source_time: Time_ = field(default_factory=Time_)
    timeout: Duration_ = field(default_factory=Duration_)
    target_time: Time_ = field(default_factory=Time_)
    fixed_frame: str = ""
    advanced: bool = False


@dataclass
class SendGoalRequest_(
    IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_SendGoal_Request_"
):
    """The ``send_goal`` request, after rmw_cyclonedds_cpp's request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    goal_id: UUID_ = field(default_factory=UUID_)
    goal: LookupTransform_Goal_ = field(default_factory=LookupTransform_Goal_)


@dataclass
class SendGoalResponse_(
    IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_SendGoal_Response_"
):
    """The ``send_goal`` reply, after the request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    accepted: bool = False
    stamp: Time_ = field(default_factory=Time_)


@dataclass
class GetResultRequest_(
    IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_GetResult_Request_"
):
    """The ``get_result`` request, after the request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    goal_id: UUID_ = field(default_factory=UUID_)


@dataclass
class TF2Error_(IdlStruct, typename="tf2_msgs::msg::dds_::TF2Error_"):
    """``tf2_msgs/msg/TF2Error``."""

    error: uint8 = 0
    error_string: str = ""


@dataclass
class GetResultResponse_(
    IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_GetResult_Response_"
):
    """The ``get_result`` reply, after the request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    status: int8 = 0
    transform: TransformStamped_ = field(default_factory=TransformStamped_)
    error: TF2Error_ = field(default_factory=TF2Error_)


@dataclass
class CancelGoalRequest_(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    """The ``cancel_goal`` request, after the request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    goal_info: GoalInfo_ = field(default_factory=GoalInfo_)


@dataclass
class CancelGoalResponse_(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    """The ``cancel_goal`` reply, after the request header."""

    request_guid: uint64 = 0
    request_seq: int64 = 0
    return_code: int8 = 0
    goals_canceling: sequence[GoalInfo_] = field(default_factory=list)  # type: ignore[type-arg,assignment]


@dataclass
class FeedbackMessage_(
    IdlStruct, typename="tf2_msgs::action::dds_::LookupTransform_FeedbackMessage_"
):
    """The ``feedback`` topic's type (the empty feedback has rosidl's placeholder
    member)."""

    goal_id: UUID_ = field(default_factory=UUID_)
    structure_needs_at_least_one_member: uint8 = 0



def dds_topic_name(topic: str) -> str:
    """The DDS topic of a ROS 2 topic: rmw's ``rt`` prefix before the fully qualified
    name (``/clock`` -> ``rt/clock``; ``rmw_dds_common``'s ``ros_topic_prefix``).

    Raises:
        ValueError: if ``topic`` is not a global ROS graph name (``/a/b_c``: starts with
            ``/``, alphanumerics and ``_``, no empty token, no trailing ``/``).
    """
    tokens = topic[1:].split("/") if topic.startswith("/") else []
    if not tokens or not all(
        t and t.replace("_", "a").isascii() and t.replace("_", "a").isalnum() and not t[0].isdigit()
        for t in tokens
    ):
        raise ValueError(f"topic {topic!r} is not a global ROS graph name such as '/clock'")
    return "rt" + topic


# -- Cyclone DDS configuration -------------------------------------------------------------

_FAST_DDS_VENDOR: Final = "1.15"  # eProsima's RTPS vendor id


def _xml_attr(value: str) -> str:
    return (
        value.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")
    )


def cyclone_config(
    *,
    interfaces: Sequence[str] | None = None,
    peers: Sequence[str] | None = None,
    multicast: bool | None = None,
    max_participant_index: int = 32,
) -> str:
    """A Cyclone DDS XML configuration (the ``<CycloneDDS>`` document) for tfbus.

    Default (no arguments): **loopback only** -- the ``127.0.0.1`` interface, multicast
    off, discovery by unicast to peer ``127.0.0.1`` (participant indices 0 to
    ``max_participant_index``), like ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` plus a
    loopback Fast DDS profile on the ROS 2 side. Nothing is sent to any other address.

    With ``interfaces`` (names such as ``"eth0"`` or addresses): those interfaces, with
    SPDP multicast discovery (unless ``multicast=False``) and optional unicast ``peers``:
    what a robot network needs.

    Always: ``<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation>``, so that
    endpoints of Fast DDS 3.x (vendor 1.15, rmw_fastrtps_cpp in ROS 2 Kilted) are matched by
    type name as rmw_cyclonedds_cpp does; without it Cyclone >= 11 discovers them but never
    matches (it cannot resolve their TypeObjects).

    Raises:
        ValueError: if an interface or peer is empty, or ``max_participant_index`` is not
            in 0..120.
    """
    if not 0 <= max_participant_index <= 120:
        raise ValueError(f"max_participant_index must be in 0..120, got {max_participant_index}")
    for what, values in (("interfaces", interfaces), ("peers", peers)):
        if values is not None and (isinstance(values, str) or not all(values)):
            raise ValueError(f"{what} must be a list of non-empty strings, got {values!r}")
    if interfaces is None:
        nics = ['<NetworkInterface address="127.0.0.1" multicast="false"/>']
        peer_list = list(peers) if peers is not None else ["127.0.0.1"]
        allow_multicast = bool(multicast)
    else:
        allow_multicast = multicast is None or multicast
        nics = [
            f"<NetworkInterface {'address' if any(c in n for c in '.:') else 'name'}="
            f'"{_xml_attr(n)}"/>'
            for n in interfaces
        ]
        peer_list = list(peers or ())
    peers_xml = "".join(f'\n        <Peer address="{_xml_attr(p)}"/>' for p in peer_list)
    if peers_xml:
        peers_xml = f"\n      <Peers>{peers_xml}\n      </Peers>"
    nics_xml = "".join(f"\n        {n}" for n in nics)
    return f"""<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces>{nics_xml}
      </Interfaces>
      <AllowMulticast>{"default" if allow_multicast else "false"}</AllowMulticast>
    </General>
    <Discovery>
      <ParticipantIndex>auto</ParticipantIndex>
      <MaxAutoParticipantIndex>{max_participant_index}</MaxAutoParticipantIndex>{peers_xml}
    </Discovery>
    <Compatibility>
      <!-- match Fast DDS 3.x (vendor 1.15) endpoints by type name, as rmw does -->
      <IgnoreTypeInformation>{_FAST_DDS_VENDOR}</IgnoreTypeInformation>
    </Compatibility>
  </Domain>
</CycloneDDS>
"""
