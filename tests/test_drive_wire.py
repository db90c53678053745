"""services.drive.wire against rmw_zenoh's formats, ROS 2's type hashes and bytes ROS 2 wrote.

Provenance of the vectors (each written by ROS 2 itself, not by this code or rosbags):
- DESIGN_*: rmw_zenoh ``docs/design.md`` (Jazzy branch), its examples of a data key and of the
  liveliness tokens of the ``listener`` / ``talker`` demo nodes; the formats agree with
  ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`` (``TopicInfo``, ``Entity::Entity``,
  ``qos_to_keyexpr``) of ros2-gbp/rmw_zenoh-release ``release/kilted/rmw_zenoh_cpp`` 0.6.7.
- RIHS01 hashes: std_msgs/msg/String from that design.md key (and ``ros2 bag record`` metadata
  of Jazzy, ``type_description_hash``); geometry_msgs/msg/Twist as ``ros2 topic info /cmd_vel
  --verbose`` prints it on a Jazzy system (``Topic type hash: RIHS01_9c45...``);
  sensor_msgs/msg/PointCloud from a Jazzy ``ros2 bag record`` metadata.yaml; LaserScan,
  Odometry, PoseStamped and TwistStamped as /work/shared/CHECKED.md pins them (rmw_zenoh
  section), the same strings that the type tables of independent ROS 2-over-Zenoh clients in
  the public GitHub index carry.
- CDR bytes: the held-out rosbag2 recordings (``/work/shared/data/holdout/rosbag2/``, written by
  ``ros2 bag record`` on ROS 2 Humble; provenance and sha256 in its README and summary.json).
"""

from __future__ import annotations

import hashlib
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from services.drive import wire

HOLDOUT = Path("/work/shared/data/holdout/rosbag2")
DESIGN_STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
DESIGN_KEY = f"0/chatter/std_msgs::msg::dds_::String_/{DESIGN_STRING_HASH}"
DESIGN_NODE = "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
DESIGN_SUB = (
    "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
    f"std_msgs::msg::dds_::String_/{DESIGN_STRING_HASH}/::,10:,:,:,,"
)
DESIGN_PUB = (
    "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    f"std_msgs::msg::dds_::String_/{DESIGN_STRING_HASH}/::,7:,:,:,,"
)
RIHS = "RIHS01_"
ROS2_HASHES = {
    "std_msgs/msg/String": DESIGN_STRING_HASH,
    "geometry_msgs/msg/Twist": "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    "sensor_msgs/msg/PointCloud": "RIHS01_614593df71d3c2b9bd4604a71b750fd218f0d65c045ea988b713719455a65b3b",
    "geometry_msgs/msg/TwistStamped": RIHS
    + "5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
    "sensor_msgs/msg/LaserScan": "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "geometry_msgs/msg/PoseStamped": RIHS
    + "10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
}


@pytest.mark.parametrize("msgtype", sorted(ROS2_HASHES))
def test_rihs01_hashes_equal_ros2s(msgtype):
    assert wire.type_hash(msgtype) == ROS2_HASHES[msgtype]
    assert wire.type_hash(msgtype, "kilted") == ROS2_HASHES[msgtype]
    assert wire.type_hash(msgtype, "humble") == "TypeHashNotSupported"


def test_data_key_is_the_design_documents():
    assert wire.topic_key(0, "/chatter", "std_msgs/msg/String", DESIGN_STRING_HASH) == DESIGN_KEY
    # inner slashes stay key separators; the domain leads
    key = wire.topic_key(7, "/robot1/cmd_vel", wire.TWIST, wire.type_hash(wire.TWIST))
    assert key == f"7/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/{ROS2_HASHES[wire.TWIST]}"


def test_liveliness_tokens_are_the_design_documents():
    listener = wire.NodeName(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "listener")
    assert listener.token() == DESIGN_NODE
    sub = listener.endpoint_token(10, "MS", "/chatter", "std_msgs/msg/String", DESIGN_STRING_HASH, wire.QoS())
    assert sub == DESIGN_SUB
    talker = wire.NodeName(0, "8b20917502ee955ac4476e0266340d5c", 0, "talker")
    pub = talker.endpoint_token(
        10, "MP", "/chatter", "std_msgs/msg/String", DESIGN_STRING_HASH, wire.QoS(depth=7)
    )
    assert pub == DESIGN_PUB


def test_qos_chunks_and_parsing():
    assert wire.SENSOR_QOS.chunk() == "2::,5:,:,:,,"
    assert wire.QoS(depth=42).chunk() == "::,:,:,:,,"  # every part rmw_zenoh's default: all empty
    fields = wire.parse_token(DESIGN_PUB)
    assert fields["kind"] == "MP" and fields["node"] == "talker" and fields["topic"] == "/chatter"
    assert fields["namespace"] == "/" and fields["id"] == 10 and fields["qos"] == "::,7:,:,:,,"
    ns = wire.NodeName(3, "ab", 1, "drive", namespace="/robot1")
    assert ns.token() == "@ros2_lv/3/ab/1/1/NN/%/%robot1/drive"
    assert wire.parse_token(ns.token())["namespace"] == "/robot1"
    with pytest.raises(wire.WireError):
        wire.parse_token("navlearn/run/alive/actor/a")


