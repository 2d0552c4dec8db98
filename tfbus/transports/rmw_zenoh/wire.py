"""rmw_zenoh's wire for ``/tf`` and ``/tf_static``, without I/O: key expressions, the
attachment, liveliness tokens and their QoS strings.

Every rule here is taken from ros2/rmw_zenoh's source (``rmw_zenoh_cpp/src/detail/``) and
its design notes (``design.md`` in its docs folder);
``tests/transports/test_rmw_zenoh_wire.py`` holds the golden vectors worked out from it,
each with the file and line it comes from.

* **Data key** (``liveliness_utils.cpp``, ``TopicInfo::TopicInfo``):
  ``<domain_id>/<topic name without its leading and trailing slash>/<DDS type
  name>/<type hash>``, e.g. ``0/tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369...``; a
  namespaced topic keeps its inner slashes (``0/robot1/tf/...``).
* **Attachment** on every put (``attachment_helpers.cpp``,
  ``AttachmentData::serialize_to_zbytes``: zenoh-ext's serializer, little-endian):
  ``int64 sequence_number`` (from 1, ``rmw_publisher_data.cpp``), ``int64
  source_timestamp`` (ns since the epoch), then the 16-byte publisher GID as a sequence
  (its length, 16, as one LEB128 byte, then the bytes): 33 bytes
  (:data:`ATTACHMENT_POSITIONAL`; Kilted, Jazzy >= 0.2.4, Humble >= 0.1.2). The older
  labelled form of Jazzy (:data:`ATTACHMENT_LABELLED`) puts each field after its name as a
  zenoh-ext string: ``"sequence_number"``, ``"source_timestamp"``, ``"source_gid"`` (77
  bytes). A subscription drops a sample without an attachment
  (``rmw_subscription_data.cpp``, ``on_sample``).
* **Liveliness tokens** (``liveliness_utils.cpp``, ``Entity::Entity``):
  ``@ros2_lv/<domain>/<session zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/
  <node name>`` and, for a publisher or subscription, ``/<topic>/<type>/<type hash>/<qos>``;
  every name has its ``/`` replaced by ``%`` (``mangle_name``), so the root namespace and
  enclave are ``%``.
* **QoS string** (``liveliness_utils.cpp``, ``qos_to_keyexpr``): six ``:``-separated
  fields (reliability, durability, ``history,depth``, ``deadline sec,nsec``, ``lifespan
  sec,nsec``, ``liveliness kind,sec,nsec``), each left empty where it equals rmw_zenoh's
  default profile (``qos.cpp``: reliable, volatile, keep-last 42, infinite durations,
  automatic liveliness).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Final

from tfbus.errors import WireDecodeError
from tfbus.transports._base import DOMAIN_ID_MAX, ros_domain_id

__all__ = [
    "ADMIN_SPACE",
    "ATTACHMENT_LABELLED",
    "ATTACHMENT_POSITIONAL",
    "DEFAULT_QOS",
    "DOMAIN_ID_MAX",
    "GID_SIZE",
    "TF_DDS_TYPE",
    "TF_LISTENER_QOS",
    "TF_QOS",
    "TF_STATIC_LISTENER_QOS",
    "TF_STATIC_QOS",
    "TF_TYPE_HASH",
    "Attachment",
    "EndpointToken",
    "QosProfile",
    "check_domain",
    "check_namespace",
    "check_node_name",
    "check_topic",
    "data_key",
    "decode_attachment",
    "demangle_name",
    "encode_attachment",
    "endpoint_token",
    "mangle_name",
    "node_token",
    "parse_token",
    "qos_to_keyexpr",
]

ADMIN_SPACE: Final = "@ros2_lv"
"""The first chunk of every rmw_zenoh liveliness token (``liveliness_utils.cpp``)."""
TF_DDS_TYPE: Final = "tf2_msgs::msg::dds_::TFMessage_"
"""``tf2_msgs/msg/TFMessage``'s type name as rmw puts it on the wire (its DDS name)."""
TF_TYPE_HASH: Final = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""REP-2011 type hash of ``tf2_msgs/msg/TFMessage``: ``type_hashes[0].hash_string`` of
rosidl's ``share/tf2_msgs/msg/TFMessage.json`` (ROS 2 Kilted, built by
``scripts/install/install_ros2_env.sh``), what ``rosidl_stringify_type_hash`` prints."""
GID_SIZE: Final = 16
"""Bytes of a publisher GID (``RMW_GID_STORAGE_SIZE`` since Iron)."""
ATTACHMENT_POSITIONAL: Final = "positional"
"""The 33-byte attachment: sequence number, source timestamp, GID, no labels."""
ATTACHMENT_LABELLED: Final = "labelled"
"""The older 77-byte attachment with a name before each field (Jazzy before 0.2.4)."""

_INT64: Final = struct.Struct("<q")
_LABELS: Final = (b"sequence_number", b"source_timestamp", b"source_gid")
_INT64_MIN: Final = -(2**63)
_INT64_MAX: Final = 2**63 - 1
_TOKEN_FORBIDDEN: Final = frozenset("*$?#")
_DECIMAL: Final = re.compile(r"[0-9]+")  # ASCII digits only (str.isdigit takes "²")


# -- QoS --------------------------------------------------------------------------------

_INFINITE: Final = (9223372036, 854775807)
"""``RMW_DURATION_INFINITE`` as (sec, nsec) (``rmw/time.h``)."""


@dataclass(frozen=True, slots=True)
class QosProfile:
    """The rmw QoS fields a token carries, after rmw_zenoh's ``best_available_qos``
    (``qos.cpp``: system defaults replaced by its defaults).

    Attributes:
        reliability: ``RMW_QOS_POLICY_RELIABILITY_*`` (1 reliable, 2 best effort).
        durability: ``RMW_QOS_POLICY_DURABILITY_*`` (1 transient local, 2 volatile).
        history: ``RMW_QOS_POLICY_HISTORY_*`` (1 keep last, 2 keep all).
        depth: history depth, messages.
        deadline: (sec, nsec).
        lifespan: (sec, nsec).
        liveliness: ``RMW_QOS_POLICY_LIVELINESS_*`` (1 automatic).
        liveliness_lease_duration: (sec, nsec).
    """

    reliability: int = 1
    durability: int = 2
    history: int = 1
    depth: int = 42
    deadline: tuple[int, int] = _INFINITE
    lifespan: tuple[int, int] = _INFINITE
    liveliness: int = 1
    liveliness_lease_duration: tuple[int, int] = _INFINITE


DEFAULT_QOS: Final = QosProfile()
"""rmw_zenoh's default profile (``qos.cpp``, ``QoS::QoS``): reliable, volatile, keep-last
42, infinite deadline, lifespan and lease, automatic liveliness."""
TF_QOS: Final = QosProfile(depth=100)
"""tf2_ros ``DynamicBroadcasterQoS`` (``tf2_ros/qos.hpp``): reliable, volatile, keep-last 100."""
TF_LISTENER_QOS: Final = QosProfile(depth=100)
"""tf2_ros ``DynamicListenerQoS``: reliable, volatile, keep-last 100."""
TF_STATIC_QOS: Final = QosProfile(durability=1, depth=1)
"""tf2_ros ``StaticBroadcasterQoS``: reliable, transient local, keep-last 1."""
TF_STATIC_LISTENER_QOS: Final = QosProfile(durability=1, depth=100)
"""tf2_ros ``StaticListenerQoS``: reliable, transient local, keep-last 100."""


def qos_to_keyexpr(qos: QosProfile) -> str:
    """The QoS string of a liveliness token (rmw_zenoh ``liveliness_utils.cpp``,
    ``qos_to_keyexpr``): each field empty where it equals :data:`DEFAULT_QOS`.

    ``qos_to_keyexpr(TF_STATIC_QOS) == ":1:,1:,:,:,,"``.
    """
    d = DEFAULT_QOS

    def field(value: object, default: object) -> str:
        return "" if value == default else str(value)

    return ":".join((
        field(qos.reliability, d.reliability),
        field(qos.durability, d.durability),
        f"{field(qos.history, d.history)},{field(qos.depth, d.depth)}",
        f"{field(qos.deadline[0], d.deadline[0])},{field(qos.deadline[1], d.deadline[1])}",
        f"{field(qos.lifespan[0], d.lifespan[0])},{field(qos.lifespan[1], d.lifespan[1])}",
        f"{field(qos.liveliness, d.liveliness)},"
        f"{field(qos.liveliness_lease_duration[0], d.liveliness_lease_duration[0])},"
        f"{field(qos.liveliness_lease_duration[1], d.liveliness_lease_duration[1])}",
    ))


# -- names and keys --------------------------------------------------------------------


def mangle_name(name: str) -> str:
    """``name`` with every ``/`` replaced by ``%`` (``liveliness_utils.cpp``,
    ``mangle_name``): a ROS name as one key chunk."""
    return name.replace("/", "%")


def demangle_name(chunk: str) -> str:
    """The inverse of :func:`mangle_name` (``demangle_name``)."""
    return chunk.replace("%", "/")


def data_key(domain_id: int, topic: str, type_name: str = TF_DDS_TYPE,
             type_hash: str = TF_TYPE_HASH) -> str:
    """The key expression a topic's samples are put on (``TopicInfo::TopicInfo``):
    ``<domain_id>/<topic without its end slashes>/<type_name>/<type_hash>``.

    Raises:
        ValueError: ``domain_id`` outside 0..232, or ``topic`` not an absolute ROS name
            (``/tf``, ``/robot1/tf``).
    """
    check_domain(domain_id)
    check_topic(topic)
    return f"{domain_id}/{topic.strip('/')}/{type_name}/{type_hash}"


def check_domain(domain_id: int) -> None:
    """Raises ValueError (naming the value) unless ``domain_id`` is an int in 0..232
    (:func:`~tfbus.transports._base.ros_domain_id`'s rule)."""
    ros_domain_id(domain_id)


def _valid_name_token(token: str) -> bool:
    return bool(token) and (token[0].isalpha() or token[0] == "_") and all(
        c.isascii() and (c.isalnum() or c == "_") for c in token)


def check_topic(topic: str) -> None:
    """Raises ValueError (naming the value) unless ``topic`` is an absolute ROS 2 topic
    name: ``/`` then tokens of letters, digits and ``_`` separated by single ``/``, not
    starting with a digit (``rcl_validate_topic_name``)."""
    parts = topic.split("/") if isinstance(topic, str) else []
    if len(parts) < 2 or parts[0] != "" or not all(_valid_name_token(p) for p in parts[1:]):
        raise ValueError(f"topic must be an absolute ROS 2 name like '/tf', got {topic!r}")


def check_namespace(namespace: str) -> str:
    """``namespace`` as a ROS 2 node namespace (``""`` and ``"/"`` -> ``"/"``, ``"robot1"``
    -> ``"/robot1"``).

    Raises:
        ValueError: not made of ROS name tokens separated by ``/`` (named).
    """
    text = namespace.strip("/")
    if not text:
        return "/"
    if not all(_valid_name_token(p) for p in text.split("/")):
        raise ValueError(f"namespace must be ROS name tokens separated by '/', got {namespace!r}")
    return "/" + text


def check_node_name(name: str) -> None:
    """Raises ValueError (naming the value) unless ``name`` is a ROS 2 node name
    (letters, digits and ``_``, not starting with a digit: ``rmw_validate_node_name``)."""
    if not isinstance(name, str) or not _valid_name_token(name):
        raise ValueError(f"node name must be letters, digits and '_' (not starting with a "
                         f"digit), got {name!r}")


def _entity_chunks(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str,
                   enclave: str, namespace: str, name: str) -> tuple[str, ...]:
    return (ADMIN_SPACE, str(domain_id), zid, str(node_id), str(entity_id), kind,
            mangle_name(enclave), mangle_name(namespace), mangle_name(name))


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, name: str,
               enclave: str = "/") -> str:
    """A node's liveliness token (``Entity::Entity`` for ``EntityType::Node``, whose
    entity id is its node id: ``rmw_node_data.cpp``)::

        @ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<name>
    """
    return "/".join(_entity_chunks(domain_id, zid, node_id, node_id, "NN", enclave,
                                   namespace, name))


