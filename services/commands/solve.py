"""`navlearn solve`: solve a grid map's navigation MDP by dynamic programming and draw it."""

from __future__ import annotations

import argparse

METHODS = ("vi", "gs", "pi", "mpi", "qvi", "grid")


def parse_cell(text: str) -> tuple[int, int]:
    """``"r,c"`` -> ``(r, c)``; argparse type."""
    try:
        row, col = (int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected ROW,COL (two integers), got {text!r}") from None
    return row, col


def add_world_args(parser: argparse.ArgumentParser) -> None:
    """Map, goal and grid-world dynamics flags shared by `solve` and `tabular`."""
    parser.add_argument("--start", type=parse_cell, metavar="ROW,COL", help="start cell (default: see above)")
    parser.add_argument("--goal", type=parse_cell, metavar="ROW,COL", help="goal cell (default: see above)")
    parser.add_argument("--slip", type=float, default=0.1, help="probability that another move happens")
    parser.add_argument("--connectivity", type=int, choices=(4, 8), default=8, help="4 or 8 moves")
    parser.add_argument(
        "--step-cost", type=float, default=1.0, help="cost per cell moved (diagonal: x sqrt 2)"
    )
    parser.add_argument(
        "--collision-cost", type=float, default=5.0, help="cost of a blocked move (robot stays)"
    )


def load_task(args: argparse.Namespace, default_map: str | None = None):
    """``(GridDynamics, start)`` from the flags; ValueError with a one-line reason on bad input."""
    from pathlib import Path

    from agents.mdp import default_start_goal
    from worlds.gridworld import GridDynamics, GridWorldConfig
    from worlds.maps import load_movingai, parse_ascii

    if args.map is None:
        grid, markers = parse_ascii(default_map or "", "gridworld-default")
    else:
        path = Path(args.map)
        if not path.is_file():
            raise ValueError(f"{path}: map file not found")
        text = path.read_text(encoding="ascii", errors="replace")
        if text.startswith("type "):
            grid, markers = load_movingai(path), {}
        else:
            grid, markers = parse_ascii(text, path)
    start, goal = args.start or markers.get("S"), args.goal or markers.get("G")
    if start is None or goal is None:
        default_start, default_goal = default_start_goal(grid, args.connectivity)
        start, goal = start or default_start, goal or default_goal
    config = GridWorldConfig(args.connectivity, args.slip, args.step_cost, args.collision_cost)
    dynamics = GridDynamics.build(grid, goal, config)
    dynamics.state(start)  # raises if the start cannot reach the goal
    return dynamics, start


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "solve",
        help="solve a grid map's navigation MDP (value/policy iteration) and draw values and policy",
        description="Build the grid-world MDP of a map (moves with slip, blocked moves cost a collision, "
        "absorbing goal; thesis ch. 2), solve it by dynamic programming, print iterations, time and the "
        "stopping-rule residual and bound, and draw the value function with greedy-policy arrows and the "
        "greedy path from start to goal. Without --start/--goal: an ASCII map's S/G markers, else the "
        "goal is the bottom-right-most cell of the largest free region and the start the cell farthest "
        "from it.",
    )
    parser.add_argument("--map", help="MovingAI .map or ASCII map file (default: a small built-in map)")
    add_world_args(parser)
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="vi",
        help="vi: value iteration, gs: Gauss-Seidel VI, pi: policy iteration, mpi: modified PI, "
        "qvi: Q-value iteration (all on the sparse MDP); grid: goal-outward Gauss-Seidel sweeps over "
        "the grid (fastest)",
    )
    parser.add_argument("--gamma", type=float, default=0.99, help="discount factor in [0, 1)")
    parser.add_argument(
        "--eps",
        type=float,
        default=0.01,
        help="stop when the greedy policy is eps-optimal (value-iteration family)",
    )
    parser.add_argument("--out", default="values.png", help="PNG file for the picture")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys
    import time

    from rich.console import Console

    from agents.mdp import SOLVERS, dynamics_to_mdp, grid_value_iteration
    from agents.mdp.plot import plot_values
    from worlds.gridworld import DEFAULT_MAP

    if not 0.0 <= args.gamma < 1.0 or not args.eps > 0:
        print("navlearn solve: --gamma must be in [0, 1) and --eps positive", file=sys.stderr)
        return 2
    try:
        dynamics, start = load_task(args, DEFAULT_MAP)
    except ValueError as exc:
        print(f"navlearn solve: {exc}", file=sys.stderr)
        return 2
    grid = dynamics.grid
    print(
        f"map {grid.name or args.map} {grid.height}x{grid.width}: {dynamics.n_states} states x "
        f"{dynamics.n_actions} actions, slip {args.slip}, gamma {args.gamma}; "
        f"start {start}, goal {dynamics.goal}"
    )
    with Console().status(f"solving with {args.method}..."):
        began = time.perf_counter()
        if args.method == "grid":
            result = grid_value_iteration(dynamics, args.gamma, args.eps)
        else:
            mdp = dynamics_to_mdp(dynamics, args.gamma)
            built = time.perf_counter()
            print(f"sparse MDP built in {built - began:.2f} s ({mdp.stacked.nnz} transitions)")
            began = built
            extra = {} if args.method == "pi" else {"eps": args.eps}
            result = SOLVERS[args.method](mdp, **extra)
        seconds = time.perf_counter() - began
    unit = "policy improvements" if args.method == "pi" else "sweeps"
    print(
        f"{result.method}: {result.iterations} {unit} in {seconds:.3f} s, residual {result.residual:.3g}, "
        f"max |V - V*| <= {result.bound:.3g}{'' if result.converged else ' (NOT converged: iteration cap)'}"
    )
    path = dynamics.intended_path(result.policy, start)
    reached = path[-1] == dynamics.goal
    print(
        f"V(start) = {result.values[dynamics.state(start)]:.3f}; greedy path (intended moves) "
        f"{'reaches the goal in' if reached else 'does NOT reach the goal after'} {len(path) - 1} moves"
    )
    if not reached:
        print(
            "  (far from the goal gamma**distance is below what eps resolves, so values are flat there: "
            "a larger --gamma or a smaller --eps makes the goal visible)"
        )
    title = f"{grid.name or 'map'}: {result.method}, slip {args.slip}, gamma {args.gamma}"
    fig = plot_values(dynamics, result.values, result.policy, path, start, title)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
