"""ROS 2's wire as rmw_zenoh writes it: key expressions, liveliness tokens, the attachment, CDR.

Read from rmw_zenoh's release sources (ros2-gbp/rmw_zenoh-release, Jazzy 0.2.x, Kilted 0.6.7:
``src/detail/liveliness_utils.cpp``, ``attachment_helpers.cpp``, ``qos.cpp``) and its
``docs/design.md``; /work/shared/CHECKED.md has the summary. This module is the one place where
ROS 2 bytes become objects (as ``protocols/`` is for navlearn's own messages); it stays out of
``protocols/`` because it needs rosbags, which ``protocols/`` must not depend on.

* Data key: ``<domain>/<topic without leading or trailing '/'>/<pkg>::msg::dds_::<Name>_/<hash>``,
  the hash ``RIHS01_<64 hex>`` (the type's RIHS01 hash, computed by rosbags) on Jazzy and later,
  ``TypeHashNotSupported`` on Humble. A wrong hash fails silently on a real robot (the topic is
  listed, no data flows), so the hashes are tested against vectors from ROS 2 itself.
* Liveliness tokens (so ``ros2 node list`` / ``ros2 topic list`` see us): a node
  ``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>``, an endpoint
  ``@ros2_lv/<domain>/<zid>/<nid>/<id>/MP|MS/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>``,
  every ``/`` inside a field written ``%`` (the root namespace and the default enclave are ``%``).
  The QoS field leaves rmw_zenoh's defaults (reliable, volatile, keep last 42) empty.
* Attachment, on every sample (rmw_zenoh drops a sample without it): sequence number (int64, from
  1), source timestamp (int64 ns), source gid (16 bytes), in zenoh-ext serialization: 33 bytes.
* Payload: CDR with its 4-byte encapsulation header, rosbags' ``serialize_cdr``/``deserialize_cdr``.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from zenoh import ZBytes
from zenoh.ext import Int64, ZDeserializeError, z_deserialize, z_serialize

from services.drive.config import DISTROS

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
ADMIN_SPACE = "@ros2_lv"
HUMBLE_HASH = "TypeHashNotSupported"
"""the hash chunk of every data key and token of rmw_zenoh on Humble (no type hashes there)"""
GID_SIZE = 16


class WireError(ValueError):
    """Bytes or names that are not ROS 2 as rmw_zenoh writes it (the message says what and why)."""


@functools.cache
def typestore():
    """rosbags' typestore of ROS 2 Jazzy: the message definitions, CDR and RIHS01 hashes. The five
    types used here are the same in Humble, Jazzy and Kilted."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def dds_type(msgtype: str) -> str:
    """``sensor_msgs/msg/LaserScan`` -> ``sensor_msgs::msg::dds_::LaserScan_`` (the type chunk)."""
    package, kind, name = _split_type(msgtype)
    return f"{package}::{kind}::dds_::{name}_"


def _split_type(msgtype: str) -> tuple[str, str, str]:
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise WireError(f"{msgtype!r} is not a ROS 2 type name like sensor_msgs/msg/LaserScan")
    return parts[0], parts[1], parts[2]


def type_hash(msgtype: str, distro: str = "jazzy") -> str:
    """The hash chunk rmw_zenoh writes for ``msgtype`` on ``distro``: ``RIHS01_<hex>`` (computed by
    rosbags from the message definition) or, on Humble, ``TypeHashNotSupported``."""
    if distro not in DISTROS:
        raise WireError(f"unknown ROS 2 distribution {distro!r}; one of {', '.join(DISTROS)}")
    if distro == "humble":
        return HUMBLE_HASH
    return typestore().hash_rihs01(msgtype)


def topic_key(domain: int, topic: str, msgtype: str, hash_chunk: str) -> str:
    """The data key expression of ``topic`` (``/robot1/scan`` -> ``0/robot1/scan/...``)."""
    name = check_topic(topic).strip("/")
    return f"{int(domain)}/{name}/{dds_type(msgtype)}/{hash_chunk}"


def check_topic(topic: str) -> str:
    """``topic`` if it is a fully qualified ROS 2 topic name (``/scan``, ``/robot1/odom``), else WireError."""
    if not topic.startswith("/") or topic.endswith("/") or "//" in topic or len(topic) < 2:
        raise WireError(f"topic {topic!r} must be absolute, like /scan or /robot1/cmd_vel")
    bad = [ch for ch in topic if not (ch.isalnum() or ch in "/_")]
    if bad or any(part[0].isdigit() for part in topic[1:].split("/")):
        raise WireError(
            f"topic {topic!r}: ROS 2 names hold letters, digits and _, no part starts with a digit"
        )
    return topic


