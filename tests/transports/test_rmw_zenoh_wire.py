"""Golden vectors of rmw_zenoh's wire (:mod:`tfbus.transports.rmw_zenoh.wire`), each worked
out by hand from ros2/rmw_zenoh's source (no real rmw_zenoh installs here). Sources, in
``rmw_zenoh_cpp/src/detail/`` of github.com/ros2/rmw_zenoh:

* ``liveliness_utils.cpp`` @ 3411fdec: ``strip_slashes`` (lines 61-73), ``TopicInfo::TopicInfo``
  building the data key (87-93), ``ADMIN_SPACE``/``NN``/``MP``/``MS`` and the ``%``, ``:``, ``,``
  delimiters (122-131), ``qos_to_keyexpr`` (239-300), ``Entity::Entity`` assembling a token
  (384-418: admin space, domain, zid, nid, id, kind, mangled enclave, namespace, name, then
  topic, type, hash, QoS), ``Entity::make(const std::string &)`` checking a received token,
  ``mangle_name`` (``/`` -> ``%``);
* ``qos.cpp`` @ 7efeee2b lines 18-33: the default profile (keep-last 42, reliable, volatile,
  infinite durations, automatic liveliness) whose fields the QoS string leaves empty;
* ``attachment_helpers.cpp`` @ 534747dc lines 67-74, ``AttachmentData::serialize_to_zbytes``:
  int64 sequence number, int64 source timestamp, the GID array (zenoh-ext serializer:
  little-endian, a sequence as its LEB128 length then its items) -- 33 bytes; and the Jazzy
  version of the same file (zenoh 1.0 API: ``AttachmentData::serialize_to_zbytes`` lines 50-60,
  ``attachment_data_t::serialize_to_zbytes`` lines 104-115) writing the labels
  ``"sequence_number"``, ``"source_timestamp"``, ``"source_gid"`` before the fields;
* ``rmw_publisher_data.cpp`` @ 3e19ec73: ``sequence_number_(1)`` in ``PublisherData``'s
  constructor (the first sample carries 1).

The tf2_ros QoS profiles are ``tf2_ros/qos.hpp``'s (``DynamicBroadcasterQoS`` depth 100,
``StaticBroadcasterQoS`` transient local depth 1, ``StaticListenerQoS`` transient local depth
100). The type hash is rosidl's, ``type_hashes[0]`` of ``share/tf2_msgs/msg/TFMessage.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("zenoh")

from zenoh.ext import Int64, z_serialize

from tfbus.errors import WireDecodeError
from tfbus.transports.rmw_zenoh.wire import (
    DEFAULT_QOS,
    TF_LISTENER_QOS,
    TF_QOS,
    TF_STATIC_LISTENER_QOS,
    TF_STATIC_QOS,
    TF_TYPE_HASH,
    Attachment,
    EndpointToken,
    QosProfile,
    data_key,
    decode_attachment,
    encode_attachment,
    endpoint_token,
    mangle_name,
    node_token,
    parse_token,
    qos_to_keyexpr,
)

HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
TYPE = "tf2_msgs::msg::dds_::TFMessage_"
ROOT = Path(__file__).resolve().parents[2]


def test_type_hash_is_rosidls() -> None:
    """The hash rosidl generated for tf2_msgs/msg/TFMessage (ROS 2 Kilted), when the ROS 2
    venv of ``scripts/install/install_ros2_env.sh`` is there; the literal otherwise."""
    assert TF_TYPE_HASH == HASH
    described = ROOT / ".venv-ros2" / "share" / "tf2_msgs" / "msg" / "TFMessage.json"
    if described.is_file():
        hashes = json.loads(described.read_text())["type_hashes"]
        assert hashes[0] == {"type_name": "tf2_msgs/msg/TFMessage", "hash_string": HASH}


@pytest.mark.parametrize(("domain", "topic", "key"), [
    # TopicInfo::TopicInfo (liveliness_utils.cpp:87-93) with strip_slashes (61-73)
    (0, "/tf", f"0/tf/{TYPE}/{HASH}"),
    (0, "/tf_static", f"0/tf_static/{TYPE}/{HASH}"),
    (42, "/robot1/tf", f"42/robot1/tf/{TYPE}/{HASH}"),
    (232, "/fleet/r2/tf_static", f"232/fleet/r2/tf_static/{TYPE}/{HASH}"),
])
def test_data_keys(domain: int, topic: str, key: str) -> None:
    assert data_key(domain, topic) == key


@pytest.mark.parametrize(("domain", "topic"), [
    (-1, "/tf"), (233, "/tf"), (True, "/tf"), (0, "tf"), (0, "/tf/"), (0, "//tf"),
    (0, "/1tf"), (0, "/t f"), (0, "/tf*"),
])
def test_bad_topic_or_domain_is_named(domain: int, topic: str) -> None:
    with pytest.raises(ValueError, match=r"domain_id|topic"):
        data_key(domain, topic)


@pytest.mark.parametrize(("qos", "text"), [
    # qos_to_keyexpr (liveliness_utils.cpp:239-300) against qos.cpp:18-33's defaults
    (DEFAULT_QOS, "::,:,:,:,,"),
    (TF_QOS, "::,100:,:,:,,"),                     # DynamicBroadcasterQoS
    (TF_LISTENER_QOS, "::,100:,:,:,,"),            # DynamicListenerQoS
    (TF_STATIC_QOS, ":1:,1:,:,:,,"),               # StaticBroadcasterQoS
    (TF_STATIC_LISTENER_QOS, ":1:,100:,:,:,,"),    # StaticListenerQoS
    (QosProfile(reliability=2, history=2, depth=5, deadline=(1, 500)), "2::2,5:1,500:,:,,"),
    (QosProfile(liveliness=3, liveliness_lease_duration=(2, 0)), "::,:,:,:3,2,0"),
])
def test_qos_strings(qos: QosProfile, text: str) -> None:
    assert qos_to_keyexpr(qos) == text


def test_mangled_names() -> None:
    """mangle_name: every '/' becomes '%' (the root namespace is '%')."""
    assert mangle_name("/") == "%"
    assert mangle_name("/robot1/arm") == "%robot1%arm"
    assert mangle_name("/tf_static") == "%tf_static"


def test_node_and_endpoint_tokens() -> None:
    """Entity::Entity (liveliness_utils.cpp:384-418) for a node and its endpoints."""
    zid = "6a3f0e1d2c4b5a69788796a5b4c3d2e1"
    assert node_token(0, zid, 0, "/", "tfbus_7") == f"@ros2_lv/0/{zid}/0/0/NN/%/%/tfbus_7"
    assert node_token(3, zid, 0, "/robot1", "tfbus_7") == (
        f"@ros2_lv/3/{zid}/0/0/NN/%/%robot1/tfbus_7")
    assert endpoint_token(0, zid, 0, 1, "MS", "/", "tfbus_7", "/tf", TF_LISTENER_QOS) == (
        f"@ros2_lv/0/{zid}/0/1/MS/%/%/tfbus_7/%tf/{TYPE}/{HASH}/::,100:,:,:,,")
    assert endpoint_token(0, zid, 0, 4, "MP", "/robot1", "tfbus_7", "/robot1/tf_static",
                          TF_STATIC_QOS) == (
        f"@ros2_lv/0/{zid}/0/4/MP/%/%robot1/tfbus_7/%robot1%tf_static/{TYPE}/{HASH}"
        "/:1:,1:,:,:,,")
    with pytest.raises(ValueError, match="kind"):
        endpoint_token(0, zid, 0, 1, "NN", "/", "n", "/tf", TF_QOS)


GID = bytes(range(0xA0, 0xB0))
STAMP = 1_763_942_400_123_456_789
SEQ_1 = (1).to_bytes(8, "little", signed=True)
STAMP_LE = STAMP.to_bytes(8, "little", signed=True)
POSITIONAL = SEQ_1 + STAMP_LE + b"\x10" + GID  # attachment_helpers.cpp:67-74
LABELLED = (b"\x0fsequence_number" + SEQ_1 + b"\x10source_timestamp" + STAMP_LE
            + b"\x0asource_gid" + b"\x10" + GID)  # the Jazzy form, lines 50-60 / 104-115


def test_positional_attachment() -> None:
    att = Attachment(1, STAMP, GID)
    raw = encode_attachment(att)
    assert len(raw) == 33
    assert raw == POSITIONAL
    # the same bytes from eclipse-zenoh's own zenoh-ext serializer
    assert raw == z_serialize((Int64(1), Int64(STAMP), GID)).to_bytes()
    assert decode_attachment(raw) == att


def test_labelled_attachment() -> None:
    att = Attachment(1, STAMP, GID)
    raw = encode_attachment(att, "labelled")
    assert len(raw) == 77
    assert raw == LABELLED
    assert raw == z_serialize(("sequence_number", Int64(1), "source_timestamp", Int64(STAMP),
                               "source_gid", GID)).to_bytes()
    assert decode_attachment(raw) == att


def test_attachment_extremes_round_trip() -> None:
    for seq, stamp in ((2**63 - 1, -(2**63)), (0, 0), (123456789, 1)):
        att = Attachment(seq, stamp, bytes(16))
        assert decode_attachment(encode_attachment(att)) == att
        assert decode_attachment(encode_attachment(att, "labelled")) == att
    with pytest.raises(ValueError, match="gid"):
        encode_attachment(Attachment(1, 1, bytes(15)))
    with pytest.raises(ValueError, match="sequence_number"):
        encode_attachment(Attachment(2**63, 1, bytes(16)))
    with pytest.raises(ValueError, match="form"):
        encode_attachment(Attachment(1, 1, bytes(16)), "json")


@pytest.mark.parametrize("raw", [
    b"",
    POSITIONAL[:32],                                  # one byte short
    POSITIONAL[:16] + b"\x0f" + GID,                  # GID length 15 in 33 bytes
    POSITIONAL + b"\x00",                             # 34 bytes: neither form
    LABELLED[:-1],                                    # truncated GID
    LABELLED.replace(b"sequence_number", b"sequence_numbex"),
    LABELLED.replace(b"source_gid", b"source_gix"),
    LABELLED[:40],
    b"\x0fsequence_number\x01",                       # truncated int64
])
def test_bad_attachments_are_refused(raw: bytes) -> None:
    with pytest.raises(WireDecodeError):
        decode_attachment(raw)


def test_tokens_parse_back() -> None:
    zid = "aa11"
    node = parse_token(node_token(5, zid, 2, "/robot1", "arm_node"))
    assert node == EndpointToken(5, zid, "2", "2", "NN", "/robot1", "arm_node")
    pub = parse_token(endpoint_token(5, zid, 2, 9, "MP", "/", "talker", "/robot1/tf",
                                     TF_QOS))
    assert (pub.kind, pub.topic, pub.type_name, pub.type_hash) == (
        "MP", "/robot1/tf", TYPE, HASH)
    assert pub.node_key == "aa11/2"


@pytest.mark.parametrize("key", [
    "@ros2_lv/0/aa/0/0/NN/%/%",                                 # 8 chunks
    "@ros2/0/aa/0/0/NN/%/%/n",                                  # wrong admin space
    "@ros2_lv/x/aa/0/0/NN/%/%/n",                               # domain not a number
    "@ros2_lv/0/aa/0/0/XX/%/%/n",                               # unknown entity kind
    "@ros2_lv/0/aa/n/0/NN/%/%/n",                               # node id not a number
    "@ros2_lv/0/aa/0/0/NN/%/%/n/extra",                         # node with 10 chunks
    f"@ros2_lv/0/aa/0/1/MP/%/%/n/%tf/{TYPE}/{HASH}",            # endpoint without QoS
    f"@ros2_lv/0/aa/0/1/MP/%/%/n/%tf/{TYPE}/{HASH}/::,:,:,,",    # QoS of 5 fields
    f"@ros2_lv/0/aa/0/1/MP/%/%/n/%tf/{TYPE}/{HASH}/::,:,:,:,,/x",
    "@ros2_lv/0/a*/0/0/NN/%/%/n",                               # wild chunk
    "@ros2_lv/99999999999/aa/0/0/NN/%/%/n",                     # absurd domain
    "@ros2_lv/\u00b2/aa/0/0/NN/%/%/n",                          # a digit int() refuses
    "@ros2_lv/0/aa/\u0663/0/NN/%/%/n",                          # an Arabic-Indic digit
])
def test_hostile_tokens_are_refused(key: str) -> None:
    with pytest.raises(WireDecodeError):
        parse_token(key)