def endpoint_token(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str,
                   namespace: str, name: str, topic: str, qos: QosProfile,
                   type_name: str = TF_DDS_TYPE, type_hash: str = TF_TYPE_HASH,
                   enclave: str = "/") -> str:
    """A publisher's (``kind="MP"``) or subscription's (``"MS"``) liveliness token
    (``Entity::Entity`` with a ``TopicInfo``): the node's chunks, then the mangled topic,
    type and type hash, and the QoS string (:func:`qos_to_keyexpr`).

    Raises:
        ValueError: ``kind`` is neither ``"MP"`` nor ``"MS"``.
    """
    if kind not in ("MP", "MS"):
        raise ValueError(f"kind must be 'MP' or 'MS', got {kind!r}")
    return "/".join((
        *_entity_chunks(domain_id, zid, node_id, entity_id, kind, enclave, namespace, name),
        mangle_name(topic), mangle_name(type_name), mangle_name(type_hash),
        qos_to_keyexpr(qos),
    ))


@dataclass(frozen=True, slots=True)
class EndpointToken:
    """A liveliness token taken apart (:func:`parse_token`).

    Attributes:
        domain_id: its domain.
        zid: the Zenoh session id of the process that declared it.
        node_id: the node's id within that session.
        entity_id: the entity's id (the node id for a node).
        kind: ``"NN"`` (node), ``"MP"`` (publisher), ``"MS"`` (subscription), ``"SS"``,
            ``"SC"`` (service server, client).
        namespace: the node's namespace (``"/"`` at the root).
        name: the node's name.
        topic: the topic name (``""`` for a node).
        type_name: the topic's type (``""`` for a node).
        type_hash: the topic's type hash (``""`` for a node).
    """

    domain_id: int
    zid: str
    node_id: str
    entity_id: str
    kind: str
    namespace: str
    name: str
    topic: str = ""
    type_name: str = ""
    type_hash: str = ""

    @property
    def node_key(self) -> str:
        """``<zid>/<node id>``: the node's identity on the graph."""
        return f"{self.zid}/{self.node_id}"


