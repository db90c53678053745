"""`navlearn actor`: robots stepped with the newest policy, transitions sent to the learner."""

from __future__ import annotations

import argparse

from services.actor.config import ActorConfig
from services.common.env_service import register_env_service, run_env_service

DESCRIPTION = """\
Run an actor: it steps --envs robots (a vectorised navigation env on --maps) with the newest
NNQL policy it has (Boltzmann exploration following the learner's schedule; uniformly random
until the first weights arrive), publishes a TransitionBatch of --batch-steps x --envs
transitions on navlearn/<run>/transitions/<id>, and applies weights as the learner broadcasts
them (it asks for the newest on start and after reconnecting). It keeps at most --ack-window
batches unacknowledged, so a busy learner slows it down; while the learner or router is away
it keeps up to --outbox-size batches and then waits. Zenoh reconnects by itself.

Connect it to the learner (default tcp/127.0.0.1:7447) or to a router: an actor on another
host is `navlearn actor --connect tcp/LEARNER_HOST:7447 --id robot-b --seed 2` (the learner
must listen on an address that host reaches, e.g. --listen tcp/0.0.0.0:7447). Logs to stdout;
stops cleanly on SIGTERM or Ctrl-C.

With --env it steps --envs copies of a Gymnasium env instead of robots (gymnasium.vector, sync or
async; discrete actions, observations flattened); give it the learner's --env and --env-kwargs
(docs/own-env.md).
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    register_env_service(
        subparsers,
        "actor",
        "run an actor (robots + current policy, publishes transitions)",
        DESCRIPTION,
        ActorConfig,
        "NAVLEARN_ACTOR",
        main,
    )


def main(args: argparse.Namespace) -> int:
    from services.actor.actor import run_actor

    return run_env_service(args, "actor", ActorConfig, "NAVLEARN_ACTOR", run_actor)
