"""`navlearn world show`: a picture of the robot world (map, robot, beams, moving discs, trajectory)."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
Draw the robot world to a PNG: a map (a generated one by default), the robot driven for up
to --steps steps by a simple goal-seeking policy (or uniformly random actions with --random),
its trajectory, its range beams at the last step, moving discs, start and goal. It needs no
file: `navlearn world show --out world.png` draws a generated map. With --learning the robot
observes what learned policies observe: its 24 sector minima are drawn as arcs across their
sectors and its subgoal (2.5 m along A* on the map its rays have built) as a star. With
--patch N the observation also holds the N x N egocentric patch of the map the robot built from
its own beams, drawn beside the map at the last step (occupancy and visits, heading up).

--map takes a map spec: FAMILY:N or FAMILY:HxW with FAMILY one of rects, discs, rooms, maze,
mixed (e.g. rooms:16, rects:24x32), or a map file: a ROS map_server .yaml (with its PGM/PNG
image), a MovingAI .map/.scen file or an ASCII map (# blocked, . free, optional S and G
markers), with key=value options (docs/maps.md). The cell size chosen for a map file is printed.
--policy DIR drives the robot with a saved policy (NNQL, NIRL, imitation) instead.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    world = subparsers.add_parser(
        "world",
        help="the robot world: pictures of maps and robots",
        description="The robot world of navlearn (maps, unicycle robot, range sensors, moving discs).",
    )
    sub = world.add_subparsers(dest="world_command", metavar="SUBCOMMAND")
    show = sub.add_parser(
        "show",
        help="draw a map with a robot driving it to a PNG",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    show.add_argument(
        "--map", default="mixed:16", metavar="PATH|SPEC", help="map spec or file (default mixed:16)"
    )
    show.add_argument("--out", default="world.png", help="PNG file to write (default world.png)")
    show.add_argument(
        "--steps",
        type=int,
        default=100,
        help="least step limit (default 100); longer paths get 4 times their A* path's steps",
    )
    show.add_argument("--policy", metavar="DIR", help="drive with this saved policy (default: goal-seeking)")
    show.add_argument(
        "--seed", type=int, default=0, help="seed of the map, start, goal and noise (default 0)"
    )
    show.add_argument("--obstacles", type=int, default=3, help="number of moving discs (default 3)")
    show.add_argument(
        "--obstacle-mode",
        choices=("bounce", "patrol"),
        default="bounce",
        help="how the discs move (default bounce)",
    )
    show.add_argument("--beams", type=int, default=8, help="number of range beams (default 8)")
    show.add_argument("--random", action="store_true", help="drive with uniformly random actions")
    show.add_argument(
        "--shield",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="a --policy acts through its reading shield, as `navlearn evaluate` runs it (agents.shield; "
        "default: shielded)",
    )
    show.add_argument(
        "--learning",
        action="store_true",
        help="the observation learned policies use (worlds.config.LEARNING_NAV): 24 sector minima of 96 "
        "rays, drawn as arcs, and the subgoal on the robot's own map, drawn as a star (--beams ignored)",
    )
    show.add_argument(
        "--known-map",
        action="store_true",
        help="give the robot its map (as `navlearn evaluate --known-map`): the subgoal of a --policy, or "
        "of --learning, is planned on the true map instead of the map the robot builds as it goes",
    )
    show.add_argument(
        "--patch",
        type=int,
        default=0,
        help="observe an N x N patch of the robot's own map and draw it (occupancy, visits; default 0: none)",
    )
    show.set_defaults(func=show_main)
    ahead = sub.add_parser(
        "compile",
        help="compile the robot world's kernels now (numba's cache), before processes that use it start",
        description=(
            "Compile the robot world once (actors' and the evaluator's kernels) into numba's cache, "
            "with a progress line, so that processes started afterwards (by hand, as in the secure "
            "recipe of docs/security.md, or under supervisord) load it in about a second instead of "
            "each compiling it while their clocks run. About 100 s on 2 cores busy with other work, "
            "less on idle ones; nothing to do when the cache is current. `navlearn up` does this itself."
        ),
    )
    ahead.add_argument("--maps", default="mixed:16", help="map spec to compile for (default mixed:16)")
    ahead.set_defaults(func=compile_main)
    world.set_defaults(func=lambda args: (world.print_help(), 2)[1])


def compile_main(args: argparse.Namespace) -> int:
    from rich.console import Console

    from services.common.warmup import compile_with_progress

    console = Console()
    seconds, compiled = compile_with_progress(console, args.maps)
    console.print(
        f"robot world compiled in {seconds:.0f} s (cached: later processes load it)"
        if compiled
        else f"robot world already compiled: loaded from the cache in {seconds:.1f} s"
    )
    return 0


def show_main(args: argparse.Namespace) -> int:
    import sys
    from dataclasses import replace

    import numpy as np

    if args.steps < 1 or args.beams < 1 or args.obstacles < 0 or args.patch < 0:
        print(
            "navlearn world show: --steps and --beams must be >= 1, --obstacles and --patch >= 0",
            file=sys.stderr,
        )
        return 2
    from agents.shield import ScanPolicy
    from worlds.config import LEARNING_NAV, NavConfig, ObstacleConfig, SensorConfig
    from worlds.env import NavigationEnv
    from worlds.heuristics import goal_seeking_policy
    from worlds.outcomes import OUTCOME_NAMES
    from worlds.perception import frame_layout
    from worlds.render import draw_patch, draw_robot
    from worlds.tasks import parse_map_spec

    if args.known_map and not (args.policy or args.learning):
        print("navlearn world show: --known-map needs a subgoal to plan: give --policy or --learning",
              file=sys.stderr)  # fmt: skip
        return 2
    observation = LEARNING_NAV.observation if args.learning else NavConfig().observation
    if args.known_map and args.learning:
        observation = replace(observation, subgoal="known_map")
    config = NavConfig(
        sensors=LEARNING_NAV.sensors if args.learning else replace(SensorConfig(), n_beams=args.beams),
        observation=replace(observation, patch_size=args.patch),
        obstacles=ObstacleConfig(count=args.obstacles, mode=args.obstacle_mode),
        max_steps=args.steps,
        pool_size=8,
        pool_seed=args.seed,
    )
    policy = goal_seeking_policy(config)
    driver = "random" if args.random else "goal-seeking"
    try:
        if args.policy:
            from agents.evaluation.policies import GreedyMLPPolicy, PolicyFormatError, load_policy_or_baseline

            try:
                policy = load_policy_or_baseline(args.policy, config)
            except PolicyFormatError as exc:
                raise ValueError(str(exc)) from None
            if isinstance(policy, GreedyMLPPolicy):  # its env observes what it was trained to
                if args.known_map:
                    policy.use_known_map()
                config = replace(policy.nav_config(config), obstacles=config.obstacles)
                policy.use_shield(config if args.shield else None)
            elif args.known_map and not args.learning:
                raise ValueError("--known-map changes a learned policy's subgoal; the heuristic plans none")
            driver = f"policy {args.policy}"
        sampler = parse_map_spec(args.map)
        for mf in sampler.maps:
            print(mf.note)
        env = NavigationEnv(config, maps=sampler)
    except ValueError as exc:  # bad spec or map file (MapFormatError is a ValueError)
        print(f"navlearn world show: {exc}", file=sys.stderr)
        return 2
    obs, info = env.reset(seed=args.seed)
    rng = np.random.default_rng(args.seed)
    trajectory = [tuple(info["pose"][:2])]
    act = policy.scan_actor(1) if isinstance(policy, ScanPolicy) else None  # the shield's disc tracker
    done = False
    while not done:
        if args.random:
            action = int(rng.integers(config.robot.n_actions))
        elif act is not None:
            action = int(act(obs[None], env.batch.rays, np.array([len(trajectory) == 1]))[0])
        else:
            action = int(policy(obs[None])[0])
        obs, _, terminated, truncated, info = env.step(action)
        trajectory.append(tuple(info["pose"][:2]))
        done = terminated or truncated
    task = env.batch.task(0)
    title = (
        f"{task.map_id}: {OUTCOME_NAMES[info['outcome']]} after {info['steps']} steps, "
        f"{info['path_length']:.1f} m ({driver} robot)"
    )
    fig = draw_robot(None, env.batch, 0, trajectory, title=title)
    if args.patch:
        start, stop = frame_layout(config)["patch"]
        draw_patch(fig, obs[start:stop], args.patch)
    try:
        fig.savefig(args.out, dpi=120, bbox_inches="tight")
    except OSError as exc:
        print(f"navlearn world show: cannot write {args.out}: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: {title}")
    return 0