def parse_token(key: str) -> EndpointToken:
    """Take a liveliness token apart, checking it as rmw_zenoh's graph cache does
    (``liveliness_utils.cpp``, ``Entity::make(const std::string & keyexpr)``): the admin
    space, at least nine chunks, none empty, a known entity kind, a numeric domain, and
    for an endpoint all thirteen chunks with a QoS string of six fields.

    Raises:
        WireDecodeError: the token is not one rmw_zenoh would accept (the reason named).
    """
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE:
        raise WireDecodeError(f"not an rmw_zenoh liveliness token: {key[:200]!r}")
    if any(not p or _TOKEN_FORBIDDEN.intersection(p) for p in parts):
        raise WireDecodeError(f"liveliness token with an empty or wild chunk: {key[:200]!r}")
    kind = parts[5]
    if kind not in ("NN", "MP", "MS", "SS", "SC"):
        raise WireDecodeError(f"liveliness token of unknown entity kind {kind[:20]!r}")
    if not _DECIMAL.fullmatch(parts[1]) or len(parts[1]) > 10:
        raise WireDecodeError(f"liveliness token with a bad domain id {parts[1][:20]!r}")
    if not _DECIMAL.fullmatch(parts[3]) or not _DECIMAL.fullmatch(parts[4]):
        raise WireDecodeError("liveliness token with a non-numeric node or entity id")
    base = EndpointToken(int(parts[1]), parts[2], parts[3], parts[4], kind,
                         demangle_name(parts[7]), demangle_name(parts[8]))
    if kind == "NN":
        if len(parts) != 9:
            raise WireDecodeError(f"node liveliness token with {len(parts)} chunks (9 expected)")
        return base
    if len(parts) != 13:
        raise WireDecodeError(f"endpoint liveliness token with {len(parts)} chunks (13 expected)")
    qos = parts[12].split(":")
    if len(qos) != 6:
        raise WireDecodeError(f"liveliness token QoS {parts[12][:60]!r} has {len(qos)} fields")
    return EndpointToken(base.domain_id, base.zid, base.node_id, base.entity_id, kind,
                         base.namespace, base.name, demangle_name(parts[9]),
                         demangle_name(parts[10]), parts[11])


