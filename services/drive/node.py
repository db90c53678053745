"""A ROS 2 node on a Zenoh session, as rmw_zenoh makes one: a node token, and publishers and
subscriptions that carry rmw_zenoh's keys, endpoint tokens, attachment and CDR (:mod:`wire`).

With it ``ros2 node list`` on the robot shows the node and ``ros2 topic list`` / ``ros2 topic info
-v`` its endpoints, and the robot's nodes take its samples. The session must be a client of the
robot's router (``rmw_zenohd``): ROS 2 nodes run as peers and the router does not relay between
peers, so a peer that is not on their host would see nothing.

A subscription listens to every hash of its type (``<domain>/<topic>/<type>/*``) and takes the
samples whose hash chunk is its type's RIHS01 hash or Humble's ``TypeHashNotSupported``, so it
hears Humble and Jazzy-or-later robots alike; a sample with another hash (another definition of
the type), without the attachment, or whose bytes do not decode is counted by reason in
``RosNode.rejected`` and logged once per reason, never handed on.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from services.drive import wire

log = logging.getLogger("navlearn.drive.node")


class RosNode:
    """A ROS 2 node named ``name`` in ``namespace`` on ROS domain ``domain``, on ``session``.

    ``publisher(...)`` and ``subscribe(...)`` declare endpoints; ``close()`` (or the ``with``
    block's end) undeclares everything, tokens last but one: the node's own token goes last.
    """

    def __init__(self, session, name: str, domain: int = 0, namespace: str = "/", distro: str = "jazzy"):
        self.session, self.distro = session, distro
        self.name = wire.NodeName(int(domain), str(session.zid()), 0, name, namespace)
        self._declared: list[Any] = []
        self._next_id = 1
        self.rejected: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._node_token = session.liveliness().declare_token(self.name.token())

    def _entity(self, kind: str, topic: str, msgtype: str, qos: wire.QoS) -> tuple[str, str]:
        """(data key, endpoint token) of a new endpoint, declaring the token."""
        hash_chunk = wire.type_hash(msgtype, self.distro)
        key = wire.topic_key(self.name.domain, topic, msgtype, hash_chunk)
        token = self.name.endpoint_token(self._next_id, kind, topic, msgtype, hash_chunk, qos)
        self._next_id += 1
        self._declared.append(self.session.liveliness().declare_token(token))
        return key, token

    def publisher(self, topic: str, msgtype: str, qos: wire.QoS = wire.DEFAULT_QOS) -> RosPublisher:
        key, token = self._entity("MP", topic, msgtype, qos)
        publisher = RosPublisher(self.session.declare_publisher(key), msgtype, wire.entity_gid(token))
        self._declared.append(publisher.publisher)
        return publisher

    def subscribe(
        self,
        topic: str,
        msgtype: str,
        callback: Callable[[Any, tuple[int, int, bytes]], None],
        qos: wire.QoS = wire.SENSOR_QOS,
    ):
        """Call ``callback(message, (seq, source timestamp ns, gid))`` for each valid sample on
        ``topic`` (in a Zenoh thread: keep it short)."""
        key, _ = self._entity("MS", topic, msgtype, qos)
        accepted = {wire.type_hash(msgtype, d) for d in ("jazzy", "humble")}
        pattern = key.rsplit("/", 1)[0] + "/*"

        def on_sample(sample) -> None:
            hash_chunk = str(sample.key_expr).rsplit("/", 1)[-1]
            if hash_chunk not in accepted:
                return self._reject(
                    f"type_hash:{topic}",
                    f"{topic}: a publisher's type hash {hash_chunk} is "
                    f"not {msgtype}'s ({sorted(accepted)}): another definition of the type",
                )
            attachment = sample.attachment
            try:
                info = wire.read_attachment(None if attachment is None else attachment.to_bytes())
                message = wire.decode(sample.payload.to_bytes(), msgtype)
            except wire.WireError as exc:
                return self._reject(f"malformed:{topic}", f"{topic}: {exc}")
            callback(message, info)

        subscriber = self.session.declare_subscriber(pattern, on_sample)
        self._declared.append(subscriber)
        return subscriber

    def _reject(self, reason: str, message: str) -> None:
        with self._lock:
            self.rejected[reason] += 1
            first = self.rejected[reason] == 1
        if first:
            log.warning("dropping samples: %s", message)

    def close(self) -> None:
        for entity in reversed(self._declared):
            entity.undeclare()
        self._declared.clear()
        if self._node_token is not None:
            self._node_token.undeclare()
            self._node_token = None

    def __enter__(self) -> RosNode:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


class RosPublisher:
    """Publishes rosbags messages of one type with rmw_zenoh's attachment (sequence from 1)."""

    def __init__(self, publisher, msgtype: str, gid: bytes) -> None:
        self.publisher, self.msgtype, self.gid = publisher, msgtype, gid
        self.seq = 0
        self._lock = threading.RLock()  # the control loop and a signal handler (same thread) both publish

    def put(self, message) -> None:
        payload = wire.encode(message, self.msgtype)
        with self._lock:
            self.seq += 1
            self.publisher.put(payload, attachment=wire.attachment(self.seq, time.time_ns(), self.gid))
