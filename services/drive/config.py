"""Settings of ``navlearn drive`` and ``navlearn ros2-sim`` (their flags), apart so the CLI builds fast."""

from __future__ import annotations

from dataclasses import dataclass, field

from worlds.config import RobotConfig

DISTROS = ("humble", "jazzy", "kilted", "rolling")
"""ROS 2 distributions whose rmw_zenoh wire services.drive.wire writes (kept here, free of Zenoh
imports, so that building the CLI parser stays light)"""


def _ros(default: object, env: str | None = None, **more: object):
    return field(default=default, metadata={**({"env": env} if env else {}), **more})


@dataclass
class RosSettings:
    """Where the node sits in the ROS 2 graph (both commands)."""

    domain_id: int = _ros(0, "ROS_DOMAIN_ID")
    """ROS domain id: the first chunk of every key and token (ROS's own ROS_DOMAIN_ID is read)"""
    namespace: str = "/"
    """ROS namespace of the node (topics are given whole, e.g. /robot1/scan)"""
    distro: str = _ros("jazzy", choices=DISTROS)
    """the robot's ROS 2 distribution: humble writes TypeHashNotSupported where later ones write the
    type's RIHS01 hash (subscriptions hear both; publications must match the robot)"""
    scan_topic: str = "/scan"
    """sensor_msgs/msg/LaserScan topic"""
    odom_topic: str = "/odom"
    """nav_msgs/msg/Odometry topic"""
    cmd_vel_topic: str = "/cmd_vel"
    """velocity command topic (geometry_msgs/msg/Twist, or TwistStamped with --twist-stamped)"""
    twist_stamped: bool = False
    """velocity commands as geometry_msgs/msg/TwistStamped (ROS 2 Jazzy's nav2 option) instead of Twist"""


@dataclass
class DriveConfig(RosSettings):
    """``navlearn drive``: a saved policy driving a ROS 2 robot to the goals it is given."""

    policy: str = "pretrained/nnql"
    """saved policy directory (model.safetensors + config.json): its observation is rebuilt from the
    robot's scan and odometry"""
    node_name: str = "navlearn_drive"
    """ROS node name (what `ros2 node list` shows)"""
    goal_topic: str = "/goal_pose"
    """geometry_msgs/msg/PoseStamped goal topic (RViz's 2D Goal Pose), in the odometry frame"""
    id: str = "drive"
    """status key navlearn/<run>/status/drive:<id> and token alive/drive/<id>"""
    max_linear: float = 0.3
    """largest forward speed (m/s)"""
    max_angular: float = 1.0
    """largest yaw rate (rad/s)"""
    linear_accel: float = 0.5
    """largest forward acceleration and deceleration (m/s^2)"""
    angular_accel: float = 2.0
    """largest yaw acceleration (rad/s^2)"""
    settle_gain: float = 3.0
    """proportional gain (1/s) of each action's final approach and of heading hold while driving"""
    stale_after: float = 0.5
    """scan or odometry older than this (s) stops the robot (zero velocity) until both are fresh"""
    rate: float = 20.0
    """control loop rate (Hz): velocity commands and the watchdog's checks"""
    scan_yaw: float = 0.0
    """the lidar's yaw on the robot (rad, counter-clockwise; pi for one mounted backwards)"""
    hit_margin: float = 0.05
    """metres added to every scan return before it feeds the policy's rays (services.drive.scan.
    pad_returns: keeps the lidar's noise from drawing walls in front of walls in the own map); about
    three times the lidar's range noise"""
    cell: float = 1.0
    """cell size (m) of the robot's own map (the policy's training maps have 1 m cells)"""
    margin: float = 6.0
    """the own map's extent: the box around the start and the goal, this much larger on every side (m)"""
    goal_tolerance: float = 0.0
    """goal reached within this distance (m; 0: the policy's world setting, 0.5 m, scaled to the robot
    with --robot-radius)"""
    robot_radius: float = RobotConfig().radius
    """your robot's radius (m), e.g. 0.105 for a TurtleBot3 Burger: scans, odometry and goals are read
    scaled by 0.25 / radius, so the world's 0.25 m robot the policy was trained as stands for yours,
    and each action's 0.5 m step is driven scaled back (services.drive.drive; docs/maps.md)"""
    max_actions: int = 0
    """give up a goal after this many actions, stopping the robot (0: never; the world's limit is 200)"""
    shield: bool = True
    """act through the policy's reading shield: never an action the current scan's readings say hits
    something, half a turn in place when every action would, none that meets a moving object it
    tracks in the scan where the object is going (agents.shield, agents.disc_tracker; --no-shield:
    the network's own choice)"""


@dataclass
class SimConfig(RosSettings):
    """``navlearn ros2-sim``: navlearn's world behind the ROS 2 wire."""

    map: str = "unseen:0"
    """the map and start: unseen:<k> or dynamic:<k> (episode k of `navlearn evaluate`'s set, its map,
    start, start heading and goal), or a map file (MovingAI .map or ASCII .txt, 1 m cells) with --start"""
    eval_seed: int = 0
    """seed of the evaluation set of unseen:<k> (as navlearn evaluate --seed)"""
    start: tuple[float, ...] = ()
    """x y theta of the start (m, m, rad) on a map file (default: the map's centre, heading 0)"""
    node_name: str = "navlearn_sim"
    """ROS node name of the simulated robot"""
    scan_beams: int = 360
    """lidar beams all round (angle_min -pi)"""
    scan_range: float = 6.0
    """lidar range_max (m); no return reads +inf"""
    scan_rate: float = 10.0
    """LaserScan rate (Hz)"""
    odom_rate: float = 50.0
    """Odometry rate (Hz); the physics steps at this rate too"""
    cmd_timeout: float = 0.5
    """a velocity command older than this (s) is dropped: the robot stops (as real bases do)"""
    scan_noise: float = 0.01
    """standard deviation of the Gaussian noise on each beam (m)"""
    id: str = "sim"
    """status key navlearn/<run>/status/sim:<id>: pose, collision, path length"""
    radius: float = RobotConfig().radius
    """robot radius (m): touching a wall is a collision, which stops the robot for good; unseen:<k> is
    scaled with it (radius / 0.25: the episode shrunk to a smaller robot, for drive --robot-radius)"""
