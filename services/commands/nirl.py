"""`navlearn nirl`: train NIRL in one process from a demonstration dataset; plot its weight changes."""

from __future__ import annotations

import argparse

from worlds.config import OBSERVATIONS

TRAIN_DESCRIPTION = """\
Neural inverse reinforcement learning (thesis ch. 5) in one process. Loads the demonstrations
(a Minari dataset from `navlearn demos generate` or the file demonstrator), warm-starts the soft
Q-function on them, then runs --iterations rounds of neural policy iteration: collect experience
with the Boltzmann policy on --maps, MAP-refine the demonstrations, learn the reward by inverse
soft-Q learning (IQ-Learn; --core max_margin or sqil for the alternatives) for --fix-reward-after
rounds, then fix it - a unit step cost shaped by a progress potential regressed on the
demonstrations' steps to go - and soft-Q-learn on it for the remaining rounds (demonstrations and
own experience in every batch). The environment's reward is never used. Writes to --out: the
policy (model.safetensors + config.json, loadable by `navlearn evaluate --policy DIR`),
reward.safetensors and potential.safetensors, the weights of both networks at every iteration
(weights_history.safetensors, plotted in weights.png), curve.jsonl and summary.json; prints the
greedy evaluation on 100 held-out generated maps. The defaults are NIRL's best setting (docs/notebook.md,
issue 15 part 15): 100 rounds of 2,048 robot-steps (204,800) with 0..6 moving discs, 512 Q updates per
round, the reward fixed after round 1, temperature 0.05 to 0.01, NNQL's action-local branch (3) and
discount (0.98), in the observation learning_plan (the default of --observation here and of
`navlearn demos generate`, whose sets record it): 97.1% unseen static / 89.5% with 4 moving discs
from 20 clean demonstrations on the test seed, the network alone, 3 seeds (RESULTS.md, NIRL). The policy is
the Q-network's weights averaged over the last quarter of the rounds (--average-last 0.25; 0: the
last round's); --keep-best keeps the round that scored best on the --eval-every validations instead
(off by default: with 100 static episodes it chose worse rounds than the last).
With --policy-steps N the rounds stop once the reward is fixed (--fix-reward-after) and NNQL's own
trainer runs N robot-steps on the fixed learned reward; its policy, NIRL's final one, is written to
OUT/policy_iteration (`navlearn evaluate --policy OUT/policy_iteration`); --policy-warm-start K
runs K more of NIRL's rounds on the fixed reward first and starts NNQL's network from that policy.
The progress potential is fitted on the goal and subgoal features only (--potential-inputs goal,
the default: it generalises better from 20 paths; observation: every feature); --moving-discs N
adds 0..N moving discs to the rounds' episodes. The observation learning_plan (the default)
holds the length of the own map's plan to the goal, which the potential reads: NIRL's best
observation (90% validation in a median 81,920 robot-steps; docs/notebook.md part 15). Demonstrations
recorded in another observation are refused with the --observation to give.
MAP refinement's prior is the policy's own softmax by default; --refine-prior hindsight judges each
demonstrated action instead by the lattice A* on the map the demonstration's own range readings
drew (its recorded poses and readings, never the true map; agents/nirl/hindsight.py): on 20
demonstrations with 30% random actions it relabels 31-42% of the random actions to the expert's
and 80% of those that cost a detour, keeping 99% of the clean steps. The run prints and
summary.json records how many demonstrated steps refinement relabelled.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from agents.nirl.config import NIRLConfig, NIRLRun
    from services.common.options import add_options

    parser = subparsers.add_parser(
        "nirl",
        help="train NIRL from demonstrations in one process, plot its weight changes or its learned reward",
        description="Neural inverse reinforcement learning (thesis ch. 5): `nirl train`, `nirl weights`, "
        "`nirl reward`.",
    )
    sub = parser.add_subparsers(dest="nirl_command", metavar="SUBCOMMAND", required=True)
    train = sub.add_parser(
        "train",
        help="train NIRL from a demonstration dataset",
        description=TRAIN_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    train.add_argument("--demos", required=True, help="demonstration dataset directory (Minari)")
    train.add_argument(
        "--observation",
        choices=list(OBSERVATIONS),
        default="learning_plan",
        help="what the robot observes: learning_plan (worlds.config.LEARNING_PLAN_NAV: sector minima, "
        "goal, subgoal on its own map and the length of that plan to the goal, which NIRL's progress "
        "potential reads: its best, and what `navlearn demos generate` records by default), learning "
        "(NNQL's: the same without the plan length) or plain (8 beams + goal, older demonstration sets); "
        "the demonstrations must have been recorded in it (default %(default)s)",
    )
    add_options(train, NIRLRun, "NAVLEARN_NIRL_RUN", "run: environment, evaluation, outputs")
    add_options(train, NIRLConfig, "NAVLEARN_NIRL", "NIRL hyper-parameters")
    train.set_defaults(func=run_train)

    weights = sub.add_parser(
        "weights",
        help="plot how the reward and policy networks' weights changed over a run",
        description="Read RUN/weights_history.safetensors (written by `navlearn nirl train` and by the "
        "learner service's NIRL checkpoints) and plot, per network and layer, the relative change of the "
        "weights from one iteration to the next and from the first iteration.",
    )
    weights.add_argument("--run", required=True, help="run directory holding weights_history.safetensors")
    weights.add_argument("--out", default="weights.png", help="PNG to write")
    weights.set_defaults(func=run_weights)

    reward = sub.add_parser(
        "reward",
        help="draw a run's learned reward over a map beside the true geodesic cost",
        description="Put the robot at every free cell of a task from --map (8 headings each), score every "
        "action with RUN/reward.safetensors and draw the best action's reward beside the geodesic distance "
        "to the goal, and, for runs with a progress potential (RUN/potential.safetensors, NIRL's default: "
        "it shapes the reward the policy learns on once the reward is fixed), the potential too; prints "
        "their Spearman rank correlations with minus the geodesic cost over the reachable cells.",
    )
    reward.add_argument("--run", required=True, help="NIRL run directory (reward.safetensors + config.json)")
    reward.add_argument("--map", required=True, help="map spec (FAMILY:N or a map file) of the task to draw")
    reward.add_argument("--seed", type=int, default=0, help="seed of the task drawn from --map")
    reward.add_argument("--headings", type=int, default=8, help="headings averaged per cell")
    reward.add_argument("--out", default="reward.png", help="PNG to write")
    reward.set_defaults(func=run_reward)


def run_train(args: argparse.Namespace) -> int:
    import sys

    from agents.demos import DemoFormatError
    from agents.device import resolve_device
    from agents.nirl.buffers import load_demonstrations
    from agents.nirl.config import NIRLConfig, NIRLRun
    from agents.nirl.train_local import train_nirl
    from services.common.options import OptionError, options_from_args
    from worlds.tasks import parse_map_spec

    try:
        config = options_from_args(NIRLConfig, args, "NAVLEARN_NIRL")
        run = options_from_args(NIRLRun, args, "NAVLEARN_NIRL_RUN")
        resolve_device(run.device)  # cuda without a GPU: one sentence, before anything starts
        if run.envs < 1:
            raise OptionError("--envs must be positive")
        for mf in parse_map_spec(run.maps).maps:
            print(mf.note)
        nav = OBSERVATIONS[args.observation]
        demos = load_demonstrations(args.demos, nav)
    except (OptionError, DemoFormatError, ValueError) as exc:
        print(f"navlearn nirl train: {exc}", file=sys.stderr)
        return 2
    steps = sum(len(d) for d in demos)
    print(f"{len(demos)} demonstrations ({steps} steps) from {args.demos}")
    result = train_nirl(demos, config, run, nav)
    print(
        f"{result.learner.iteration} iterations, {result.env_steps} robot-steps, "
        f"{result.learner.version} Q updates in {result.wall_time:.0f} s"
    )
    refined = result.demo_refinement
    if refined["prior"] != "off":
        print(
            f"MAP refinement ({refined['prior']} prior): {refined['relabelled']} of {refined['steps']} "
            f"demonstrated steps relabelled, {refined['reweighted']} re-weighted"
        )
    if result.final_table:
        print(result.final_table)
    if run.out:
        print(f"wrote {run.out}")
    return 0


def run_weights(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    from agents.nirl.weights import HISTORY_FILE, WeightHistory, plot_weight_changes

    path = Path(args.run) / HISTORY_FILE
    if not path.is_file():
        print(f"navlearn nirl weights: {path} not found (is --run a NIRL run directory?)", file=sys.stderr)
        return 2
    try:
        history = WeightHistory.load(path)
        out = plot_weight_changes(history, args.out, title=f"NIRL weight changes ({args.run})")
    except ValueError as exc:
        print(f"navlearn nirl weights: {exc}", file=sys.stderr)
        return 2
    print(f"{len(history)} iterations -> {out}")
    return 0


def run_reward(args: argparse.Namespace) -> int:
    import sys

    import numpy as np

    from agents.nirl.reward_map import load_potential, load_reward_network, plot_reward_map, reward_map
    from worlds.tasks import parse_map_spec

    try:
        network, potential = load_reward_network(args.run), load_potential(args.run)
        task = parse_map_spec(args.map)(np.random.default_rng(args.seed))
        if args.headings < 1:
            raise ValueError("--headings must be positive")
    except ValueError as exc:
        print(f"navlearn nirl reward: {exc}", file=sys.stderr)
        return 2
    result = reward_map(network, task, headings=args.headings, potential=potential)
    out = plot_reward_map(result, args.out, title=f"{args.run} on {task.map_id or args.map}")
    shaped = "" if potential is None else f", (progress potential, ...) = {result.potential_spearman:.3f}"
    print(
        f"Spearman(learned reward, -geodesic cost) = {result.spearman:.3f}{shaped} over the reachable "
        f"cells -> {out}"
    )
    return 0