def mangle(name: str) -> str:
    """A name as one token chunk: every ``/`` becomes ``%`` (rmw_zenoh's ``mangle_name``)."""
    if not name:
        raise WireError("an empty name cannot be a liveliness token chunk")
    return name.replace("/", "%")


@dataclass(frozen=True)
class QoS:
    """The QoS of an endpoint, as far as its token says it (rmw's enum values)."""

    reliability: int = 1
    """1 reliable, 2 best effort"""
    durability: int = 2
    """1 transient local, 2 volatile"""
    depth: int = 10
    """history depth (keep last)"""

    def chunk(self) -> str:
        """rmw_zenoh's ``qos_to_keyexpr``: ``<rel>:<dur>:<hist>,<depth>:<deadline s>,<ns>:<lifespan
        s>,<ns>:<liveliness>,<lease s>,<ns>``, each part empty when it is rmw_zenoh's default
        (reliable, volatile, keep last, depth 42, infinite durations, automatic liveliness)."""
        rel = "" if self.reliability == 1 else str(self.reliability)
        dur = "" if self.durability == 2 else str(self.durability)
        depth = "" if self.depth == 42 else str(self.depth)
        return f"{rel}:{dur}:,{depth}:,:,:,,"


DEFAULT_QOS = QoS()
"""rclcpp's ``QoS(10)``: reliable, volatile, keep last 10 (what nav2 and teleop use for /cmd_vel)"""
SENSOR_QOS = QoS(reliability=2, depth=5)
"""``rclcpp::SensorDataQoS()``: best effort, keep last 5 (lidar drivers publish /scan so; a best-effort
subscription also matches reliable publishers, a reliable one does not match best-effort ones)"""


@dataclass(frozen=True)
class NodeName:
    """Where a node sits in a ROS 2 graph."""

    domain: int
    zid: str
    """the Zenoh session id, as ``str(session.zid())`` writes it"""
    nid: int
    name: str
    namespace: str = "/"
    enclave: str = "/"

    def token(self) -> str:
        """The node's liveliness token (``NN``)."""
        return "/".join(
            (ADMIN_SPACE, str(self.domain), self.zid, str(self.nid), str(self.nid), "NN",
             mangle(self.enclave), mangle(self.namespace), mangle(self.name))
        )  # fmt: skip

    def endpoint_token(self, eid: int, kind: str, topic: str, msgtype: str, hash_chunk: str, qos: QoS) -> str:
        """The liveliness token of a publisher (``MP``) or subscription (``MS``) of this node."""
        if kind not in ("MP", "MS"):
            raise WireError(f"endpoint kind must be MP or MS, got {kind!r}")
        return "/".join(
            (ADMIN_SPACE, str(self.domain), self.zid, str(self.nid), str(eid), kind, mangle(self.enclave),
             mangle(self.namespace), mangle(self.name), mangle(check_topic(topic)), dds_type(msgtype),
             hash_chunk, qos.chunk())
        )  # fmt: skip


def parse_token(token: str) -> dict[str, Any]:
    """The fields of a liveliness token (domain, zid, nid, id, kind, enclave, namespace, node and,
    for endpoints, topic, type, hash, qos), names with their ``/`` back; WireError if it is not one."""
    parts = str(token).split("/")
    if len(parts) not in (9, 13) or parts[0] != ADMIN_SPACE or parts[5] not in ("NN", "MP", "MS", "SS", "SC"):
        raise WireError(f"{token!r} is not an rmw_zenoh liveliness token")
    names = (
        "domain",
        "zid",
        "nid",
        "id",
        "kind",
        "enclave",
        "namespace",
        "node",
        "topic",
        "type",
        "hash",
        "qos",
    )
    out: dict[str, Any] = dict(zip(names, parts[1:], strict=False))
    for key in ("enclave", "namespace", "node", "topic"):
        if key in out:
            out[key] = out[key].replace("%", "/")
    out["domain"], out["nid"], out["id"] = int(out["domain"]), int(out["nid"]), int(out["id"])
    return out


def entity_gid(token: str) -> bytes:
    """A 16-byte gid for the entity whose liveliness token is ``token``. rmw_zenoh hashes the token
    with XXH3-128; any stable 16 bytes unique per entity serve (ROS reads the gid as an identifier
    and never recomputes it), so this takes BLAKE2b-128 of the same string, from the standard library."""
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE).digest()


