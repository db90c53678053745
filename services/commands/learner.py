"""`navlearn learner`: the NNQL learner service (hosts the Zenoh router unless told to connect)."""

from __future__ import annotations

import argparse

from agents.nnql.config import NNQLConfig
from services.common.env_options import add_env_options, env_from_args
from services.common.options import add_options, config_file
from services.common.transport import add_zenoh_args
from services.learner.config import NNQL_REFUSED, LearnerConfig, learner_network
from worlds.own_env import describe_env

DESCRIPTION = """\
Run the learner: it takes transition batches from actors (navlearn/<run>/transitions/*) and
demonstrations (demos/*) over Zenoh, validates them, inserts them into TorchRL replay buffers,
trains the NNQL Q-network at a bounded update-to-data ratio (--utd-ratio, after --learning-starts
transitions; a Reverb-style rate limiter holds inserts back when the learner falls behind, and
actors wait for its acknowledgements), broadcasts versioned weights on weights/<model> every
--broadcast-every updates (late joiners query the same key), serves status/learner, and
checkpoints model, optimiser, counters and replay every --checkpoint-every seconds and on
SIGTERM/SIGINT, resuming from the newest checkpoint on start.

By default it hosts the Zenoh router on tcp/127.0.0.1:7447 (--listen changes it; use
--listen tcp/0.0.0.0:7447 to let actors on other hosts in). With --connect it joins an
existing router as a client instead. Logs to stdout.

With --env the actors run a Gymnasium env instead of navlearn's world: the learner builds one copy to
size its network from the env's spaces, refuses transitions of any other env (naming both), and
records the env in its checkpoints and saved policies (docs/own-env.md).
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "learner",
        help="run the NNQL learner service",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, LearnerConfig, "NAVLEARN_LEARNER", "learner service")
    add_env_options(parser)
    add_options(parser, NNQLConfig, "NAVLEARN_NNQL", "NNQL hyper-parameters", refuse=NNQL_REFUSED)
    parser.add_argument(
        "--nnql-config",
        metavar="FILE",
        help="JSON object of NNQL hyper-parameters (agents.nnql.config.NNQLConfig fields; `navlearn up` "
        "writes its run's there): flags win over it, it wins over NAVLEARN_NNQL_<FIELD> variables",
    )
    parser.add_argument(
        "--nirl-config",
        metavar="FILE",
        help="with --nirl: JSON object of NIRL hyper-parameters (agents.nirl.config.NIRLConfig fields); "
        "NAVLEARN_NIRL_<FIELD> environment variables set single fields (the file wins)",
    )
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="router")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import sys

    from agents.device import resolve_device
    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args
    from services.learner.run import run_learner

    try:
        config = options_from_args(LearnerConfig, args, "NAVLEARN_LEARNER")
        env = env_from_args(args)
        resolve_device(config.device)  # cuda without a GPU: one sentence, before anything starts
        nnql = options_from_args(
            NNQLConfig, args, "NAVLEARN_NNQL", base=config_file(args.nnql_config, NNQLConfig)
        )
        # its Q-network variant, before it starts; with --env one copy of the env is built, its spaces
        # read once for the checks and the learner
        spaces = None if env.own_world else describe_env(env)
        learner_network(nnql, config.observation, env, spaces)
        nirl = nirl_config(args, nnql.seed) if config.nirl else None
        settings = settings_from_args(args)
        if args.zenoh_mode is None and settings.connect:
            settings.mode = (
                "client"  # --connect (or NAVLEARN_CONNECT): join that router instead of hosting one
            )
    except (OptionError, TransportError, OSError, ValueError) as exc:
        print(f"navlearn learner: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run_learner(config, nnql, settings, stop, nirl=nirl, env=env, spaces=spaces)
    except (TransportError, ValueError) as exc:
        print(f"navlearn learner: {exc}", file=sys.stderr)
        return 2


def nirl_config(args: argparse.Namespace, seed: int):
    """NIRLConfig from NAVLEARN_NIRL_* variables and --nirl-config (JSON, which wins, as flags do);
    seeded like NNQL unless told otherwise."""
    import os

    from agents.nirl.config import NIRLConfig
    from services.common.options import options_from_args

    values = {} if os.environ.get("NAVLEARN_NIRL_SEED") else {"seed": seed}
    values.update(config_file(args.nirl_config, NIRLConfig))
    config = options_from_args(NIRLConfig, None, "NAVLEARN_NIRL", **values)
    if config.refine and config.refine_prior == "hindsight":  # demonstrations arrive without their poses
        raise ValueError(
            "NIRLConfig.refine_prior='hindsight' needs each demonstration's poses, which the wire does "
            "not carry: the distributed learner refines with refine_prior='policy' (hindsight: "
            "`navlearn nirl train`)"
        )
    return config
