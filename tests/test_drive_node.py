"""services.drive.node on two real Zenoh sessions on loopback: what a RosNode puts on the wire
(rmw_zenoh's key, attachment, CDR, tokens) and what its subscriptions take or refuse (Humble and
Jazzy hashes taken; another hash, no attachment or bad bytes counted and dropped)."""

from __future__ import annotations

import threading
import time

import pytest

from services.common.transport import ZenohSettings, open_session
from services.drive import wire
from services.drive.node import RosNode
from tests.conftest import free_port

pytestmark = pytest.mark.integration


@pytest.fixture
def sessions():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    a = open_session(ZenohSettings(mode="peer", listen=[endpoint]))
    b = open_session(ZenohSettings(mode="peer", connect=[endpoint], connect_timeout=10))
    with a, b:
        time.sleep(0.3)
        yield a, b


def wait(predicate, timeout: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def test_a_publisher_writes_rmw_zenohs_key_attachment_and_cdr(sessions):
    a, b = sessions
    got = []
    raw = b.declare_subscriber("0/robot1/cmd_vel/**", lambda s: got.append(s))
    with RosNode(a, "drive_test", 0) as node:
        publisher = node.publisher("/robot1/cmd_vel", wire.TWIST)
        time.sleep(0.3)
        publisher.put(wire.twist(0.25, -0.5))
        publisher.put(wire.twist(0.0, 0.0))
        assert wait(lambda: len(got) == 2)
        tokens = [str(r.ok.key_expr) for r in b.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok]
    raw.undeclare()
    key = f"0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/{wire.type_hash(wire.TWIST)}"
    assert [str(s.key_expr) for s in got] == [key, key]
    endpoint = next(t for t in tokens if "/MP/" in t)
    assert endpoint == (
        f"@ros2_lv/0/{a.zid()}/0/1/MP/%/%/drive_test/%robot1%cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        f"{wire.type_hash(wire.TWIST)}/::,10:,:,:,,"
    )
    assert f"@ros2_lv/0/{a.zid()}/0/0/NN/%/%/drive_test" in tokens
    seqs = []
    for sample in got:
        attachment = sample.attachment.to_bytes()
        assert len(attachment) == 33
        seq, stamp, gid = wire.read_attachment(attachment)
        assert gid == wire.entity_gid(endpoint) and abs(stamp - time.time_ns()) < 10e9
        seqs.append(seq)
    assert seqs == [1, 2]
    message = wire.decode(got[0].payload.to_bytes(), wire.TWIST)
    assert (message.linear.x, message.angular.z) == (0.25, -0.5)
    # the node's tokens leave with it (the undeclarations reach the other session within a bound)
    assert wait(lambda: not [r for r in b.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok], 10.0)


def test_a_subscription_takes_humble_and_jazzy_and_counts_what_it_refuses(sessions):
    a, b = sessions
    received, lock = [], threading.Lock()
    scan = wire.laser_scan([1.0, 2.0], 0.0, 0.1, 0.1, 5.0, 7, "laser")
    payload = wire.encode(scan, wire.LASER_SCAN)
    attachment = wire.attachment(1, time.time_ns(), bytes(16))
    keys = {h: wire.topic_key(0, "/scan", wire.LASER_SCAN, h) for h in
            (wire.type_hash(wire.LASER_SCAN), "TypeHashNotSupported", "RIHS01_" + "0" * 64)}  # fmt: skip
    with RosNode(a, "listener", 0) as node:

        def on_scan(_message, info) -> None:
            with lock:
                received.append(info)

        node.subscribe("/scan", wire.LASER_SCAN, on_scan)
        time.sleep(0.3)
        for key in keys.values():
            b.put(key, payload, attachment=attachment)
        b.put(keys[wire.type_hash(wire.LASER_SCAN)], payload)  # no attachment: rmw_zenoh drops it too
        b.put(keys[wire.type_hash(wire.LASER_SCAN)], b"\x00\x01\x00\x00\x01", attachment=attachment)
        assert wait(lambda: sum(node.rejected.values()) == 3 and len(received) == 2)
        time.sleep(0.2)
        assert len(received) == 2 and received[0][0] == 1
        assert node.rejected == {"type_hash:/scan": 1, "malformed:/scan": 2}
