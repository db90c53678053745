"""`navlearn ros2-sim`: navlearn's world behind the ROS 2 wire (a simulated robot for navlearn drive)."""

from __future__ import annotations

import argparse

from services.common.options import add_options
from services.common.transport import add_zenoh_args
from services.drive.config import SimConfig

DESCRIPTION = """\
A simulated ROS 2 robot: navlearn's world (one map, one unicycle robot with a 360-degree lidar)
behind rmw_zenoh's wire. It publishes sensor_msgs/msg/LaserScan on --scan-topic and
nav_msgs/msg/Odometry on --odom-topic (CDR, rmw_zenoh keys, attachments and liveliness tokens)
and takes geometry_msgs/msg/Twist (or TwistStamped) on --cmd-vel-topic, integrated as unicycle
kinematics; touching a wall stops it for good. Use it to try `navlearn drive` without a robot:

    navlearn router --listen tcp/127.0.0.1:7447 &
    navlearn ros2-sim --map unseen:3 &
    navlearn drive --policy pretrained/nnql &
    (publish the goal the sim's status names as a PoseStamped on /goal_pose, e.g. bench/ros2_drive.py)

--map unseen:<k> is episode k of `navlearn evaluate`'s unseen set (same map, start, heading, goal);
a map file (MovingAI .map or ASCII .txt) takes --start x y theta. Status (pose, collision, path
length, the task's goal) on navlearn/<run>/status/sim:<id>. `kill -USR2 <pid>` switches the lidar off
and on (a watchdog drill). See docs/ros2.md.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "ros2-sim",
        help="a simulated ROS 2 robot (navlearn's world behind rmw_zenoh's wire) for navlearn drive",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, SimConfig, "NAVLEARN_SIM", "simulated robot")
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args
    from services.drive.sim import run_sim
    from services.drive.wire import WireError

    try:
        config = options_from_args(SimConfig, args, "NAVLEARN_SIM")
        settings = settings_from_args(args)
    except (OptionError, TransportError) as exc:
        print(f"navlearn ros2-sim: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_sim(config, settings, stop)
    except (TransportError, WireError, ValueError, OSError) as exc:
        print(f"navlearn ros2-sim: {exc}", file=sys.stderr)
        return 2
