"""``navlearn ros2-sim``: navlearn's world behind the ROS 2 wire, for tests and for trying
``navlearn drive`` without a robot.

One robot on one map, in continuous time: it publishes ``/scan`` (sensor_msgs/LaserScan, beams
all round cast exactly on the map by :func:`worlds.sensors.cast_rays`, +inf for no return) and
``/odom`` (nav_msgs/Odometry, the pose in the map's frame ``odom``) in CDR with rmw_zenoh's keys,
attachment and tokens, and takes ``/cmd_vel`` (Twist or TwistStamped) as unicycle kinematics
integrated at the odometry rate. A command older than ``--cmd-timeout`` is dropped (the robot
stops, as real bases do). When the robot's disc, swept along a physics step, touches a wall or the
map's border (:func:`worlds.robot.collides`, the world's collision test), it stops there for good
and says so in its status (``navlearn/<run>/status/sim:<id>``: pose, collision, path length, the
task's goal). ``kill -USR2`` switches the lidar off and on (a watchdog drill).

``--map unseen:<k>`` drives episode k of ``navlearn evaluate``'s unseen set: the same map, start
cell, start heading (drawn from the episode's seed by the same code) and goal; that is how the
paired figures of bench/ros2_drive.py are made. With ``--radius R`` other than the world's 0.25 m the
episode is shrunk (or grown) to the robot, map, start and goal scaled by ``R / 0.25``: the scene a
robot of that size meets where the world's robot meets episode k, for ``navlearn drive
--robot-radius R``. Moving discs are not simulated.
"""

from __future__ import annotations

import logging
import math
import re
import signal
import threading
import time
from dataclasses import dataclass

import numpy as np

from agents.evaluation.runner import fixed_sampler, make_eval_set
from protocols import keys
from protocols.codec import encode as encode_message
from protocols.messages import StatusReport
from services.common.transport import ZenohSettings, declare_alive, open_session
from services.drive import wire
from services.drive.config import SimConfig
from services.drive.node import RosNode
from worlds.config import NavConfig
from worlds.mapfiles import WORLD_RADIUS
from worlds.maps import GridMap, Task, load_map
from worlds.robot import collides
from worlds.sensors import cast_rays
from worlds.vector_env import NavigationVectorEnv

log = logging.getLogger("navlearn.ros2_sim")


@dataclass(frozen=True)
class Scene:
    """The map, the start pose and the task's goal (None for a map file)."""

    grid: GridMap
    start: tuple[float, float, float]
    goal: tuple[float, float] | None
    name: str


