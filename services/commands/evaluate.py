"""`navlearn evaluate`: measure a saved policy on the fixed evaluation sets."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="evaluate a saved policy (imitation, NNQL, NIRL) on held-out maps",
        description="Run a saved policy (a directory with model.safetensors + config.json from `navlearn "
        "imitate train`, NNQL or NIRL) greedily on fixed, seeded evaluation sets and print success, "
        "collision (static/dynamic) and timeout rates with 95% confidence intervals, SPL, path length "
        "ratio to grid A*, time to goal and minimum clearance. With --out, also writes eval.json and a "
        "PNG per map type with the policy's paths beside A*'s.",
    )
    parser.add_argument("--policy", required=True, help="policy directory")
    parser.add_argument(
        "--maps",
        nargs="+",
        choices=("unseen", "dynamic", "movingai"),
        default=["unseen", "dynamic", "movingai"],
        help="evaluation sets: unseen (held-out generated maps), dynamic (the same with moving discs), "
        "movingai (the arena map's scenarios)",
    )
    parser.add_argument("--episodes", type=int, default=100, help="episodes per evaluation set")
    parser.add_argument("--seed", type=int, default=0, help="evaluation set seed (same seed, same episodes)")
    parser.add_argument("--size", type=int, default=16, help="side of the generated maps (cells)")
    parser.add_argument(
        "--obstacles", type=int, default=4, help="moving discs per episode in the dynamic set"
    )
    parser.add_argument("--out", help="directory for eval.json and the path plots")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from agents.evaluation import evaluate, make_eval_set, plot_paths
    from agents.evaluation.policies import PolicyFormatError, load_policy
    from worlds.config import ObstacleConfig

    if args.episodes < 1:
        print("navlearn evaluate: --episodes must be positive", file=sys.stderr)
        return 2
    try:
        policy = load_policy(args.policy)
    except PolicyFormatError as exc:
        print(f"navlearn evaluate: {exc}", file=sys.stderr)
        return 2
    config = policy.nav_config()  # the env observes what the policy was trained to (its config.json)
    try:
        sets = [
            make_eval_set(
                f,
                args.episodes,
                seed=args.seed,
                size=args.size,
                obstacles=ObstacleConfig(count=args.obstacles),
            )
            for f in args.maps
        ]
    except ValueError as exc:
        print(f"navlearn evaluate: {exc}", file=sys.stderr)
        return 2
    result = evaluate(policy, sets, config)
    print(f"{policy} on {', '.join(args.maps)} ({args.episodes} episodes each, seed {args.seed})")
    print(result.table())
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        report = {
            "policy": str(Path(args.policy).resolve()),
            "model": policy.model,
            "version": policy.version,
            "seed": args.seed,
            **result.to_dict(),
        }
        (out / "eval.json").write_text(json.dumps(report, indent=1) + "\n")
        for family in args.maps:
            print(f"wrote {plot_paths(result, family, out / f'paths_{family}.png')}")
    return 0
