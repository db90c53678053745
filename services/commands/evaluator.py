"""`navlearn evaluator`: each new policy version measured on held-out maps."""

from __future__ import annotations

import argparse

from services.common.env_options import add_env_options, env_from_args
from services.common.options import add_options
from services.common.transport import add_zenoh_args
from services.evaluator.config import EvaluatorConfig

DESCRIPTION = """\
Run the evaluator: it follows the learner's weights (navlearn/<run>/weights/<model>, asking
for the newest on start), evaluates each new policy version (or one every --every-versions
updates; versions that arrive during an evaluation are skipped) greedily on fixed, seeded
held-out sets (--families: unseen generated maps, the same with moving obstacles, the MovingAI
arena), publishes an EvalReport on eval/<id> (the learner shows it in its status), appends a
line to <out>/evaluations.jsonl and redraws <out>/learning_curve.png (success rate and path
length ratio to A* against policy version and wall time). Logs to stdout; stops cleanly on
SIGTERM or Ctrl-C.

With --env it plays --episodes seeded greedy episodes of that Gymnasium env instead and reports the
mean return with its 95% interval, the episode length and the success rate where the env gives
info["is_success"] (docs/own-env.md).
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluator",
        help="run the evaluator service (new policy versions on held-out maps)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, EvaluatorConfig, "NAVLEARN_EVALUATOR", "evaluator")
    add_env_options(parser)
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args
    from services.evaluator.evaluator import run_evaluator

    try:
        config = options_from_args(EvaluatorConfig, args, "NAVLEARN_EVALUATOR")
        env = env_from_args(args)
        settings = settings_from_args(args)
    except (OptionError, TransportError, OSError, ValueError) as exc:
        print(f"navlearn evaluator: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_evaluator(config, settings, stop, env)
    except (TransportError, ValueError) as exc:
        print(f"navlearn evaluator: {exc}", file=sys.stderr)
        return 2
