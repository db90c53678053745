"""`navlearn demos`: generate expert demonstrations (Minari datasets) and inspect them."""

from __future__ import annotations

import argparse

from services.common.options import add_options
from worlds.config import OBSERVATIONS
from worlds.own_env import ENV_TITLE, EnvConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demos",
        help="generate expert demonstrations as Minari datasets, or summarise one",
        description="Demonstrations for imitation learning and NIRL (thesis ch. 3): the modified-A* "
        "expert drives the robot in the navigation env; each episode is stored in a Minari dataset.",
    )
    sub = parser.add_subparsers(dest="demos_command", metavar="SUBCOMMAND", required=True)

    gen = sub.add_parser(
        "generate",
        help="run the expert and write a Minari dataset",
        description="Run the modified-A* expert on tasks drawn from --maps and record the robot's own "
        "observations, actions, rewards, terminations and truncations, plus per-episode metadata (map, "
        "start, goal, source, seed), as a Minari dataset in the directory --out.",
    )
    gen.add_argument(
        "--maps",
        default="mixed:16",
        help="map spec: FAMILY:N[xM], mixed:N, or map files (a map_server .yaml, a MovingAI "
        ".map/.scen, an ASCII map, a directory) with key=value options (docs/maps.md)",
    )
    gen.add_argument("--episodes", type=int, default=200, help="number of expert episodes to run")
    gen.add_argument(
        "--out",
        required=True,
        help="dataset directory; its name is the Minari dataset id (e.g. demos/expert-v0), its parent "
        "the datasets root",
    )
    gen.add_argument(
        "--noise",
        type=float,
        default=0.0,
        help="probability of replacing the expert's action by a random wall-free one (imperfect demos)",
    )
    gen.add_argument("--seed", type=int, default=0, help="episode i resets the env with seed SEED + i")
    gen.add_argument("--obstacles", type=int, default=0, help="number of moving discs per episode")
    gen.add_argument(
        "--keep-failures", action="store_true", help="also keep episodes that did not reach the goal"
    )
    gen.add_argument(
        "--observation",
        choices=list(OBSERVATIONS),
        default="learning_plan",
        help="what the recorded robot observes (the expert acts on the true map; the robot's own "
        "observation of each episode is recorded, and the dataset records its settings): learning_plan "
        "(worlds.config.LEARNING_PLAN_NAV: sector minima, goal, own-map subgoal and that plan's length "
        "to the goal; what `nirl train` learns in by default, and `imitate train` and `up --nirl` in "
        "`learning` load it with the plan length dropped, exactly), learning (worlds.config.LEARNING_NAV, "
        "without the plan length) or plain (8 beams + goal, the older sets); default %(default)s",
    )
    gen.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    gen.set_defaults(func=generate)

    rec = sub.add_parser(
        "record",
        help="record demonstrations on your own Gymnasium env (--env) as a Minari dataset",
        description="Play --episodes episodes of a Gymnasium env (--env, as `navlearn up --env` takes it: "
        "observations flattened) with a demonstrator - a trained policy directory (--policy: "
        "`navlearn train --local --env` or `up --env`'s policy/, or `imitate train --env`'s) or your own "
        "callable (--expert module:fn, one flat observation -> one action) - and write them as a Minari "
        "dataset in --out, with the env's Gymnasium spec and its id and kwargs recorded; "
        "`navlearn imitate train --env` learns from it and checks it was recorded on that env. "
        "Episode i resets the env with --seed + i. How-to: docs/own-env.md.",
    )
    who = rec.add_mutually_exclusive_group(required=True)
    who.add_argument("--policy", metavar="DIR", help="a saved policy directory that acts greedily")
    who.add_argument(
        "--expert", metavar="MODULE:FN", help="your callable: one flat observation (numpy) -> one action"
    )
    rec.add_argument("--episodes", type=int, default=100, help="episodes to record (default %(default)s)")
    rec.add_argument("--out", required=True, help="dataset directory named like a Minari id (demos/mine-v0)")
    rec.add_argument("--seed", type=int, default=0, help="episode i resets the env with seed SEED + i")
    rec.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    add_options(rec, EnvConfig, "NAVLEARN_ENV", ENV_TITLE + "; default: the env --policy records")
    rec.set_defaults(func=record)

    info = sub.add_parser(
        "info",
        help="summarise a demonstration dataset",
        description="Load (and so validate) a demonstration dataset; print its size, outcomes and sources.",
    )
    info.add_argument("path", help="dataset directory")
    info.set_defaults(func=show_info)


