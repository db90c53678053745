"""`navlearn train --local`: NNQL trained in one process (vector env + learner)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

from agents.device import DEVICES, resolve_device
from agents.nnql.config import Q_NETWORKS, NNQLConfig
from services.common.options import add_options, options_from_args
from worlds.config import LEARNING_NAV, TRAINING_DISCS
from worlds.own_env import ENV_TITLE, EnvConfig, env_spaces


def register(subparsers) -> None:
    defaults = NNQLConfig()
    parser = subparsers.add_parser(
        "train",
        help="train NNQL in one process (--local)",
        description=(
            "Train the NNQL policy (neural-network Q-learning, thesis ch. 4) in one process: a vector "
            "env of N robots, a TorchRL replay buffer and the learner, with the Boltzmann exploration "
            "schedule. Writes the policy (model.safetensors + config.json, loadable by "
            "`navlearn evaluate --policy DIR`), curve.png, curve.jsonl and summary.json to --out, then "
            "prints the greedy evaluation on 100 held-out generated maps. Distributed training "
            "(actors + learner over Zenoh) is `navlearn up`."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--local", action="store_true", help="train in this process (required)")
    parser.add_argument("--steps", type=int, default=200_000, help="robot-steps to collect (all robots)")
    parser.add_argument("--envs", type=int, default=16, help="robots stepped together")
    parser.add_argument("--maps", default="mixed:16", help="training map spec: mixed:16, rooms:20, x.map ...")
    parser.add_argument("--out", default="runs/nnql-local", help="output directory")
    parser.add_argument("--seed", type=int, default=0, help="seed of env, network and exploration")
    parser.add_argument(
        "--eval-every", type=int, default=25_000, help="robot-steps between validation evaluations (0: none)"
    )
    parser.add_argument(
        "--eval-episodes",
        type=int,
        default=100,
        help="episodes per validation evaluation (seed 1)",
    )
    parser.add_argument(
        "--eval-dynamic-episodes",
        type=int,
        default=0,
        help="episodes with 4 moving discs added to each validation evaluation; the kept weights are then "
        "chosen on the success pooled over both",
    )
    parser.add_argument(
        "--keep-last",
        action="store_true",
        help="save the last weights instead of those that scored best on the validation evaluations",
    )
    parser.add_argument(
        "--final-eval-episodes",
        type=int,
        default=100,
        help="episodes of the final test (seed 0; 0: skip)",
    )
    parser.add_argument(
        "--hidden",
        default=",".join(str(h) for h in defaults.hidden_sizes),
        help="hidden layer widths, comma-separated",
    )
    parser.add_argument("--lr", type=float, default=defaults.lr, help="Adam learning rate")
    parser.add_argument("--batch-size", type=int, default=defaults.batch_size, help="transitions per update")
    parser.add_argument(
        "--utd-ratio", type=float, default=defaults.utd_ratio, help="gradient updates per transition"
    )
    parser.add_argument("--prioritized", action="store_true", help="prioritized replay (PrioritizedSampler)")
    parser.add_argument(
        "--n-step", type=int, default=defaults.n_step, help="n-step returns (1: one-step Q-learning)"
    )
    parser.add_argument(
        "--dueling",
        action=argparse.BooleanOptionalAction,
        default=defaults.dueling,
        help="dueling head of the MLP Q-network: Q = V + A - mean(A), saved folded",
    )
    parser.add_argument(
        "--moving-discs",
        type=int,
        default=TRAINING_DISCS,
        help="train with 0..N moving discs per episode, uniform; the dynamic test set has 4, 0 trains on "
        "static maps only",
    )
    parser.add_argument("--sarsa", action="store_true", help="SARSA: bootstrap on the next action taken")
    parser.add_argument(
        "--recurrent",
        action="store_true",
        help="recurrent Q, R2D2-style: LSTM, sequence replay, burn-in, stored state (agents/nnql)",
    )
    for name in ("lstm_size", "seq_len", "burn_in", "sequences"):
        parser.add_argument(
            "--" + name.replace("_", "-"),
            type=int,
            default=getattr(defaults, name),
            help=f"{name} (--recurrent)",
        )
    parser.add_argument(
        "--epsilon-greedy", action="store_true", help="epsilon-greedy exploration instead of Boltzmann"
    )
    parser.add_argument(
        "--device",
        choices=DEVICES,
        default="cpu",
        help="where the learner's networks, loss and sampled batches live (auto: a GPU if torch sees one)",
    )
    parser.add_argument(
        "--patch",
        type=int,
        default=0,
        help="add an egocentric PATCH x PATCH patch of the robot's own map to the observation "
        "(occupancy + visits; read by a small CNN beside the MLP); 0: none",
    )
    parser.add_argument(
        "--cnn-goal",
        action="store_true",
        help="with --patch: draw the goal into the patch CNN's input too (one more channel; no planner)",
    )
    parser.add_argument(
        "--cnn-embed",
        type=int,
        default=defaults.cnn_embed,
        help="with --patch: map the CNN's features to this many before the MLP head (0: as they are)",
    )
    parser.add_argument(
        "--action-local",
        type=int,
        default=defaults.action_local,
        help="K > 0 adds a branch shared by the actions that reads, for each action, the 2K+1 readings "
        "around its heading and the goal seen from it (0: off; with or without --patch); --patch 16 "
        "--no-subgoal --cnn-goal --cnn-embed 64 --action-local 3 is bench/perception.py's best no-planner "
        "variant",
    )
    parser.add_argument(
        "--no-subgoal",
        action="store_true",
        help="drop the subgoal planned on the robot's own map (learning alone; e.g. with --patch 16)",
    )
    parser.add_argument(
        "--frame-stack", type=int, default=1, help="observe the last K frames, newest first (1: one frame)"
    )
    parser.add_argument("--previous-action", action="store_true", help="observe the previous action, one-hot")
    parser.add_argument(
        "--range-rate",
        action="store_true",
        help="observe each reading's change since the previous step (a motion cue for moving discs)",
    )
    parser.add_argument(
        "--plan-length",
        action="store_true",
        help="observe the length of the subgoal's path to the goal on the robot's own map (how far the goal "
        "is round the walls seen so far); needs the subgoal",
    )
    parser.add_argument(
        "--q-network",
        choices=Q_NETWORKS,
        default=defaults.q_network,
        help="auto: CNN over the patch beside the MLP when there is one; mlp: one MLP over every input",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_options(parser, EnvConfig, "NAVLEARN_ENV", ENV_TITLE)
    parser.set_defaults(func=run)


def observation_of(args: argparse.Namespace):
    """worlds.config.LEARNING_NAV with the observation flags (--patch, --no-subgoal, --frame-stack,
    --previous-action, --range-rate, --plan-length) applied."""
    subgoal = "none" if args.no_subgoal else LEARNING_NAV.observation.subgoal
    observation = replace(
        LEARNING_NAV.observation,
        patch_size=args.patch,
        subgoal=subgoal,
        frame_stack=args.frame_stack,
        previous_action=args.previous_action or LEARNING_NAV.observation.previous_action,
        range_rate=args.range_rate or LEARNING_NAV.observation.range_rate,
        plan_length=args.plan_length or LEARNING_NAV.observation.plan_length,
    )
    return replace(LEARNING_NAV, observation=observation)


def run(args: argparse.Namespace) -> int:
    if not args.local:
        print("navlearn train: only --local exists; distributed training is `navlearn up`", file=sys.stderr)
        return 2
    try:
        hidden = tuple(int(h) for h in args.hidden.split(",") if h.strip())
        nnql = NNQLConfig(
            hidden_sizes=hidden,
            lr=args.lr,
            batch_size=args.batch_size,
            utd_ratio=args.utd_ratio,
            prioritized=args.prioritized,
            n_step=args.n_step,
            dueling=args.dueling,
            sarsa=args.sarsa,
            double_q=not args.sarsa,
            exploration="epsilon" if args.epsilon_greedy else "boltzmann",
            seed=args.seed,
            q_network=args.q_network,
            cnn_goal=args.cnn_goal,
            cnn_embed=args.cnn_embed,
            action_local=args.action_local,
            recurrent=args.recurrent,
            lstm_size=args.lstm_size,
            seq_len=args.seq_len,
            burn_in=args.burn_in,
            sequences=args.sequences,
        )
        nav = observation_of(args)
        if (args.cnn_goal or args.cnn_embed) and not args.patch:
            raise ValueError("--cnn-goal and --cnn-embed shape the patch network: add --patch (e.g. 16)")
        if args.steps < 1 or args.envs < 1:
            raise ValueError("--steps and --envs must be positive")
        if args.moving_discs < 0 or args.eval_dynamic_episodes < 0:
            raise ValueError("--moving-discs and --eval-dynamic-episodes must be >= 0")
        resolve_device(args.device)
        from worlds.tasks import parse_map_spec

        parse_map_spec(args.maps)
        env = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
        if not env.own_world:
            if nnql.recurrent or args.patch or nnql.action_local:
                raise ValueError(
                    "--recurrent, --patch and --action-local are for navlearn's world; drop them with --env"
                )
            env_spaces(env)  # a bad id or a continuous action space: refused now, with its sentence
    except ValueError as err:
        print(f"navlearn train: {err}", file=sys.stderr)
        return 2

    from agents.nnql.train_local import LocalTrainConfig, train_local

    run_config = LocalTrainConfig(
        steps=args.steps,
        envs=args.envs,
        maps=args.maps,
        moving_discs=args.moving_discs,
        seed=args.seed,
        out=args.out,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        eval_dynamic_episodes=args.eval_dynamic_episodes,
        keep_best=not args.keep_last,
        final_eval_episodes=args.final_eval_episodes,
        progress=not args.no_progress,
        device=args.device,
    )
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