def scene(config: SimConfig) -> Scene:
    """The scene ``config.map`` names (see :class:`services.drive.config.SimConfig`)."""
    match = re.fullmatch(r"unseen:(\d+)", config.map)
    if match:
        return eval_scene(int(match.group(1)), config.eval_seed, config.radius / WORLD_RADIUS)
    grid = load_map(config.map)
    if config.start and len(config.start) != 3:
        raise ValueError(f"--start takes x y theta, got {config.start}")
    centre = (grid.width * grid.cell_size / 2, grid.height * grid.cell_size / 2, 0.0)
    start = tuple(config.start) if config.start else centre
    cell = (int(start[1] // grid.cell_size), int(start[0] // grid.cell_size))
    if not grid.in_bounds(cell) or grid.blocked[cell]:
        where = "outside" if not grid.in_bounds(cell) else "inside a wall of"
        raise ValueError(
            f"the start ({start[0]:g}, {start[1]:g}) is {where} {config.map}: give --start x y theta"
        )
    return Scene(grid, start, None, config.map)


def eval_scene(k: int, seed: int, scale: float = 1.0) -> Scene:
    """Episode ``k`` of evaluation set ``unseen`` of seed ``seed``: its map, its start pose as
    ``navlearn evaluate`` starts it (heading from the episode's seed) and its goal cell's centre,
    every length times ``scale`` (a robot of ``scale`` times the world's radius)."""
    es = make_eval_set("unseen", k + 1, seed=seed)
    task: Task = es.tasks[k]
    env = NavigationVectorEnv(1, NavConfig(), maps=fixed_sampler([task], f"ros2-sim:{seed}:{k}"))
    env.reset(seed=[es.seeds[k]], options={"tasks": [task]})
    x, y, theta = (float(v) for v in env.poses()[0])
    cell = task.grid.cell_size * scale
    grid = task.grid if scale == 1.0 else GridMap(task.grid.blocked, cell, task.grid.name)
    goal = ((task.goal[1] + 0.5) * cell, (task.goal[0] + 0.5) * cell)
    shrunk = "" if scale == 1.0 else f", scaled x{scale:.4g}"
    return Scene(grid, (x * scale, y * scale, theta), goal, f"unseen:{k} (seed {seed}{shrunk})")


class SimRobot:
    """The robot's state and physics (no Zenoh here): ``command`` sets the velocity, ``advance``
    integrates it, ``scan`` casts the lidar."""

    def __init__(self, scene: Scene, config: SimConfig, seed: int = 0) -> None:
        self.scene, self.config = scene, config
        self.x, self.y, self.theta = scene.start
        self.linear = self.angular = 0.0
        self.cmd_at = -math.inf
        self.collided = False
        self.path_length = 0.0
        self.lock = threading.Lock()
        self.rng = np.random.default_rng(seed)
        self.angles = -math.pi + np.arange(config.scan_beams) * (2 * math.pi / config.scan_beams)

    def command(self, linear: float, angular: float, now: float) -> None:
        with self.lock:
            finite = math.isfinite(linear) and math.isfinite(angular)
            self.linear, self.angular = (float(linear), float(angular)) if finite else (0.0, 0.0)
            self.cmd_at = now

    def advance(self, dt: float, now: float) -> None:
        """One physics step of ``dt`` seconds (unicycle; a collision stops the robot for good)."""
        with self.lock:
            if self.collided or now - self.cmd_at > self.config.cmd_timeout:
                self.linear = self.angular = 0.0
                return
            theta = self.theta + self.angular * dt
            x = self.x + self.linear * dt * math.cos(theta)
            y = self.y + self.linear * dt * math.sin(theta)
            if bool(collides(self.scene.grid, self.x, self.y, x, y, self.config.radius)):
                self.collided, self.linear, self.angular = True, 0.0, 0.0
                log.info("collision at (%.2f, %.2f): the robot stops", x, y)
                return
            self.path_length += math.hypot(x - self.x, y - self.y)
            self.x, self.y, self.theta = x, y, (theta + math.pi) % (2 * math.pi) - math.pi

    def pose(self) -> tuple[float, float, float]:
        with self.lock:
            return self.x, self.y, self.theta

    def scan(self) -> np.ndarray:
        """Ranges (float32) of the beams at ``self.angles`` from the heading: +inf for no return."""
        x, y, theta = self.pose()
        ranges = cast_rays(self.scene.grid, x, y, theta, self.angles, self.config.scan_range)[0]
        hit = ranges < self.config.scan_range  # the noise is on returns: nothing in range stays +inf
        if self.config.scan_noise > 0:
            ranges = ranges + self.rng.normal(0.0, self.config.scan_noise, ranges.shape)
        return np.where(hit, np.clip(ranges, 0.0, self.config.scan_range), np.inf).astype(np.float32)

    def status(self) -> dict:
        with self.lock:
            return {
                "map": self.scene.name,
                "pose": [round(self.x, 4), round(self.y, 4), round(self.theta, 4)],
                "collided": self.collided,
                "path_length": round(self.path_length, 4),
                "cmd": [self.linear, self.angular],
                "goal": None if self.scene.goal is None else list(self.scene.goal),
            }


def run_sim(config: SimConfig, settings: ZenohSettings, stop: threading.Event) -> int:
    """Publish /scan and /odom, take /cmd_vel, answer status, until ``stop`` is set."""
    robot = SimRobot(scene(config), config)
    lidar_on = threading.Event()
    lidar_on.set()

    def toggle_lidar(*_args) -> None:
        (lidar_on.clear if lidar_on.is_set() else lidar_on.set)()
        log.info("lidar %s (SIGUSR2)", "on" if lidar_on.is_set() else "off")

    signal.signal(signal.SIGUSR2, toggle_lidar)
    session = open_session(settings, stop=stop)
    if session is None:
        return 0
    with (
        session,
        RosNode(session, config.node_name, config.domain_id, config.namespace, config.distro) as node,
    ):
        scans = node.publisher(config.scan_topic, wire.LASER_SCAN, wire.SENSOR_QOS)
        odoms = node.publisher(config.odom_topic, wire.ODOMETRY)
        cmd_type = wire.TWIST_STAMPED if config.twist_stamped else wire.TWIST

        def on_cmd(message, _info) -> None:
            twist = message.twist if config.twist_stamped else message
            robot.command(twist.linear.x, twist.angular.z, time.monotonic())

        node.subscribe(config.cmd_vel_topic, cmd_type, on_cmd, wire.DEFAULT_QOS)
        status_key = keys.sim_status(settings.run, config.id)

        def on_status(query) -> None:
            report = StatusReport(sender=f"{keys.SIM_STATUS_PREFIX}{config.id}", robot=robot.status())
            query.reply(status_key, encode_message(report))

        queryable = session.declare_queryable(status_key, on_status)
        token = declare_alive(session, settings.run, "sim", config.id)
        log.info(
            "simulated robot on %s at %s: /scan %s, /odom %s, %s %s (domain %d)",
            robot.scene.name,
            robot.pose(),
            config.scan_topic,
            config.odom_topic,
            config.cmd_vel_topic,
            cmd_type,
            config.domain_id,
        )
        dt, scan_every = 1.0 / config.odom_rate, 1.0 / config.scan_rate
        next_tick = next_scan = time.monotonic()
        inc = 2 * math.pi / config.scan_beams
        try:
            while not stop.is_set():
                now = time.monotonic()
                robot.advance(dt, now)
                x, y, theta = robot.pose()
                stamp = time.time_ns()
                odoms.put(
                    wire.odometry(x, y, theta, robot.linear, robot.angular, stamp, "odom", "base_footprint")
                )
                if now >= next_scan:
                    next_scan += scan_every
                    if lidar_on.is_set():
                        scans.put(
                            wire.laser_scan(
                                robot.scan(),
                                -math.pi,
                                inc,
                                0.05,
                                config.scan_range,
                                stamp,
                                "base_scan",
                                scan_every,
                            )
                        )
                next_tick += dt
                stop.wait(max(0.0, next_tick - time.monotonic()))
        finally:
            token.undeclare()
            queryable.undeclare()
    log.info("stopped")
    return 0