def generate(args: argparse.Namespace) -> int:
    import sys
    from dataclasses import replace
    from pathlib import Path

    from rich.progress import Progress

    from agents.demos import dataset_location, write_demos
    from agents.planning.demonstrate import generate_demos
    from worlds.config import ObstacleConfig, observation_settings
    from worlds.env import observation_space
    from worlds.tasks import parse_map_spec

    if args.episodes < 1:
        print("navlearn demos generate: --episodes must be positive", file=sys.stderr)
        return 2
    if not 0.0 <= args.noise <= 1.0:
        print("navlearn demos generate: --noise must be in [0, 1]", file=sys.stderr)
        return 2
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        print(f"navlearn demos generate: {out} exists (use --overwrite)", file=sys.stderr)
        return 2
    try:
        for mf in parse_map_spec(args.maps).maps:
            print(mf.note)
        dataset_location(out)
    except ValueError as exc:  # DemoFormatError is a ValueError
        print(f"navlearn demos generate: {exc}", file=sys.stderr)
        return 2
    base = OBSERVATIONS[args.observation]
    config = replace(
        base, pool_size=min(base.pool_size, args.episodes), obstacles=ObstacleConfig(count=args.obstacles)
    )
    with Progress() as progress:
        bar = progress.add_task("expert episodes", total=args.episodes)
        demos, stats = generate_demos(
            args.maps,
            args.episodes,
            seed=args.seed,
            noise=args.noise,
            config=config,
            keep_failures=args.keep_failures,
            progress=lambda k: progress.advance(bar, k),
        )
    if not demos:
        print(f"navlearn demos generate: no episode reached the goal ({stats.outcomes})", file=sys.stderr)
        return 1
    from gymnasium import spaces

    path = write_demos(
        out,
        demos,
        observation_space(config),
        spaces.Discrete(config.robot.n_actions),
        description=f"navlearn expert demonstrations on {args.maps}",
        extra_metadata={
            "maps": args.maps,
            "seed": args.seed,
            "noise": args.noise,
            "obstacles": args.obstacles,
        },
        observation=observation_settings(config),
        overwrite=args.overwrite,
    )
    print(
        f"{stats.kept} of {stats.episodes} episodes kept ({stats.steps} steps), outcomes {stats.outcomes}, "
        f"{stats.replans / max(stats.episodes, 1):.1f} replans per episode -> {path}"
    )
    return 0


def record(args: argparse.Namespace) -> int:
    """`navlearn demos record`: a demonstrator's episodes on a user's env, as a Minari dataset."""
    import sys

    try:
        env, act, who = demonstrator(args)
        from agents.env_demos import record_env_demos

        path, stats = record_env_demos(args.out, env, act, args.episodes, args.seed, who, args.overwrite)
    except (ValueError, OSError) as exc:  # OptionError, EnvError, DemoFormatError, PolicyFormatError
        print(f"navlearn demos record: {exc}", file=sys.stderr)
        return 2
    print(
        f"{stats.episodes} episodes of {env.signature()} by {who} ({stats.steps} steps, mean return "
        f"{stats.mean_return:.1f}) -> {path}"
    )
    return 0


def demonstrator(args: argparse.Namespace):
    """(EnvConfig, act: flat observation -> action, who) of `demos record`'s flags: --env, else the env
    --policy records; a --policy of another env than --env is refused naming both."""
    import importlib

    import numpy as np

    from agents.env_demos import env_name
    from services.common.options import options_from_args

    given = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
    if args.policy:
        from agents.evaluation.policies import load_policy

        policy = load_policy(args.policy)
        recorded = getattr(policy, "env", None)
        env = given if given.env else EnvConfig.from_record(recorded)
        if env.own_world:
            raise ValueError(
                f"--policy {args.policy}: a policy of navlearn's world, whose demonstrations come from "
                "`navlearn demos generate` (the expert); `record` is for a Gymnasium --env"
            )
        if recorded is not None and recorded != env.record():
            raise ValueError(
                f"--policy {args.policy} was trained on env {env_name(recorded)}, not on --env "
                f"{env_name(env.record())}: record on its env (drop --env) or give a policy of this one"
            )
        return env, lambda obs: int(policy(np.asarray(obs, np.float32)[None])[0]), f"policy {args.policy}"
    if given.own_world:
        raise ValueError(
            "--expert acts in a Gymnasium env: give --env (navlearn's world has `demos generate`)"
        )
    module, _, name = args.expert.partition(":")
    try:
        fn = getattr(importlib.import_module(module), name) if name else None
    except ImportError as exc:
        raise ValueError(f"--expert {args.expert}: cannot import {module!r} ({exc})") from None
    if not callable(fn):
        raise ValueError(f"--expert {args.expert}: not module:callable (a function of one observation)")
    return given, fn, f"expert {args.expert}"


def show_info(args: argparse.Namespace) -> int:
    import sys
    from collections import Counter

    from agents.demo_observation import dataset_observation
    from agents.demos import DemoFormatError, dataset_info, load_demos
    from worlds.outcomes import OUTCOME_NAMES

    try:
        demos = load_demos(args.path)
        meta = dataset_info(args.path)
        observation, width = dataset_observation(args.path)
    except DemoFormatError as exc:
        print(f"navlearn demos info: {exc}", file=sys.stderr)
        return 2
    steps = sum(len(d) for d in demos)
    outcomes = Counter(OUTCOME_NAMES[d.metadata["outcome"]] for d in demos)
    sources = Counter(d.metadata["source"] for d in demos)
    maps = len({d.metadata["map_id"] for d in demos})
    print(f"{args.path}: {len(demos)} episodes, {steps} steps, {maps} maps")
    print(f"  outcomes {dict(outcomes)}, sources {dict(sources)}")
    print(f"  generated with {meta['navlearn']}")
    print(f"  observation ({width} values per step): {observation or 'not recorded'}")
    return 0
