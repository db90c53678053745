"""`navlearn evaluator`: each new policy version measured on held-out maps."""

from __future__ import annotations

import argparse

from services.common.env_service import register_env_service, run_env_service
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
    register_env_service(
        subparsers,
        "evaluator",
        "run the evaluator service (new policy versions on held-out maps)",
        DESCRIPTION,
        EvaluatorConfig,
        "NAVLEARN_EVALUATOR",
        main,
    )


def main(args: argparse.Namespace) -> int:
    from services.evaluator.evaluator import run_evaluator

    return run_env_service(args, "evaluator", EvaluatorConfig, "NAVLEARN_EVALUATOR", run_evaluator)
