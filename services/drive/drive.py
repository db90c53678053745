"""``navlearn drive``: a saved policy drives a ROS 2 robot to the goals it is given.

The node (:class:`services.drive.node.RosNode`) subscribes to the robot's LaserScan and Odometry
and to goals (PoseStamped), and publishes velocity commands. :class:`Driver` is the control
loop, with no Zenoh in it (the publisher is handed in as ``send``), ticking at ``--rate``:

* a new goal starts an episode: the robot's own map is a :class:`worlds.live.Workspace` around
  the robot and the goal (odometry frame), the observation builder (:class:`worlds.live.LiveObserver`,
  the world's own code) starts afresh;
* at rest, on a scan taken after the last action ended, it checks the scan's geometry
  (:func:`services.drive.scan.check_geometry`: one sentence, and the robot stays put, if the
  policy cannot use it), builds the observation from the scan's rays and the odometry pose, asks
  the policy for an action and executes it as closed-loop motion on odometry
  (:class:`services.drive.motion.ActionMotion`, within the speed and acceleration limits);
* the goal is reached when an action ends within the goal tolerance (the world's rule); after
  ``--max-actions`` actions the robot gives up; either way it stops;
* the watchdog: whenever the last scan or odometry is older than ``--stale-after``, the current
  action is dropped and zero velocity is sent at every tick until both are fresh again, when the
  policy decides anew on a fresh scan;
* SIGINT and SIGTERM send zero velocity before anything else (the signal handler itself), and
  once more on the way out; after the handler every command is zero, even one a tick the signal
  interrupted was about to send (:meth:`Driver.stop`).

**A robot of another size** (``--robot-radius R``): the policy's world is the world's robot, a
0.25 m disc (:data:`worlds.mapfiles.WORLD_RADIUS`). The driver reads the robot's scan, odometry and
goals scaled by ``0.25 / R`` into that world, and drives each action's step scaled back, as
``navlearn evaluate --robot-radius`` reads a map file (docs/maps.md): a TurtleBot3 Burger (0.105 m)
drives steps of 0.21 m and sees its 2.5 m as the policy's 6 m. The goal tolerance, the own map's
cell and margin stay the world's (0.5 m, 1 m, 6 m: in the robot's metres 0.21, 0.42 and 2.5 m);
``hit_margin`` and the speed limits are the robot's own metres.

Its status (goal, distance, last action, stale inputs, counters) is answered on
``navlearn/<run>/status/drive:<id>`` (``navlearn status --drives`` shows it).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.evaluation.policies import load_policy
from agents.shield import ScanPolicy
from protocols import keys
from protocols.codec import encode as encode_message
from protocols.messages import StatusReport
from services.common.process import stop_on_signals
from services.common.transport import declare_alive, open_session
from services.drive import wire
from services.drive.motion import ActionMotion, Limits
from services.drive.node import RosNode
from services.drive.scan import ScanRefused, check_geometry, pad_returns, scan_rays
from worlds.live import LiveObserver, Workspace
from worlds.mapfiles import WORLD_RADIUS

log = logging.getLogger("navlearn.drive")


@dataclass
class Inputs:
    """The newest scan, odometry and goal, written by Zenoh callbacks, read by the control loop."""

    scan: Any = None
    scan_at: float | None = None
    pose: tuple[float, float, float] | None = None
    odom_frame: str = ""
    odom_at: float | None = None
    goal: tuple[float, float] | None = None
    goal_frame: str = ""
    goal_seq: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {"scans": 0, "odometry": 0, "goals": 0})
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_scan(self, message, now: float) -> None:
        with self.lock:
            self.scan, self.scan_at = message, now
            self.counts["scans"] += 1

    def on_odometry(self, pose: tuple[float, float, float], frame: str, now: float) -> None:
        with self.lock:
            self.pose, self.odom_frame, self.odom_at = pose, frame, now
            self.counts["odometry"] += 1

    def on_goal(self, goal: tuple[float, float], frame: str) -> None:
        with self.lock:
            self.goal, self.goal_frame = goal, frame
            self.goal_seq += 1
            self.counts["goals"] += 1


class Driver:
    """The control loop of one robot (see the module docstring): ``tick(now)`` at a steady rate,
    ``halt()`` for zero velocity now. ``send(linear, angular)`` publishes a velocity command."""

    def __init__(
        self,
        policy,
        inputs: Inputs,
        send: Callable[[float, float], None],
        limits: Limits,
        *,
        stale_after: float,
        cell: float,
        margin: float,
        goal_tolerance: float,
        max_actions: int,
        scan_topic: str = "/scan",
        scan_yaw: float = 0.0,
        hit_margin: float = 0.05,
        robot_radius: float = WORLD_RADIUS,
    ) -> None:
        if not (math.isfinite(robot_radius) and robot_radius > 0):
            raise ValueError(f"--robot-radius must be a positive number of metres, got {robot_radius}")
        self.policy, self.inputs, self._send, self.limits = policy, inputs, send, limits
        self.act = policy.scan_actor(1) if isinstance(policy, ScanPolicy) else None
        """the policy with its shield's disc tracker, which reads the scans (None: ``policy(obs)``)"""
        self.nav = policy.nav_config()
        self.observer = LiveObserver(self.nav, snap_hits=True)
        self.robot = self.nav.robot
        self.scale = WORLD_RADIUS / robot_radius
        """the world's metres per metre of the robot (module docstring)"""
        self.stale_after, self.cell, self.margin = stale_after, cell, margin
        self.goal_tolerance = goal_tolerance or self.nav.goal_tolerance / self.scale  # the robot's metres
        self.hit_margin = hit_margin
        self.max_actions, self.scan_topic, self.scan_yaw = max_actions, scan_topic, scan_yaw
        self.state, self.detail = "waiting for a goal", ""
        self.goal: tuple[float, float] | None = None
        self.goal_seq = 0
        self.motion: ActionMotion | None = None
        self.last_action: int | None = None
        self.actions = 0
        self.decided_after = -math.inf  # the next decision needs a scan received after this time
        self.last_tick: float | None = None
        self.stale: list[str] = []
        self.command = (0.0, 0.0)
        self.stopping = False
        """set by :meth:`stop`: from then on every command sent is zero"""
        self.counters = {
            "goals_reached": 0,
            "goals_given_up": 0,
            "goals_refused": 0,
            "scans_refused": 0,
            "stale_stops": 0,
            "action_timeouts": 0,
        }
        self._lock = threading.RLock()

    def warm_up(self) -> None:
        """One observation and one policy call on an empty scene (through the disc tracker when the
        policy has one), so that loading the compiled perception and tracker and the first forward
        pass happen before any goal, not in the control loop."""
        observer = LiveObserver(self.nav)
        observer.start(Workspace.around((0.0, 0.0), (3.0, 0.0), self.margin, self.cell), (3.0, 0.0))
        rays = np.full(len(self.nav.sensors.ray_angles), self.nav.sensors.max_range)
        obs = observer.observe(rays, (0.0, 0.0, 0.0))[None, :]
        if self.act is None:
            self.policy(obs)
        else:  # the disc tracker's compiled loops too; the first goal's first action starts afresh
            self.act(obs, rays[None, :], np.array([True]))

    # ------------------------------------------------------------------ commands
    def send(self, linear: float, angular: float) -> None:
        with self._lock:
            if self.stopping:
                linear, angular = 0.0, 0.0
            self.command = (linear, angular)
            self._send(linear, angular)

    def halt(self) -> None:
        """Zero velocity now (the watchdog, the end of a goal, the loop's exit)."""
        self.send(0.0, 0.0)

    def stop(self) -> None:
        """Zero velocity now and for good: the signal handler's first act. The handler runs on the
        main thread between two bytecodes of whatever it interrupted, which may be a :meth:`tick`
        that has computed a moving command and not yet sent it; latching ``stopping`` makes that
        send a zero too, so nothing but zero follows the handler's."""
        self.stopping = True
        self.halt()

    # ------------------------------------------------------------------ the loop
    def tick(self, now: float) -> None:
        with self._lock:
            dt = 0.0 if self.last_tick is None else min(max(now - self.last_tick, 0.0), 0.25)
            self.last_tick = now
            with self.inputs.lock:
                scan, scan_at, pose = self.inputs.scan, self.inputs.scan_at, self.inputs.pose
                odom_at, odom_frame = self.inputs.odom_at, self.inputs.odom_frame
                goal, goal_frame, goal_seq = self.inputs.goal, self.inputs.goal_frame, self.inputs.goal_seq
            self.stale = [
                name
                for name, at in (("scan", scan_at), ("odometry", odom_at))
                if at is None or now - at > self.stale_after
            ]
            if goal_seq != self.goal_seq and pose is not None:
                self.goal_seq = goal_seq
                self._new_goal(goal, goal_frame, odom_frame, pose, now)
            if self.goal is None or self.state not in ("driving", "stale"):
                if self.command != (0.0, 0.0):
                    self.halt()
                return
            if self.stale:
                if self.state != "stale":
                    self.counters["stale_stops"] += 1
                    log.warning("stopping: %s older than %.2f s", " and ".join(self.stale), self.stale_after)
                self.state, self.motion, self.decided_after = "stale", None, now
                self.halt()  # at every tick while stale: the base gets zero even if one is lost
                return
            if self.state == "stale":
                log.info("scan and odometry fresh again: driving on")
                self.state = "driving"
            if self.motion is None and not self._decide(scan, scan_at, pose, now):
                return
            linear, angular, done = self.motion.command(pose, dt)
            self.send(linear, angular)
            if done:
                if self.motion.timed_out:
                    self.counters["action_timeouts"] += 1
                    log.warning(
                        "action %d took longer than %.1f s: stopped it", self.last_action, self.motion.timeout
                    )
                self.motion, self.decided_after = None, now

    def _new_goal(self, goal, goal_frame: str, odom_frame: str, pose, now: float) -> None:
        self.motion, self.last_action, self.actions, self.detail = None, None, 0, ""
        if goal_frame and odom_frame and goal_frame != odom_frame:
            self._finish(
                "goal refused",
                "goals_refused",
                f"the goal is in frame {goal_frame!r} but odometry in {odom_frame!r}, and navlearn drive "
                f"does no TF lookup: publish goals in {odom_frame!r}.",
            )
            return
        start, target = self._world(pose[:2]), self._world(goal)
        try:
            workspace = Workspace.around(start, target, self.margin, self.cell)
        except ValueError as exc:
            self._finish("goal refused", "goals_refused", f"{exc}.")
            return
        self.goal, self.state, self.decided_after = goal, "driving", -math.inf
        self.observer.start(workspace, target)
        log.info("new goal (%.2f, %.2f), %.2f m away", goal[0], goal[1], math.dist(goal, pose[:2]))

    def _finish(self, state: str, counter: str, detail: str = "") -> None:
        self.state, self.detail, self.motion = state, detail, None
        self.counters[counter] += 1
        (log.warning if detail else log.info)("%s%s", state, f": {detail}" if detail else "")
        self.halt()

    def _decide(self, scan, scan_at: float, pose, now: float) -> bool:
        """At rest: stop at the goal or at the action limit, else start the policy's next action.
        Returns whether an action is under way."""
        if self.command != (0.0, 0.0):
            self.halt()
        if math.dist(pose[:2], self.goal) <= self.goal_tolerance:
            self._finish("reached", "goals_reached")
            return False
        if self.max_actions and self.actions >= self.max_actions:
            self._finish("gave up", "goals_given_up", f"{self.actions} actions without reaching the goal")
            return False
        if scan_at <= self.decided_after:
            return False  # wait for a scan taken after the last action ended
        self.decided_after = now
        try:
            check_geometry(scan, self.nav, self.scan_topic, self.scan_yaw)
        except ScanRefused as exc:
            self.counters["scans_refused"] += 1
            if self.detail != str(exc):
                log.error("%s", exc)
            self.detail = str(exc)
            return False
        self.detail = ""
        max_range = self.nav.sensors.max_range
        reach = max_range / self.scale  # the policy's range in the robot's metres
        rays = pad_returns(
            scan_rays(scan, self.nav.sensors.ray_angles, reach, self.scan_yaw), self.hit_margin, reach
        )
        rays = np.where(rays < reach, np.minimum(rays * self.scale, np.nextafter(max_range, 0.0)), max_range)
        at = (*self._world(pose[:2]), pose[2])
        obs = self.observer.observe(rays, at, -1 if self.last_action is None else self.last_action)
        if self.act is None:
            action = int(np.asarray(self.policy(obs[None, :])).reshape(-1)[0])
        else:  # a goal's first action forgets the discs of the last goal
            action = int(self.act(obs[None, :], rays[None, :], np.array([self.last_action is None]))[0])
        turn, step = self.robot.motion(action)  # the turn-around too
        self.motion = ActionMotion(pose, turn, step / self.scale, self.limits)
        self.last_action, self.actions = action, self.actions + 1
        return True

    def _world(self, point) -> tuple[float, float]:
        """A point of the robot's odometry frame in the policy's world (its metres times :attr:`scale`)."""
        return (point[0] * self.scale, point[1] * self.scale)

    # ------------------------------------------------------------------ status
    def status(self, now: float) -> dict:
        with self._lock, self.inputs.lock:
            pose = self.inputs.pose
            ages = {
                name: (None if at is None else round(now - at, 3))
                for name, at in (("scan", self.inputs.scan_at), ("odometry", self.inputs.odom_at))
            }
            return {
                "state": self.state,
                "detail": self.detail,
                "goal": None if self.goal is None else [round(v, 4) for v in self.goal],
                "distance": None
                if self.goal is None or pose is None
                else round(math.dist(pose[:2], self.goal), 4),
                "pose": None if pose is None else [round(v, 4) for v in pose],
                "last_action": self.last_action,
                "actions": self.actions,
                "command": list(self.command),
                "stale": list(self.stale),
                "input_age_s": ages,
                "counts": dict(self.inputs.counts),
                **self.counters,
            }