# -- attachment ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Attachment:
    """The attachment of one rmw_zenoh sample (``AttachmentData``).

    Attributes:
        sequence_number: the publisher's count of its messages (from 1).
        source_timestamp: nanoseconds since the epoch when it was published.
        gid: the publisher's 16-byte GID.
    """

    sequence_number: int
    source_timestamp: int
    gid: bytes


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _zbytes(raw: bytes) -> bytes:
    return _leb128(len(raw)) + raw


def encode_attachment(attachment: Attachment, form: str = ATTACHMENT_POSITIONAL) -> bytes:
    """The attachment bytes of ``attachment`` in ``form`` (:data:`ATTACHMENT_POSITIONAL`:
    33 bytes; :data:`ATTACHMENT_LABELLED`: 77 bytes). zenoh-ext's serializer: int64
    little-endian, a byte string as its LEB128 length and the bytes.

    Raises:
        ValueError: a GID that is not 16 bytes, a number outside int64, or an unknown form.
    """
    if len(attachment.gid) != GID_SIZE:
        raise ValueError(f"gid must be {GID_SIZE} bytes, got {len(attachment.gid)}")
    for label, number in (("sequence_number", attachment.sequence_number),
                          ("source_timestamp", attachment.source_timestamp)):
        if not _INT64_MIN <= number <= _INT64_MAX:
            raise ValueError(f"{label} must fit an int64, got {number!r}")
    seq = _INT64.pack(attachment.sequence_number)
    stamp = _INT64.pack(attachment.source_timestamp)
    gid = _zbytes(bytes(attachment.gid))
    if form == ATTACHMENT_POSITIONAL:
        return seq + stamp + gid
    if form == ATTACHMENT_LABELLED:
        return b"".join((_zbytes(_LABELS[0]), seq, _zbytes(_LABELS[1]), stamp,
                         _zbytes(_LABELS[2]), gid))
    raise ValueError(f"attachment form must be {ATTACHMENT_POSITIONAL!r} or "
                     f"{ATTACHMENT_LABELLED!r}, got {form!r}")