def attachment(seq: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The attachment of every sample: zenoh-ext serialization of (int64 seq, int64 ns, 16-byte gid)."""
    if len(gid) != GID_SIZE:
        raise WireError(f"a gid has {GID_SIZE} bytes, got {len(gid)}")
    return z_serialize((Int64(seq), Int64(timestamp_ns), bytes(gid))).to_bytes()


def read_attachment(raw: bytes | None) -> tuple[int, int, bytes]:
    """(seq, timestamp ns, gid) of an attachment; WireError when missing or malformed."""
    if raw is None:
        raise WireError("sample without the rmw_zenoh attachment (sequence number, timestamp, gid)")
    try:
        seq, stamp, gid = z_deserialize(tuple[Int64, Int64, bytes], ZBytes(bytes(raw)))
    except (ZDeserializeError, ValueError, TypeError) as exc:
        raise WireError(f"malformed rmw_zenoh attachment of {len(raw)} bytes: {exc}") from None
    if len(gid) != GID_SIZE:
        raise WireError(f"rmw_zenoh attachment gid has {len(gid)} bytes, expected {GID_SIZE}")
    return int(seq), int(stamp), bytes(gid)


def encode(message: Any, msgtype: str) -> bytes:
    """CDR bytes (little-endian, with the encapsulation header) of a rosbags message object."""
    return bytes(typestore().serialize_cdr(message, msgtype))


def decode(raw: bytes, msgtype: str) -> Any:
    """The rosbags message object in CDR bytes ``raw``; WireError saying why when they do not hold one."""
    raw = bytes(raw)
    if len(raw) < 4 or raw[0] != 0 or raw[1] not in (0, 1):
        raise WireError(f"{msgtype}: {len(raw)} bytes without a CDR encapsulation header (00 00 or 00 01)")
    try:
        return typestore().deserialize_cdr(raw, msgtype)
    except Exception as exc:  # rosbags raises struct, index and its own errors on short or bad bytes
        raise WireError(
            f"{msgtype}: {len(raw)} bytes do not decode as CDR ({type(exc).__name__}: {exc})"
        ) from None


# ------------------------------------------------------------------ message objects


def _types():
    return typestore().types


def stamp(ns: int):
    """builtin_interfaces/msg/Time of ``ns`` nanoseconds."""
    return _types()["builtin_interfaces/msg/Time"](
        sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)
    )


def header(ns: int, frame_id: str):
    return _types()["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame_id)


def stamp_ns(message) -> int:
    """The header stamp of a stamped message, in nanoseconds."""
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def _vector(x: float = 0.0, y: float = 0.0, z: float = 0.0):
    return _types()["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def twist(linear: float, angular: float):
    """geometry_msgs/msg/Twist: forward speed (m/s) and yaw rate (rad/s), the rest zero."""
    return _types()[TWIST](linear=_vector(linear), angular=_vector(z=angular))


def twist_stamped(linear: float, angular: float, ns: int, frame_id: str):
    return _types()[TWIST_STAMPED](header=header(ns, frame_id), twist=twist(linear, angular))


def pose(x: float, y: float, yaw: float):
    """geometry_msgs/msg/Pose at (x, y, 0) facing ``yaw``."""
    types = _types()
    return types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
        orientation=types["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        ),
    )


def yaw_of(orientation) -> float:
    """The yaw (rad) of a geometry_msgs/msg/Quaternion (rotation about z; roll and pitch ignored)."""
    q = orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose_stamped(x: float, y: float, yaw: float, ns: int, frame_id: str):
    return _types()[POSE_STAMPED](header=header(ns, frame_id), pose=pose(x, y, yaw))


def odometry(
    x: float, y: float, yaw: float, linear: float, angular: float, ns: int, frame_id: str, child: str
):
    """nav_msgs/msg/Odometry: pose in ``frame_id``, twist in ``child`` (covariances zero: unknown)."""
    types = _types()
    return types[ODOMETRY](
        header=header(ns, frame_id),
        child_frame_id=child,
        pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose(x, y, yaw), covariance=np.zeros(36)),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=twist(linear, angular), covariance=np.zeros(36)
        ),
    )


def laser_scan(ranges, angle_min: float, angle_increment: float, range_min: float, range_max: float, ns: int,
               frame_id: str, scan_time: float = 0.0):  # fmt: skip
    """sensor_msgs/msg/LaserScan of ``ranges`` (float32) at ``angle_min + i * angle_increment``."""
    ranges = np.asarray(ranges, np.float32)
    return _types()[LASER_SCAN](
        header=header(ns, frame_id),
        angle_min=float(angle_min),
        angle_max=float(angle_min + (len(ranges) - 1) * angle_increment),
        angle_increment=float(angle_increment),
        time_increment=0.0,
        scan_time=float(scan_time),
        range_min=float(range_min),
        range_max=float(range_max),
        ranges=ranges,
        intensities=np.zeros(0, np.float32),
    )