@pytest.mark.parametrize("topic", ["scan", "/scan/", "//scan", "/2scan", "/sc an", "/"])
def test_bad_topics_are_refused(topic):
    with pytest.raises(wire.WireError, match="topic"):
        wire.topic_key(0, topic, wire.LASER_SCAN, "h")


def test_attachment_is_33_bytes_as_rmw_zenoh_serializes_it():
    gid = bytes(range(16))
    raw = wire.attachment(5, 1_700_000_000_123_456_789, gid)
    # rmw_zenoh's AttachmentData::serialize_to_zbytes: int64 seq, int64 stamp, then the 16-byte
    # array as a zenoh-ext sequence (LEB128 length 16, then the bytes), all little-endian
    assert raw == struct.pack("<qqB", 5, 1_700_000_000_123_456_789, 16) + gid
    assert wire.read_attachment(raw) == (5, 1_700_000_000_123_456_789, gid)
    with pytest.raises(wire.WireError, match="without"):
        wire.read_attachment(None)
    with pytest.raises(wire.WireError):
        wire.read_attachment(raw[:20])
    assert len(wire.entity_gid(DESIGN_PUB)) == 16 and wire.entity_gid(DESIGN_PUB) != wire.entity_gid(
        DESIGN_SUB
    )


def _bag_messages(bag: str, topic: str, limit: int | None = None):
    from rosbags.rosbag2 import Reader

    with Reader(HOLDOUT / bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
            if limit is not None and k >= limit:
                return
            yield conn.msgtype, bytes(raw)


@pytest.mark.parametrize(
    ("bag", "topic"),
    [
        ("gazebo_tb3_walker", "/scan"),
        ("gazebo_tb3_walker", "/odom"),
        ("mumble_rplidar_real", "/scan"),
    ],
)
def test_decodes_what_ros2_wrote_and_reencodes_it_byte_for_byte(bag, topic):
    summary = {b["bag"]: b for b in json.loads((HOLDOUT / "summary.json").read_text())}[bag]
    detail = summary["topics"][topic]["detail"]
    count = 0
    for k, (msgtype, raw) in enumerate(_bag_messages(bag, topic)):
        message = wire.decode(raw, msgtype)
        assert wire.encode(message, msgtype) == raw
        if k == 0:  # the first message against the recording's summary (an oracle written beside it)
            first = detail["first_message"]
            assert hashlib.sha256(raw).hexdigest() == first["raw_sha256"]
            assert [message.header.stamp.sec, message.header.stamp.nanosec] == first["stamp"]
            if msgtype == wire.LASER_SCAN:
                np.testing.assert_allclose(message.ranges[:5], first["ranges_first5"], rtol=1e-7)
            else:
                p = message.pose.pose.position
                np.testing.assert_allclose([p.x, p.y, p.z], first["position"])
        count += 1
    assert count == detail["n"]


def test_encoding_round_trips_the_messages_drive_and_sim_write():
    cases = [
        (wire.TWIST, wire.twist(0.3, -0.7)),
        (wire.TWIST_STAMPED, wire.twist_stamped(0.3, -0.7, 12_000_000_001, "base_link")),
        (wire.POSE_STAMPED, wire.pose_stamped(1.5, -2.0, 0.8, 5, "odom")),
        (wire.ODOMETRY, wire.odometry(1.0, 2.0, -3.0, 0.2, 0.1, 9, "odom", "base_footprint")),
        (wire.LASER_SCAN, wire.laser_scan([1.0, np.inf, np.nan, 0.5], -math.pi, 0.1, 0.1, 6.0, 3, "laser")),
    ]
    for msgtype, message in cases:
        raw = wire.encode(message, msgtype)
        assert raw[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation, as rmw_zenoh sends
        again = wire.decode(raw, msgtype)
        assert wire.encode(again, msgtype) == raw
    scan = wire.decode(wire.encode(cases[-1][1], wire.LASER_SCAN), wire.LASER_SCAN)
    assert np.isinf(scan.ranges[1]) and np.isnan(scan.ranges[2])
    assert math.isclose(
        wire.yaw_of(
            wire.decode(wire.encode(cases[2][1], wire.POSE_STAMPED), wire.POSE_STAMPED).pose.orientation
        ),
        0.8,
        rel_tol=1e-12,
    )


@pytest.mark.parametrize("raw", [b"", b"\x00\x01", b"\x07\x07\x00\x00abcd", b"\x00\x01\x00\x00\x01"])
def test_bad_bytes_get_a_clear_error(raw):
    with pytest.raises(wire.WireError, match="LaserScan"):
        wire.decode(raw, wire.LASER_SCAN)
