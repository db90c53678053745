"""End to end through a real Zenoh router: `navlearn ros2-sim` + `navlearn drive` + a goal
published as a PoseStamped. The robot reaches the goal, the ROS 2 graph (liveliness tokens) shows
both nodes as rmw_zenoh would, a stale scan brings zero velocity within 0.5 s, and SIGTERM sends
zero velocity first; a smaller robot (--robot-radius) reaches the goal of the same episode shrunk to
it. Paired figures over many episodes: bench/ros2_drive.py (results/ros2/)."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time

import pytest

from services.common.transport import ZenohSettings, open_session
from services.drive import wire
from services.drive.node import RosNode
from services.drive.trial import Trial, robot_status
from tests.conftest import free_port
from tests.drive_helpers import FAST
from tests.wire_helpers import start, stop, wait_for_line

pytestmark = [pytest.mark.integration, pytest.mark.slow]
EPISODE = 32
"""the unseen set's episode with the shortest A* path (5.7 m), which the shipped policy solves"""
STALE_AFTER = 0.3


class Commands:
    """Every /cmd_vel and /scan sample this test's own node receives, with its arrival time."""

    def __init__(self, node: RosNode) -> None:
        self.cmds: list[tuple[float, float, float]] = []
        self.scans: list[float] = []
        self.lock = threading.Lock()
        node.subscribe("/cmd_vel", wire.TWIST, self._cmd, wire.DEFAULT_QOS)
        node.subscribe("/scan", wire.LASER_SCAN, self._scan)

    def _cmd(self, message, _info) -> None:
        with self.lock:
            self.cmds.append((time.monotonic(), message.linear.x, message.angular.z))

    def _scan(self, _message, _info) -> None:
        with self.lock:
            self.scans.append(time.monotonic())

    def wait_moving(self, timeout: float = 15.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if self.cmds and (self.cmds[-1][1] != 0.0 or self.cmds[-1][2] != 0.0):
                    return
            time.sleep(0.01)
        raise AssertionError("the robot never moved")


@contextlib.contextmanager
def running(sim_args: tuple[str, ...] = (), drive_args: tuple[str, ...] = ()):
    """A router, `navlearn ros2-sim` on episode EPISODE and `navlearn drive` of the shipped policy,
    all stopped on the way out."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    zenoh = ["--connect", endpoint, "--run", "e2e"]
    cli = ["-m", "services.cli"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NAVLEARN_", "ROS_"))}
    router, router_lines = start([*cli, "router", "--listen", endpoint], env)
    procs = [router]
    try:
        wait_for_line(router_lines, "listening", 20)
        sim, sim_lines = start(
            [*cli, "ros2-sim", "--map", f"unseen:{EPISODE}", "--odom-rate", "100", *sim_args, *zenoh], env
        )
        drive, drive_lines = start(
            [
                *cli,
                "drive",
                "--policy",
                "pretrained/nnql",
                *FAST,
                "--stale-after",
                str(STALE_AFTER),
                "--max-actions",
                "200",
                *drive_args,
                *zenoh,
            ],
            env,
        )
        procs += [sim, drive]
        wait_for_line(sim_lines, "simulated robot", 25)
        wait_for_line(drive_lines, "driving", 25)
        session = open_session(ZenohSettings(connect=[endpoint], run="e2e", connect_timeout=10))
        with session, Trial(session, "e2e") as trial:
            yield {
                "trial": trial,
                "session": session,
                "endpoint": endpoint,
                "env": env,
                "sim": sim,
                "drive": drive,
                "drive_lines": drive_lines,
                "commands": Commands(trial.node),
            }
    finally:
        for proc in reversed(procs):
            stop(proc)


@pytest.fixture(scope="module")
def stack():
    with running() as parts:
        yield parts


def test_the_robot_reaches_its_goal(stack):
    result = stack["trial"].run_goal(timeout=25)
    assert result["outcome"] == "success", result
    assert result["final_distance"] <= 0.5 and result["action_timeouts"] == 0


def test_the_ros2_graph_sees_both_nodes_and_their_endpoints(stack):
    """What `ros2 node list` / `ros2 topic list -v` read: rmw_zenoh liveliness tokens under
    @ros2_lv/<domain>/, in the design document's format."""
    tokens = [
        wire.parse_token(reply.ok.key_expr)
        for reply in stack["session"].liveliness().get("@ros2_lv/0/**", timeout=2.0)
        if reply.ok is not None
    ]
    seen = {(t["node"], t["kind"], t.get("topic"), t.get("type"), t.get("hash")) for t in tokens}
    twist, scan = wire.type_hash(wire.TWIST), wire.type_hash(wire.LASER_SCAN)
    assert ("navlearn_drive", "NN", None, None, None) in seen
    assert ("navlearn_sim", "NN", None, None, None) in seen
    assert ("navlearn_drive", "MP", "/cmd_vel", "geometry_msgs::msg::dds_::Twist_", twist) in seen
    assert ("navlearn_drive", "MS", "/scan", "sensor_msgs::msg::dds_::LaserScan_", scan) in seen
    assert ("navlearn_sim", "MP", "/scan", "sensor_msgs::msg::dds_::LaserScan_", scan) in seen
    assert {t.get("topic") for t in tokens if t["node"] == "navlearn_drive"} >= {"/odom", "/goal_pose"}
    drive_zid = {t["zid"] for t in tokens if t["node"] == "navlearn_drive"}
    assert len(drive_zid) == 1 and all(t["namespace"] == "/" for t in tokens)


def test_navlearn_status_shows_the_drive_and_the_sim(stack):
    import json
    import subprocess
    import sys

    argv = [
        sys.executable,
        "-m",
        "services.cli",
        "status",
        "--drives",
        "--json",
        "--connect",
        stack["endpoint"],
        "--run",
        "e2e",
    ]
    # the module's tests may run on different pytest-xdist workers, each with its own stack: give this
    # stack's drive a goal of its own rather than relying on another test having run first
    trial = stack["trial"]
    pose = robot_status(trial.session, trial.sim_key)["pose"]
    trial.publish_goal((13.5, 13.5) if math.dist(pose[:2], (13.5, 13.5)) > 4 else (2.5, 2.5))
    stack["commands"].wait_moving()
    done = subprocess.run(argv, env=stack["env"], capture_output=True, text=True, timeout=20)
    assert done.returncode == 0, done.stderr  # no learner here, but the drive and the sim answer
    robots = json.loads(done.stdout)["robots"]
    assert robots["drive:drive"]["state"] in ("reached", "driving") and robots["drive:drive"]["goal"]
    assert robots["drive:drive"]["shield"] is True  # the default: it acts through its reading shield
    assert robots["sim:sim"]["collided"] is False and len(robots["sim:sim"]["pose"]) == 3


def drive_somewhere(stack) -> None:
    """Give the drive a goal away from the robot and wait until it moves (each test that needs motion
    sets it up itself: under ``pytest -n 2`` a worker may run any test of this module first)."""
    trial = stack["trial"]
    sim_status = robot_status(trial.session, trial.sim_key)
    start_goal = (13.5, 13.5) if math.dist(sim_status["pose"][:2], (13.5, 13.5)) > 4 else (2.5, 2.5)
    trial.publish_goal(start_goal)
    stack["commands"].wait_moving()


def test_zero_velocity_within_half_a_second_of_a_stale_scan(stack):
    trial, commands, sim = stack["trial"], stack["commands"], stack["sim"]
    drive_somewhere(stack)
    time.sleep(0.3)
    os.kill(sim.pid, signal.SIGUSR2)  # the simulated lidar stops publishing
    time.sleep(1.5)
    with commands.lock:
        last_scan = max(commands.scans)
        after = [c for c in commands.cmds if c[0] > last_scan]
    first_zero = next(c for c in after if c[1] == 0.0 and c[2] == 0.0)
    assert first_zero[0] - last_scan < 0.5
    assert all(c[1] == 0.0 and c[2] == 0.0 for c in after if c[0] > first_zero[0])  # and it stays stopped
    drive = robot_status(trial.session, trial.drive_key)
    assert drive["state"] == "stale" and drive["stale"] == ["scan"] and drive["stale_stops"] >= 1
    os.kill(sim.pid, signal.SIGUSR2)  # lidar back: the policy drives on
    commands.wait_moving(timeout=5.0)


def test_sigterm_sends_zero_velocity_first(stack):
    commands, drive = stack["commands"], stack["drive"]
    drive_somewhere(stack)
    sent = time.monotonic()
    drive.send_signal(signal.SIGTERM)
    assert drive.wait(10) == 0
    time.sleep(0.3)
    with commands.lock:
        after = [c for c in commands.cmds if c[0] > sent]
    # a command whose publish was under way when the signal came may still arrive after `sent` (a
    # Python handler runs once the native put returns); from the handler's zero on, only zeros
    zeros = [i for i, c in enumerate(after) if c[1:] == (0.0, 0.0)]
    assert zeros and zeros[0] <= 1, after[:3]
    assert all(c[1:] == (0.0, 0.0) for c in after[zeros[0] :]), after
    assert after[zeros[0]][0] - sent < 0.2
    wait_for_line(stack["drive_lines"], "zero velocity sent", 5)


def test_a_smaller_robot_reaches_its_goal():
    """A TurtleBot3-sized robot (0.105 m) in the same episode shrunk to its size (the sim's --radius),
    driven with --robot-radius 0.105: 0.21 m steps to the shrunk goal, stopping within 0.21 m of it."""
    shrink = 0.105 / 0.25
    with running(("--radius", "0.105", "--scan-range", "3.5"), ("--robot-radius", "0.105")) as parts:
        result = parts["trial"].run_goal(timeout=25, tolerance=0.5 * shrink)
    assert result["outcome"] == "success", result
    assert result["final_distance"] <= 0.5 * shrink and result["action_timeouts"] == 0
    assert result["path_length"] <= 5.7 * shrink * 2  # the episode's 5.7 m A* path, shrunk
