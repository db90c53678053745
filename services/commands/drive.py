"""`navlearn drive`: a saved policy driving a ROS 2 robot over Zenoh, as rmw_zenoh speaks it."""

from __future__ import annotations

import argparse

from services.common.options import add_options
from services.common.transport import add_zenoh_args
from services.drive.config import DriveConfig

DESCRIPTION = """\
Drive a ROS 2 robot with a saved policy (navlearn train / imitate / nirl output, or pretrained/nnql).
The process is a ROS 2 node on the robot's Zenoh network, with no ROS installation here: it joins
the robot's router (rmw_zenohd; give --connect tcp/ROBOT:7447) as a Zenoh client and speaks
rmw_zenoh's wire (key expressions, liveliness tokens, attachments, CDR), so `ros2 node list` and
`ros2 topic list` on the robot show it.

It subscribes to sensor_msgs/msg/LaserScan (--scan-topic), nav_msgs/msg/Odometry (--odom-topic)
and geometry_msgs/msg/PoseStamped goals in the odometry frame (--goal-topic, RViz's 2D Goal
Pose), and publishes geometry_msgs/msg/Twist (or TwistStamped) on --cmd-vel-topic. For each goal
it rebuilds the observation the policy was trained with from the scan (any beam count and angles,
REP 117 inf/nan readings, resampled to the policy's rays) and the odometry (the robot's own map and
subgoal, by the world's own code), and executes each discrete action as closed-loop motion on
odometry within --max-linear / --max-angular and the acceleration limits.

Safety: zero velocity whenever the scan or odometry is older than --stale-after; SIGINT/SIGTERM send
zero velocity first; a scan the policy cannot use (too few beams, not all round) is refused in one
sentence and the robot stays put. Status (state, goal, distance, last action, stale inputs) is
answered on navlearn/<run>/status/drive:<id> (navlearn status --drives). See docs/ros2.md.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "drive",
        help="drive a ROS 2 robot with a saved policy (over Zenoh, as rmw_zenoh speaks it)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, DriveConfig, "NAVLEARN_DRIVE", "drive")
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from agents.evaluation.policies import PolicyFormatError
    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args
    from services.drive.drive import run_drive
    from services.drive.wire import WireError

    try:
        config = options_from_args(DriveConfig, args, "NAVLEARN_DRIVE")
        settings = settings_from_args(args)
    except (OptionError, TransportError) as exc:
        print(f"navlearn drive: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_drive(config, settings, stop)
    except (TransportError, PolicyFormatError, WireError, ValueError) as exc:
        print(f"navlearn drive: {exc}", file=sys.stderr)
        return 2
