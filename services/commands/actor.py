"""`navlearn actor`: robots stepped with the newest policy, transitions sent to the learner."""

from __future__ import annotations

import argparse

from services.actor.config import ActorConfig
from services.common.env_options import add_env_options, env_from_args
from services.common.options import add_options
from services.common.transport import add_zenoh_args

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
    parser = subparsers.add_parser(
        "actor",
        help="run an actor (robots + current policy, publishes transitions)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, ActorConfig, "NAVLEARN_ACTOR", "actor")
    add_env_options(parser)
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from services.actor.actor import run_actor
    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args

    try:
        config = options_from_args(ActorConfig, args, "NAVLEARN_ACTOR")
        env = env_from_args(args)
        settings = settings_from_args(args)
    except (OptionError, TransportError, OSError, ValueError) as exc:
        print(f"navlearn actor: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_actor(config, settings, stop, env)
    except (TransportError, ValueError) as exc:
        print(f"navlearn actor: {exc}", file=sys.stderr)
        return 2