def decode_attachment(data: bytes | memoryview) -> Attachment:
    """Read either attachment form (told apart by length and the first label).

    Raises:
        WireDecodeError: neither form, exactly (wrong length, a wrong label, a GID that is
            not 16 bytes).
    """
    raw = bytes(data)
    if len(raw) == 17 + GID_SIZE:
        if raw[16] != GID_SIZE:
            raise WireDecodeError(f"attachment GID length {raw[16]} (16 expected)")
        return Attachment(_INT64.unpack_from(raw, 0)[0], _INT64.unpack_from(raw, 8)[0],
                          raw[17:])
    pos = 0
    values: list[int] = []
    for label in _LABELS[:2]:
        if raw[pos:pos + 1 + len(label)] != _zbytes(label):
            raise WireDecodeError(f"attachment of {len(raw)} bytes is neither rmw_zenoh form")
        pos += 1 + len(label)
        if len(raw) < pos + 8:
            raise WireDecodeError("attachment truncated")
        values.append(_INT64.unpack_from(raw, pos)[0])
        pos += 8
    if raw[pos:pos + 1 + len(_LABELS[2])] != _zbytes(_LABELS[2]):
        raise WireDecodeError("attachment without its source_gid label")
    pos += 1 + len(_LABELS[2])
    if raw[pos:pos + 1] != bytes((GID_SIZE,)) or len(raw) != pos + 1 + GID_SIZE:
        raise WireDecodeError("attachment source_gid is not 16 bytes")
    return Attachment(values[0], values[1], raw[pos + 1:])
