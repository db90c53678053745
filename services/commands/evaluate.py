"""`navlearn evaluate`: measure a saved policy on the fixed evaluation sets, or compare two policies."""

from __future__ import annotations

import argparse

from services.common.options import add_options
from worlds.own_env import ENV_TITLE, EnvConfig

HEADLINE_HELP = "500, agents.evaluation.HEADLINE_EPISODES"
"""what --help says the default episode count is (not imported: agents.evaluation takes 2 s to load)"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="evaluate a saved policy (imitation, NNQL, NIRL) on held-out maps, or compare two",
        description="Run a saved policy (a directory with model.safetensors + config.json from `navlearn "
        "imitate train`, NNQL or NIRL) greedily on fixed, seeded evaluation sets and print success, "
        "collision (static/dynamic) and timeout rates with 95% confidence intervals, SPL, path length "
        "ratio to grid A*, time to goal and minimum clearance. With --out, also writes eval.json and a "
        "PNG per map type with the policy's paths beside A*'s. With --compare A B, runs both on the same "
        "episodes and prints, per set and per map family (rects, discs, rooms), both success rates, the "
        "episodes only one solved with the exact McNemar p-value, SPL, and each one's path length ratio "
        "to A* on the episodes both solved (--out: compare.json). --map evaluates on your own map files "
        "(ROS map_server YAML, MovingAI .map with its .scen, ASCII; docs/maps.md).",
    )
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--policy", metavar="DIR", help="policy directory")
    which.add_argument(
        "--compare",
        nargs=2,
        metavar="DIR",
        help="two policy directories to compare on the same episodes (either may be 'heuristic', the "
        "goal-seeking baseline)",
    )
    parser.add_argument(
        "--maps",
        nargs="+",
        choices=("unseen", "dynamic", "movingai"),
        help="evaluation sets: unseen (held-out generated maps), dynamic (the same with moving discs), "
        "movingai (the arena map's 130 scenarios: use --episodes 130 or fewer); default: unseen dynamic, "
        "none when --map is given",
    )
    parser.add_argument(
        "--map",
        action="append",
        metavar="PATH",
        help="an evaluation set on your map file(s): a map_server .yaml, a MovingAI .map (its .scen "
        "scenarios when beside it), an ASCII map, or a directory of them; repeat for several sets. "
        "Pairs are drawn by A* distance from --seed; the cell size chosen is printed",
    )
    maps = parser.add_argument_group("map files (--map)", "how map files are read and their pairs drawn")
    maps.add_argument("--min-distance", type=float, help="least A* start-goal distance in metres (default 2)")
    maps.add_argument(
        "--max-distance",
        type=float,
        help="largest A* start-goal distance in metres (default: the map's longest)",
    )
    maps.add_argument(
        "--unknown",
        metavar="{blocked,free}",
        help="map_server cells of unknown occupancy (worlds.mapfiles.UNKNOWN; default blocked: nobody has "
        "seen them)",
    )
    maps.add_argument(
        "--pairs",
        metavar="{own,drawn}",
        help="where the pairs come from (worlds.tasks.PAIRS): own (default): a MovingAI .scen's or an "
        "ASCII map's S/G pairs when the file has them, else drawn; drawn: always draw pairs by A* "
        "distance, as many as --episodes (a .scen's few pairs repeat when --episodes asks for more)",
    )
    maps.add_argument(
        "--cell-size",
        type=float,
        help="world cell size in metres for map_server maps (default: the largest multiple of the "
        "resolution up to half the robot radius; walls are never lost)",
    )
    maps.add_argument(
        "--robot-radius",
        type=float,
        metavar="M",
        help="your robot's radius in metres, e.g. 0.105 for a TurtleBot3 Burger (default 0.25, the "
        "world's robot, the one policies are trained with): the map is read scaled by 0.25 / M, so "
        "the world's robot, its 0.5 m step and 6 m rays stand for yours (docs/maps.md)",
    )
    parser.add_argument(
        "--step-factor",
        type=float,
        help="step limit = max(--max-steps, step-factor x the A* path's steps); default 4 "
        "(worlds.config.NavConfig.step_factor); 0: a fixed --max-steps",
    )
    parser.add_argument("--max-steps", type=int, help="least step limit of an episode (default 200)")
    parser.add_argument(
        "--episodes", type=int, help=f"episodes per evaluation set (default: {HEADLINE_HELP})"
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="evaluation set seed: same seed, same episodes (default: %(default)s)",
    )
    parser.add_argument(
        "--size", type=int, default=16, help="side of the generated maps in cells (default: %(default)s)"
    )
    parser.add_argument(
        "--obstacles",
        type=int,
        default=4,
        help="moving discs per episode in the dynamic set (default: %(default)s)",
    )
    parser.add_argument(
        "--shield",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="a learned policy acts through its reading shield: never an action its current range "
        "readings say hits something (0.1 m to spare first), half a turn in place when every action "
        "would, and kept clear of where the moving discs it tracks in the scan are going "
        "(agents.shield, agents.disc_tracker; the heuristic is never shielded). --no-shield: the "
        "network's own choice (default: shielded)",
    )
    parser.add_argument(
        "--known-map",
        action="store_true",
        help="give the robot its map, as a robot localised in it: a learned policy's subgoal is planned on "
        "the true map (the generated map or your --map file) instead of on the map the robot builds from "
        "its range readings, which still drive the network and its shield. For policies that observe an "
        "own-map subgoal, as the shipped ones do; it shortens paths on maps of about 1 m cells, not on "
        "0.1 m map_server maps (docs/navigation-by-size.md section 16; default: the robot does not know "
        "the map)",
    )
    parser.add_argument(
        "--out", help="directory for eval.json and the path plots (with --compare: compare.json)"
    )
    add_options(parser, EnvConfig, "NAVLEARN_ENV", ENV_TITLE + "; default: the env the policy records")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from agents.evaluation import (
        HEADLINE_EPISODES,
        compare,
        evaluate,
        make_eval_set,
        make_map_eval_set,
        plot_paths,
    )
    from agents.evaluation.policies import GreedyMLPPolicy, PolicyFormatError, load_policy_or_baseline
    from worlds.config import NavConfig, ObstacleConfig
    from worlds.tasks import parse_map_spec, with_options

    if args.episodes is None:
        args.episodes = HEADLINE_EPISODES
    if args.episodes < 1:
        print("navlearn evaluate: --episodes must be positive", file=sys.stderr)
        return 2
    if args.maps is None:
        args.maps = [] if args.map else ["unseen", "dynamic"]
    limits = {"step_factor": args.step_factor, "max_steps": args.max_steps}
    try:
        config = NavConfig(**{k: v for k, v in limits.items() if v is not None})
    except ValueError as exc:
        print(f"navlearn evaluate: {exc}", file=sys.stderr)
        return 2
    map_specs = [
        with_options(
            spec, min_distance=args.min_distance, max_distance=args.max_distance, unknown=args.unknown,
            cell_size=args.cell_size, radius=args.robot_radius, pairs=args.pairs,
        )
        for spec in args.map or []
    ]  # fmt: skip
    specs = args.compare or [args.policy]
    policies, configs = [], []
    for spec in specs:
        try:
            policy = load_policy_or_baseline(spec, config)
        except PolicyFormatError as exc:
            print(f"navlearn evaluate: {exc}", file=sys.stderr)
            return 2
        if getattr(policy, "env", None) is not None or args.opt_env:
            if args.known_map:
                print(f"navlearn evaluate: {spec}: --known-map is for navlearn's robot, not a Gymnasium env",
                      file=sys.stderr)  # fmt: skip
                return 2
            policies.append(policy)
            continue
        if isinstance(policy, GreedyMLPPolicy) and policy.architecture["n_actions"] != config.robot.n_actions:
            print(
                f"navlearn evaluate: {spec}: the policy takes {policy.architecture['n_actions']} actions; "
                f"the environment has {config.robot.n_actions}",
                file=sys.stderr,
            )
            return 2
        if isinstance(policy, GreedyMLPPolicy) and args.known_map:
            try:
                policy.use_known_map()
            except ValueError as exc:
                print(f"navlearn evaluate: {spec}: --known-map: {exc}", file=sys.stderr)
                return 2
        policies.append(policy)
        # a saved policy's env observes what it was trained to (the observation in its config.json)
        configs.append(policy.nav_config(config) if isinstance(policy, GreedyMLPPolicy) else config)
        if isinstance(policy, GreedyMLPPolicy) and args.shield:
            try:
                policy.use_shield(configs[-1])
            except ValueError as exc:
                print(f"navlearn evaluate: {spec}: {exc}", file=sys.stderr)
                return 2
    if args.known_map and not any(isinstance(p, GreedyMLPPolicy) for p in policies):
        print("navlearn evaluate: --known-map changes a learned policy's subgoal; the heuristic plans none",
              file=sys.stderr)  # fmt: skip
        return 2
    if len(configs) < len(policies):  # a Gymnasium env: its own episodes, not navlearn's map sets
        return evaluate_on_env(args, specs, policies)
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
        for spec in map_specs:
            sampler = parse_map_spec(spec)
            for mf in sampler.maps:
                print(mf.note)
            sets.append(make_map_eval_set(sampler, args.episodes, seed=args.seed))
    except ValueError as exc:
        print(f"navlearn evaluate: {exc}", file=sys.stderr)
        return 2
    args.maps = [s.family for s in sets]
    results = [evaluate(policy, sets, cfg) for policy, cfg in zip(policies, configs, strict=True)]
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    if args.compare:
        names = [
            f"{spec} ({p!r})" if isinstance(p, GreedyMLPPolicy) else spec
            for spec, p in zip(specs, policies, strict=True)
        ]
        comparison = compare(*results, names=names)
        print(f"{', '.join(args.maps)} ({args.episodes} episodes each, seed {args.seed})")
        print(comparison.table())
        if out:
            report = {
                "seed": args.seed,
                **comparison.to_dict(),
                "metrics": {
                    k: r.to_dict(with_episodes=False)["metrics"] for k, r in zip("ab", results, strict=True)
                },
            }
            (out / "compare.json").write_text(json.dumps(report, indent=1) + "\n")
            print(f"wrote {out / 'compare.json'}")
        return 0
    policy, result = policies[0], results[0]
    print(f"{policy} on {', '.join(args.maps)} ({args.episodes} episodes each, seed {args.seed})")
    print(result.table())
    if out:
        report = {
            "policy": str(Path(args.policy).resolve()),
            "model": getattr(policy, "model", args.policy),
            "version": getattr(policy, "version", 0),
            "shield": getattr(policy, "shield", None) is not None,
            "known_map": args.known_map,
            "seed": args.seed,
            **result.to_dict(),
        }
        (out / "eval.json").write_text(json.dumps(report, indent=1) + "\n")
        for family in args.maps:
            print(f"wrote {plot_paths(result, family, out / f'paths_{family}.png')}")
    return 0


def evaluate_on_env(args: argparse.Namespace, specs: list[str], policies: list) -> int:
    """``navlearn evaluate`` of policies trained on a Gymnasium env: the env each records (or --env),
    ``--episodes`` greedy episodes seeded ``--seed``; return with its 95% interval, length, success where
    the env gives ``is_success`` (agents.evaluation.env_returns). ``--out``: eval.json."""
    import json
    import sys
    from pathlib import Path

    from agents.evaluation.env_returns import evaluate_env, table
    from services.common.options import OptionError, options_from_args
    from worlds.own_env import EnvError, env_spaces

    reports = {}
    for spec, policy in zip(specs, policies, strict=True):
        try:
            given = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
            env = given if given.env else EnvConfig.from_record(getattr(policy, "env", None))
            if env.own_world:
                raise EnvError(
                    f"{spec}: trained on navlearn's world; evaluate it without --env, or give the env"
                )
            obs_dim, n_actions = env_spaces(env)
            takes = policy.obs_dim, policy.architecture["n_actions"]
            if takes != (obs_dim, n_actions):
                raise EnvError(
                    f"{spec}: the policy takes {takes[0]} inputs and {takes[1]} actions; --env "
                    f"{env.signature()} has {obs_dim} and {n_actions}: give the env it was trained on"
                )
            metrics = evaluate_env(policy, env, args.episodes, seed=args.seed)
        except (OptionError, EnvError) as exc:
            print(f"navlearn evaluate: {exc}", file=sys.stderr)
            return 2
        print(f"{policy!r} ({spec}), {args.episodes} greedy episodes, seed {args.seed}")
        print(table(metrics))
        reports[spec] = {"policy": spec, "model": policy.model, "version": policy.version, "seed": args.seed,
                         "env": env.record(), "metrics": metrics}  # fmt: skip
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        name = "compare.json" if args.compare else "eval.json"
        (out / name).write_text(json.dumps(reports if args.compare else reports[specs[0]], indent=1) + "\n")
        print(f"wrote {out / name}")
    return 0
