"""`navlearn train --local`: NNQL trained in one process (vector env + learner).

Its flags are the fields of LocalTrainConfig (the run), TrainObservation (what the robots observe)
and NNQLConfig (the learner), built by services.common.options as `up`'s and `learner`'s are, so
an option is spelled the same in every command.
"""

from __future__ import annotations

import argparse
import sys

from agents.nnql.config import NNQLConfig
from agents.nnql.train_config import LocalTrainConfig, TrainObservation
from services.common.options import OptionError, add_options, options_from_args
from worlds.config import observation_settings
from worlds.own_env import ENV_TITLE, EnvConfig, describe_env

DESCRIPTION = """\
Train the NNQL policy (neural-network Q-learning, thesis ch. 4) in one process: a vector env of N
robots, a TorchRL replay buffer and the learner, with the Boltzmann exploration schedule. Writes
the policy (model.safetensors + config.json, loadable by `navlearn evaluate --policy DIR`),
curve.png, curve.jsonl and summary.json to --out, then prints the greedy evaluation on 100
held-out generated maps. Distributed training (actors + learner over Zenoh) is `navlearn up`,
which takes the same NNQL flags. The Q-network is --network's (auto: the action-local branch on
navlearn's world, the patch CNN with --patch-size, the MLP with --env). --patch-size 16 --subgoal none
--network patch --patch-goal --patch-embed 64 --patch-window 3 is the best no-planner variant of
bench/perception.py.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "train",
        help="train NNQL in one process (--local)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--local", action="store_true", help="train in this process (required)")
    add_options(parser, LocalTrainConfig, "NAVLEARN_TRAIN", "run: budget, environment, evaluation, outputs")
    add_options(parser, TrainObservation, "NAVLEARN_TRAIN", "what the robots observe")
    add_options(parser, NNQLConfig, "NAVLEARN_NNQL", "NNQL hyper-parameters", skip=("seed",))
    add_options(parser, EnvConfig, "NAVLEARN_ENV", ENV_TITLE)
    parser.set_defaults(func=run)


def configs(args: argparse.Namespace):
    """(LocalTrainConfig, NNQLConfig, NavConfig, EnvConfig) from the parsed flags; OptionError or
    ValueError naming the flag for anything wrong."""
    run = options_from_args(LocalTrainConfig, args, "NAVLEARN_TRAIN")
    nav = options_from_args(TrainObservation, args, "NAVLEARN_TRAIN").nav()
    # SARSA bootstraps on the action taken: double Q-learning does not apply unless asked for
    sarsa = {"double_q": False} if args.opt_sarsa and args.opt_double_q is None else {}
    nnql = options_from_args(NNQLConfig, args, "NAVLEARN_NNQL", seed=run.seed, **sarsa)
    if run.steps < 1 or run.envs < 1:
        raise OptionError("--steps and --envs must be positive")
    if run.moving_discs < 0 or run.eval_dynamic_episodes < 0:
        raise OptionError("--moving-discs and --eval-dynamic-episodes must be >= 0")
    env = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
    image = None
    if not env.own_world:
        if nav.observation.patch_size:
            raise OptionError("--patch-size is for navlearn's world; drop it with --env")
        # a bad id or a continuous action space: refused now, with its sentence
        image = describe_env(env).image
    # the Q-network variant this observation can feed, its settings used: refused now, not in training
    nnql.resolved(observation_settings(nav) if env.own_world else None, image)
    return run, nnql, nav, env


def run(args: argparse.Namespace) -> int:
    from agents.device import resolve_device
    from worlds.tasks import parse_map_spec

    if not args.local:
        print("navlearn train: only --local exists; distributed training is `navlearn up`", file=sys.stderr)
        return 2
    try:
        run_config, nnql, nav, env = configs(args)
        resolve_device(run_config.device)
        for mf in parse_map_spec(run_config.maps).maps:
            print(mf.note)
    except (OptionError, ValueError) as err:
        print(f"navlearn train: {err}", file=sys.stderr)
        return 2

    from agents.nnql.train_local import train_local

    result = train_local(run_config, nnql, nav, env_config=env)
    print(
        f"{result.env_steps} robot-steps, {result.updates} updates in {result.wall_time:.0f} s "
        f"({result.env_steps_per_s:.0f} steps/s, learner {result.updates_per_s:.0f} updates/s)"
    )
    if result.selected_version is not None:
        print(f"saved the weights of version {result.selected_version} (best on the validation set)")
    if result.final_table:
        print(result.final_table)
    print(f"wrote {result.out}")
    return 0