def run_drive(config, settings, stop: threading.Event) -> int:
    """``navlearn drive``'s process: load the policy, join the robot's router, drive until ``stop``."""
    policy = load_policy(config.policy)
    if config.shield:
        policy.use_shield(policy.nav_config())
    limits = Limits(
        config.max_linear,
        config.max_angular,
        config.linear_accel,
        config.angular_accel,
        gain=config.settle_gain,
    )
    if config.rate <= 0 or config.stale_after <= 0:
        raise ValueError(
            f"--rate and --stale-after must be positive, got {config.rate}, {config.stale_after}"
        )
    session = open_session(settings, stop=stop)
    if session is None:
        return 0
    inputs = Inputs()
    with (
        session,
        RosNode(session, config.node_name, config.domain_id, config.namespace, config.distro) as node,
    ):
        cmd_type = wire.TWIST_STAMPED if config.twist_stamped else wire.TWIST
        cmd = node.publisher(config.cmd_vel_topic, cmd_type, wire.DEFAULT_QOS)

        def send(linear: float, angular: float) -> None:
            if config.twist_stamped:
                cmd.put(wire.twist_stamped(linear, angular, time.time_ns(), "base_link"))
            else:
                cmd.put(wire.twist(linear, angular))

        driver = Driver(
            policy,
            inputs,
            send,
            limits,
            stale_after=config.stale_after,
            cell=config.cell,
            margin=config.margin,
            goal_tolerance=config.goal_tolerance,
            max_actions=config.max_actions,
            scan_topic=config.scan_topic,
            scan_yaw=config.scan_yaw,
            hit_margin=config.hit_margin,
            robot_radius=config.robot_radius,
        )
        driver.warm_up()
        stop_on_signals(first=driver.stop, event=stop)  # from here on a signal sends zero velocity first

        def on_odometry(message, _info) -> None:
            p = message.pose.pose
            pose = (p.position.x, p.position.y, wire.yaw_of(p.orientation))
            inputs.on_odometry(pose, message.header.frame_id, time.monotonic())

        def on_goal(message, _info) -> None:
            p = message.pose.position
            inputs.on_goal((p.x, p.y), message.header.frame_id)

        node.subscribe(config.scan_topic, wire.LASER_SCAN, lambda m, _: inputs.on_scan(m, time.monotonic()))
        node.subscribe(config.odom_topic, wire.ODOMETRY, on_odometry)
        node.subscribe(config.goal_topic, wire.POSE_STAMPED, on_goal, wire.DEFAULT_QOS)
        status_key = keys.drive_status(settings.run, config.id)

        def on_status(query) -> None:
            view = driver.status(time.monotonic())
            view["rejected"] = dict(node.rejected)
            view["policy"] = config.policy
            view["shield"] = policy.shield is not None
            report = StatusReport(sender=f"{keys.DRIVE_STATUS_PREFIX}{config.id}", robot=view)
            query.reply(status_key, encode_message(report))

        queryable = session.declare_queryable(status_key, on_status)
        token = declare_alive(session, settings.run, "drive", config.id)
        log.info(
            "driving %s%s as ROS node %s (domain %d): %s + %s -> %s (%s), goals on %s",
            config.policy,
            " through its reading shield" if policy.shield is not None else " (no shield)",
            config.node_name,
            config.domain_id,
            config.scan_topic,
            config.odom_topic,
            config.cmd_vel_topic,
            cmd_type,
            config.goal_topic,
        )
        period = 1.0 / config.rate
        next_tick = time.monotonic()
        try:
            while not stop.is_set():
                driver.tick(time.monotonic())
                next_tick += period
                stop.wait(max(0.0, next_tick - time.monotonic()))
        finally:
            driver.halt()
            token.undeclare()
            queryable.undeclare()
    log.info("stopped (zero velocity sent)")
    return 0
