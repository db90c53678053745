"""`navlearn tabular`: model-free learning (Q-learning, SARSA, Monte Carlo) on a grid world,
with the learning curve as a PNG."""

from __future__ import annotations

import argparse
from dataclasses import asdict

from agents.tabular.config import MonteCarloConfig, TabularConfig
from services.commands.solve import add_world_args, load_task
from services.common.options import OptionError, add_options, options_from_args

ALGORITHMS = ("qlearning", "sarsa", "mc")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "tabular",
        help="learn a grid world by Q-learning, SARSA or Monte Carlo control and plot the learning curve",
        description="Model-free control on the tabular grid world of a map (thesis ch. 2.4). Episodes "
        "start at --start, or at a random state each time with --exploring-starts. At the end the greedy "
        "policy is compared with value iteration's optimum. Without --start/--goal: an ASCII map's S/G "
        "markers, else the goal is the bottom-right-most cell of the largest free region and the start "
        "the cell farthest from it. Without --map: a small built-in map.",
    )
    parser.add_argument("--algo", choices=ALGORITHMS, default="qlearning", help="learning algorithm")
    parser.add_argument("--map", help="MovingAI .map or ASCII map file (default: a small built-in map)")
    add_world_args(parser)
    parser.add_argument(
        "--exploring-starts", action="store_true", help="start each episode in a random state, not --start"
    )
    parser.add_argument("--max-steps", type=int, default=200, help="episode length cap")
    add_options(parser, TabularConfig, "NAVLEARN_TABULAR", "learner")
    parser.add_argument("--every-visit", action="store_true", help="Monte Carlo: update on every visit")
    parser.add_argument("--out", default="curve.png", help="PNG file for the learning curve")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys
    import time

    import numpy as np
    from rich.progress import Progress

    from agents.mdp import dynamics_to_mdp, value_iteration
    from agents.tabular import monte_carlo_control, q_learning, sarsa
    from worlds.gridworld import DEFAULT_MAP, GridWorldEnv

    try:
        dynamics, start = load_task(args, DEFAULT_MAP)
        config = options_from_args(TabularConfig, args, "NAVLEARN_TABULAR")
        if args.algo == "mc":
            config = MonteCarloConfig(first_visit=not args.every_visit, **asdict(config))
        if not 0.0 <= config.gamma < 1.0:
            raise ValueError("--gamma must be in [0, 1) (the comparison with value iteration needs it)")
        env = GridWorldEnv(
            dynamics.grid,
            dynamics.goal,
            None if args.exploring_starts else start,
            dynamics.config,
            max_steps=args.max_steps,
        )
    except (OptionError, ValueError) as exc:
        print(f"navlearn tabular: {exc}", file=sys.stderr)
        return 2
    learn = {"qlearning": q_learning, "sarsa": sarsa, "mc": monte_carlo_control}[args.algo]
    print(
        f"{args.algo} on {dynamics.grid.name} ({dynamics.n_states} states x {dynamics.n_actions} actions), "
        f"slip {args.slip}, start {'random' if args.exploring_starts else start}, goal {dynamics.goal}"
    )
    began = time.perf_counter()
    with Progress() as progress:
        bar = progress.add_task(f"{args.algo} episodes", total=config.episodes)
        result = learn(env, config, progress=lambda done: progress.update(bar, completed=done))
    seconds = time.perf_counter() - began
    steps = int(result.lengths.sum())
    tail = max(1, config.episodes // 10)
    print(
        f"{config.episodes} episodes, {steps} steps in {seconds:.2f} s; mean return of the last {tail} "
        f"episodes {result.returns[-tail:].mean():.2f} (first {tail}: {result.returns[:tail].mean():.2f})"
    )
    mdp = dynamics_to_mdp(dynamics, config.gamma)
    best = value_iteration(mdp, eps=1e-8)
    q_star = mdp.q_values(best.values)
    optimal = q_star[np.arange(dynamics.n_states), result.policy] >= best.values - 1e-6
    reach = sum(
        dynamics.intended_path(result.policy, dynamics.cell(s))[-1] == dynamics.goal
        for s in range(dynamics.n_states)
    )
    print(
        f"greedy policy: optimal action (value iteration) in {optimal.sum()}/{dynamics.n_states} states, "
        f"reaches the goal from {reach}/{dynamics.n_states} (from the start: "
        f"{'yes' if dynamics.intended_path(result.policy, start)[-1] == dynamics.goal else 'no'})"
    )
    _plot_curve(result.returns, f"{args.algo} on {dynamics.grid.name}, slip {args.slip}", args.out)
    print(f"wrote {args.out}")
    return 0


def _plot_curve(returns, title: str, out: str) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import numpy as np

    window = max(1, len(returns) // 100)
    smooth = np.convolve(returns, np.ones(window) / window, mode="valid")
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(np.arange(1, len(returns) + 1), returns, color="0.75", linewidth=0.5, label="return per episode")
    ax.plot(np.arange(window, len(returns) + 1), smooth, color="C0", linewidth=1.8, label=f"mean of {window}")
    ax.set_xlabel("episode")
    ax.set_ylabel("return (undiscounted)")
    ax.set_title(title)
    low = np.percentile(returns, 1)
    ax.set_ylim(bottom=min(low, smooth.min()) * 1.05 if low < 0 else None)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
