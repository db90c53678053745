"""`navlearn demonstrator`: publish demonstrations (A* expert, human at the keyboard, or a dataset)."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
Run a demonstrator: it publishes whole demonstrated episodes as DemoBatch messages on
navlearn/<run>/demos/<source>, for the learner's demonstration buffer (NIRL, imitation).

  --source astar   the modified-A* expert drives the robot on --maps, --rate episodes per
                   second, forever or --episodes times; --noise P replaces each action with a
                   random wall-free one with probability P (sub-optimal demonstrations)
  --source human   you drive the robot in this terminal: Up/w straight on, Left/a and Right/d
                   half turns, q and e hard turns, x quits; the map, robot, beams and goal are
                   drawn here; every episode that reaches the goal is published
  --source file    publishes the demonstration dataset --file (navlearn demos generate) once

Each batch waits until a learner is alive (its liveliness token), so demonstrations made before
the learner starts are delayed, not lost (--no-wait-learner sends at once). Declares
alive/demonstrator/<id>. Logs to stdout; stops cleanly on SIGTERM or Ctrl-C.

Examples:
  navlearn demonstrator --source astar --rate 2 --noise 0.3
  navlearn demonstrator --source human --maps rooms:12
  navlearn demonstrator --source file --file demos/expert-v0
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from services.common.options import add_options
    from services.common.transport import add_zenoh_args
    from services.demonstrator.config import DemonstratorConfig

    parser = subparsers.add_parser(
        "demonstrator",
        help="publish demonstrations: A* expert, human teleoperation or a dataset",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, DemonstratorConfig, "NAVLEARN_DEMONSTRATOR", "demonstrator")
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from agents.demos import DemoFormatError
    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args
    from services.demonstrator.demonstrator import DemonstratorConfig, run_demonstrator
    from worlds.tasks import parse_map_spec

    try:
        config = options_from_args(DemonstratorConfig, args, "NAVLEARN_DEMONSTRATOR")
        settings = settings_from_args(args)
        if config.source != "file":
            parse_map_spec(config.maps)
        if config.source == "human" and not sys.stdin.isatty():
            raise OptionError("--source human needs an interactive terminal")
    except (OptionError, TransportError, ValueError) as exc:
        print(f"navlearn demonstrator: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_demonstrator(config, settings, stop)
    except (TransportError, DemoFormatError, ValueError) as exc:
        print(f"navlearn demonstrator: {exc}", file=sys.stderr)
        return 2
