"""One goal through ``navlearn drive`` and ``navlearn ros2-sim``, read from their status: the
episode runner of the end-to-end tests and of bench/ros2_drive.py.

:class:`Trial` holds a Zenoh session on the shared router, a ROS node that publishes goals
(PoseStamped, as RViz's 2D Goal Pose does) and the two status keys. ``run_goal`` waits until
the drive sees the simulated robot where the sim says it is, publishes the goal, and polls both
statuses until an outcome: ``success`` (the drive reached the goal and the sim's robot stands
within the goal tolerance, with no collision), ``collision`` (the sim's robot touched a wall),
``timeout`` (the drive gave up after its action limit) or ``stuck`` (neither within the wall-clock
limit).
"""

from __future__ import annotations

import math
import time

from protocols import keys
from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.messages import StatusReport
from services.drive import wire
from services.drive.node import RosNode


def robot_status(session, key: str, timeout: float = 1.0) -> dict | None:
    """The ``robot`` part of the StatusReport answered on ``key``, or None without an answer."""
    for reply in session.get(key, timeout=timeout):
        if reply.ok is None:
            continue
        try:
            message = decode(reply.ok.payload.to_bytes())
        except ProtocolError:
            continue
        if isinstance(message, StatusReport) and message.robot is not None:
            return message.robot
    return None


class Trial:
    """Goals for one drive / sim pair on ``session`` (see the module docstring)."""

    def __init__(self, session, run: str, drive_id: str = "drive", sim_id: str = "sim", domain: int = 0,
                 goal_topic: str = "/goal_pose") -> None:  # fmt: skip
        self.session = session
        self.drive_key, self.sim_key = keys.drive_status(run, drive_id), keys.sim_status(run, sim_id)
        self.node = RosNode(session, "navlearn_goals", domain)
        self.goals = self.node.publisher(goal_topic, wire.POSE_STAMPED)

    def wait_until(self, predicate, timeout: float, poll: float = 0.1) -> tuple[dict | None, dict | None]:
        """Poll (drive status, sim status) until ``predicate(drive, sim)`` holds or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        while True:
            drive, sim = robot_status(self.session, self.drive_key), robot_status(self.session, self.sim_key)
            if drive is not None and sim is not None and predicate(drive, sim):
                return drive, sim
            if time.monotonic() > deadline:
                return drive, sim
            time.sleep(poll)

    def publish_goal(self, goal: tuple[float, float], frame: str = "odom") -> None:
        self.goals.put(wire.pose_stamped(goal[0], goal[1], 0.0, time.time_ns(), frame))

    def run_goal(
        self, goal: tuple[float, float] | None = None, timeout: float = 120.0, tolerance: float = 0.5
    ) -> dict:
        """Drive to ``goal`` (default: the sim's task goal); returns the outcome and the figures."""

        def synced(drive, sim) -> bool:
            pose = drive.get("pose")
            return pose is not None and math.dist(pose[:2], sim["pose"][:2]) < 0.05 and not drive["stale"]

        drive, sim = self.wait_until(synced, timeout=30.0)
        if drive is None or sim is None or not synced(drive, sim):
            raise RuntimeError(f"the drive does not see the simulated robot (drive {drive}, sim {sim})")
        goal = tuple(sim["goal"]) if goal is None else goal
        reached_before = drive["goals_reached"] + drive["goals_given_up"] + drive["goals_refused"]
        start = time.monotonic()
        for _ in range(50):  # the goal subscription may need a moment to match: publish until taken
            self.publish_goal(goal)
            drive, _ = self.wait_until(
                lambda d, s: d["goal"] is not None and math.dist(d["goal"], goal) < 1e-6, 0.3
            )
            if drive is not None and drive["goal"] is not None and math.dist(drive["goal"], goal) < 1e-6:
                break

        def ended(drive, sim) -> bool:
            finished = (
                drive["goals_reached"] + drive["goals_given_up"] + drive["goals_refused"] > reached_before
            )
            return sim["collided"] or finished

        drive, sim = self.wait_until(ended, timeout=timeout)
        if sim["collided"]:
            outcome = "collision"
        elif drive["state"] == "reached" and math.dist(sim["pose"][:2], goal) <= tolerance + 0.05:
            outcome = "success"
        elif drive["state"] == "gave up":
            outcome = "timeout"
        else:
            outcome = "stuck"
        return {
            "outcome": outcome,
            "state": drive["state"],
            "actions": drive["actions"],
            "path_length": sim["path_length"],
            "final_distance": round(math.dist(sim["pose"][:2], goal), 4),
            "wall_s": round(time.monotonic() - start, 2),
            "stale_stops": drive["stale_stops"],
            "action_timeouts": drive["action_timeouts"],
        }

    def close(self) -> None:
        self.node.close()

    def __enter__(self) -> Trial:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()
