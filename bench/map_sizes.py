"""Navigation against map size: does a policy hold on bigger maps? (issue 39)

For every map side in ``--sizes`` (default 16, 32, 48, 64 cells of 1 m) two sets of the shared
evaluation (:func:`agents.evaluation.make_eval_set`, generated maps of the ``mixed`` families, never
trained on): ``static`` and ``dynamic`` with moving discs - 4 up to 32 cells, then scaled with the
area (:func:`discs_for`: 9 at 48, 16 at 64). On the same episodes (same maps, starts, goals, seeds)
it runs the policy (default the shipped ``pretrained/nnql``, through its reading shield and the
shield's disc tracker as ``navlearn evaluate`` runs it; its network without the shield: row
``network``; the shield without its tracker: row ``one_frame``), the subgoal
follower (``follower``: turn towards the own map's subgoal through the same shield, the classical
mapless planner; :func:`worlds.heuristics.subgoal_scores`), the goal-seeking heuristic and the A*
expert (lattice A* on the true map, the demonstrations' source;
``--expert-episodes`` caps its episodes per set, it is the slow one) and prints per set: success
with its 95% Wilson interval, SPL, static / dynamic collisions, timeouts, and the exact McNemar
p-value of the policy against each baseline on the episodes both ran. Episodes run in the world's
default step rule (what a user gets), stated in the JSON.

It also measures the world's throughput against map size: robot-steps per CPU-second of
``NavigationVectorEnv`` (one thread, 16 robots, the policy's observation with its own-map subgoal,
the heuristic driving) - the own map and its A* grow with the map.

    python -m bench.map_sizes                               # test seed 0, 500 episodes per set
    python -m bench.map_sizes --seed 1 --episodes 200       # the validation seed (for tuning)
    python -m bench.map_sizes --out results/navigation/map_sizes   # + JSON lines and a PNG
    python -m bench.map_sizes --map office.yaml arena.map --episodes 200   # per map file
    python -m bench.map_sizes --map tb3_world.yaml,radius=0.105            # a map for a smaller robot
    python -m bench.map_sizes --known-map --out results/navigation/map_sizes_known_map   # given the map

With ``--map`` it runs the same three on map files instead (static, the sets of
:func:`agents.evaluation.make_map_eval_set`: a MovingAI map's own ``.scen`` pairs, else pairs drawn
reachable for the robot, as ``navlearn evaluate --map``), one row per file and method; ``--episodes``
is the most per file (a ``.scen`` with fewer pairs gives fewer, stated in the row).

With ``--known-map`` the robot is given its map: the policy's subgoal (and the follower's) is
planned on the true map instead of the map the robot builds from its readings
(:meth:`agents.evaluation.policies.GreedyMLPPolicy.use_known_map`), what a user who has the map gets.

Human lines, then one JSON object on the last line. Tune on ``--seed 1`` only; seed 0 is the test
seed the figures are reported on.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from agents.evaluation import evaluate, make_eval_set, make_map_eval_set
from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import rate, summarize
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import EvalSet, fixed_sampler
from agents.planning.expert import Expert
from worlds.config import NavConfig, ObstacleConfig
from worlds.env import NavigationEnv
from worlds.heuristics import goal_seeking_policy, subgoal_scores
from worlds.outcomes import Outcome
from worlds.perception import frame_layout
from worlds.tasks import parse_map_spec
from worlds.vector_env import NavigationVectorEnv

METHODS = ("policy", "network", "one_frame", "previous", "follower", "heuristic", "expert")
THROUGHPUT_ROBOTS = 16


def step_rule(nav: NavConfig) -> str:
    """The episodes' step limit in words (:func:`worlds.config.step_limit`)."""
    if nav.step_factor <= 0:
        return f"step limit {nav.max_steps}"
    return f"step limit max({nav.max_steps}, ceil({nav.step_factor:g} x the A* path's steps))"


def knowing(known_map: bool) -> str:
    """What the robot knows of the map, in words (``--known-map``)."""
    return "the robot given the map" if known_map else "the robot mapping as it goes"


def discs_for(size: int) -> int:
    """Moving discs of the dynamic set at ``size`` cells a side: 4 up to 32 cells (the dynamic set's
    crowd, as on 16x16 maps), then 4 per 32x32 cells of area (9 at 48, 16 at 64)."""
    return max(4, round(4 * (size / 32) ** 2))


def eval_sets(size: int, episodes: int, seed: int) -> dict[str, EvalSet]:
    """The static and dynamic sets of one size (same maps and episodes)."""
    static = make_eval_set("unseen", episodes, seed=seed, size=size)
    dynamic = make_eval_set(
        "dynamic", episodes, seed=seed, size=size, obstacles=ObstacleConfig(count=discs_for(size))
    )
    return {"static": static, "dynamic": dynamic}


def named_set(what: str, episodes: int, seed: int) -> EvalSet:
    """The set ``what`` names: ``static:SIZE`` or ``dynamic:SIZE`` (generated maps, the discs of
    :func:`discs_for`) or a map file (its pairs, :func:`agents.evaluation.make_map_eval_set`)."""
    if what.startswith(("static:", "dynamic:")):
        kind, size = what.split(":")
        family = "unseen" if kind == "static" else "dynamic"
        discs = ObstacleConfig(count=discs_for(int(size)))
        return make_eval_set(family, episodes, seed=seed, size=int(size), obstacles=discs)
    return make_map_eval_set(what, episodes, seed=seed)


def run_expert(eval_set: EvalSet, nav: NavConfig, limit: int) -> dict[str, np.ndarray]:
    """The expert on the first ``limit`` episodes of ``eval_set``: outcome, path length, steps."""
    config = replace(nav, obstacles=eval_set.obstacles)
    n = min(limit, len(eval_set))
    env = NavigationEnv(config, maps=fixed_sampler(eval_set.tasks[:n], f"bench:{eval_set.family}"))
    expert = Expert(config)
    outcome, length, steps = np.zeros(n, np.int64), np.zeros(n), np.zeros(n, np.int64)
    for i, (task, seed) in enumerate(zip(eval_set.tasks[:n], eval_set.seeds[:n], strict=True)):
        obs, info = env.reset(seed=seed, options={"task": task})
        expert.reset(task, info["pose"])
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert.act(info["pose"], obs))
            done = terminated or truncated
        outcome[i], length[i], steps[i] = int(info["outcome"]), float(info["path_length"]), int(info["steps"])
    env.close()
    return {"outcome": outcome, "length": length, "steps": steps}


def episode_arrays(result, name: str) -> dict[str, np.ndarray]:
    eps = result.episodes[name]
    return {
        "outcome": np.array([e.outcome for e in eps]),
        "length": np.array([e.path_length for e in eps]),
        "steps": np.array([e.steps for e in eps]),
    }


def figures(arrays: dict[str, np.ndarray], shortest: np.ndarray) -> dict:
    n = len(arrays["outcome"])
    m = summarize(arrays["outcome"], shortest[:n], arrays["length"], arrays["steps"], np.zeros(n))
    return {
        "episodes": n,
        "success": m.success.value,
        "success_ci": [m.success.low, m.success.high],
        "spl": m.spl,
        "collision_static": m.collision_static.value,
        "collision_dynamic": m.collision_dynamic.value,
        "timeout": m.timeout.value,
        "path_ratio": m.path_ratio,
        "steps_to_goal": m.time_to_goal,
    }


def paired_p(a: np.ndarray, b: np.ndarray) -> dict:
    """McNemar on the episodes both ran (the first ``min(len)``): only a / only b / p."""
    n = min(len(a), len(b))
    sa, sb = a[:n] == int(Outcome.GOAL), b[:n] == int(Outcome.GOAL)
    a_only, b_only = int((sa & ~sb).sum()), int((~sa & sb).sum())
    return {"episodes": n, "only_policy": a_only, "only_other": b_only, "p": mcnemar_exact(a_only, b_only)}


def throughput(nav: NavConfig, size: int, seconds: float, seed: int, maps=None) -> dict:
    """Robot-steps per CPU-second of the world at ``size`` (or on ``maps``, a spec or sampler; one
    thread, the heuristic driving)."""
    config = replace(nav, obstacles=ObstacleConfig(count=0))
    maps = f"mixed:{size}" if maps is None else maps
    env = NavigationVectorEnv(THROUGHPUT_ROBOTS, config, maps=maps, seed=seed, threads=1)
    heuristic, width = goal_seeking_policy(config), config.sensors.n_beams + 3
    obs, _ = env.reset(seed=seed)
    for _ in range(3):
        obs, *_ = env.step(heuristic(obs[:, :width]))
    steps, ended = 0, 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    while time.perf_counter() - wall0 < seconds:
        obs, _, terminated, truncated, _ = env.step(heuristic(obs[:, :width]))
        ended += int(np.count_nonzero(terminated | truncated))
        steps += THROUGHPUT_ROBOTS
    cpu = time.process_time() - cpu0
    env.close()
    return {"robot_steps_per_cpu_s": steps / cpu, "robot_steps": steps, "episodes_ended": ended}


@dataclass
class Methods:
    """What the bench runs on every episode: the policy (in its own observation and ``nav``, whose
    step rule everything shares; through its reading shield unless ``--no-shield``), the same network
    without the shield when the policy has one (``network``: what the shield adds, paired) and
    through the one-frame shield without its disc tracker (``one_frame``: what the tracker adds), the
    goal-seeking heuristic, when given a previous policy (shielded like the policy) and, when the
    policy observes a subgoal and acts through its shield, the subgoal follower (``follower``:
    :func:`worlds.heuristics.subgoal_scores` through the same shield, the classical mapless planner:
    what the own map's plan gives without the network)."""

    policy: object
    nav: NavConfig
    previous: object | None = None
    network: object | None = None
    one_frame: object | None = None

    def runs(self, es: EvalSet, expert_episodes: int) -> dict[str, dict[str, np.ndarray]]:
        """Outcome, path length and steps per episode of each method on ``es`` (the expert on the
        first ``expert_episodes``)."""
        heuristic, width = goal_seeking_policy(self.nav), self.nav.sensors.n_beams + 3
        runs = {
            "policy": episode_arrays(evaluate(self.policy, es, self.nav), es.family),
            **(
                {"network": episode_arrays(evaluate(self.network, es, self.nav), es.family)}
                if self.network
                else {}
            ),
            **(
                {"one_frame": episode_arrays(evaluate(self.one_frame, es, self.nav), es.family)}
                if self.one_frame
                else {}
            ),
            "heuristic": episode_arrays(evaluate(lambda o: heuristic(o[:, :width]), es, self.nav), es.family),
        }
        shield = getattr(self.policy, "shield", None)
        if shield is not None and "subgoal" in frame_layout(self.nav):
            scores = subgoal_scores(self.nav)  # in the policy's observation (self.nav), as the policy
            follower = evaluate(shield.over(scores), es, self.nav)
            runs["follower"] = episode_arrays(follower, es.family)
        if self.previous is not None:  # its own observation, the same episodes and step rule
            own = replace(
                self.previous.nav_config(), max_steps=self.nav.max_steps, step_factor=self.nav.step_factor
            )
            runs["previous"] = episode_arrays(evaluate(self.previous, es, own), es.family)
        if expert_episodes > 0:
            runs["expert"] = run_expert(es, self.nav, expert_episodes)
        return runs


def header(first: str) -> str:
    """The column heads of the rows :func:`compare_on` prints after ``first``."""
    return (f"{first} {'method':<9} {'n':>4} {'success % [95% CI]':<20} {'SPL':>5} "
            f"{'coll.st%':>8} {'coll.dyn%':>9} {'timeout%':>8} {'p vs policy':>11}")  # fmt: skip


def compare_on(es: EvalSet, methods: Methods, expert_episodes: int, label: str) -> dict:
    """Every method on ``es``: its figures and, for the others, McNemar against the policy on the
    episodes both ran; one printed row per method, starting with ``label``."""
    rows = {}
    runs = methods.runs(es, expert_episodes)
    for name, arrays in runs.items():
        rows[name] = figures(arrays, es.shortest)
        if name != "policy":
            rows[name]["paired"] = paired_p(runs["policy"]["outcome"], arrays["outcome"])
        r = rows[name]
        p = f"{r['paired']['p']:11.2g}" if "paired" in r else f"{'':>11}"
        print(f"{label} {name:<9} {r['episodes']:>4} {100 * r['success']:5.1f} "
              f"[{100 * r['success_ci'][0]:4.1f}, {100 * r['success_ci'][1]:5.1f}] {r['spl']:5.2f} "
              f"{100 * r['collision_static']:8.1f} {100 * r['collision_dynamic']:9.1f} "
              f"{100 * r['timeout']:8.1f} {p}", flush=True)  # fmt: skip
    if "expert" in runs:  # the bar: the policy where the expert succeeds
        rows["policy"]["where_expert_succeeds"] = where_solved(
            runs["policy"]["outcome"], runs["expert"]["outcome"]
        )
        w = rows["policy"]["where_expert_succeeds"]
        print(f"{label} policy on the {w['episodes']} episodes the expert solved: {100 * w['success']:.1f}% "
              f"[{100 * w['success_ci'][0]:.1f}, {100 * w['success_ci'][1]:.1f}]")  # fmt: skip
    return rows


def where_solved(policy: np.ndarray, expert: np.ndarray) -> dict:
    """The policy's success with its Wilson interval on the episodes (of those both ran) the expert
    reached the goal in."""
    n = min(len(policy), len(expert))
    solved = expert[:n] == int(Outcome.GOAL)
    solved_rate = rate(int((policy[:n][solved] == int(Outcome.GOAL)).sum()), int(solved.sum()))
    return {
        "episodes": int(solved.sum()),
        "success": solved_rate.value,
        "success_ci": [solved_rate.low, solved_rate.high],
    }


def report_head(args: argparse.Namespace, methods: Methods, bench: str) -> dict:
    """What every report of this bench starts with: the run's command-line choices, the load and date."""
    return {
        "bench": bench,
        "policy": str(Path(args.policy)),
        "policy_name": f"{Path(args.policy).name} (v{methods.policy.version})",
        "seed": args.seed,
        "episodes": args.episodes,
        "expert_episodes": args.expert_episodes,
        "shield": args.shield,
        "known_map": args.known_map,
        "load_average_before": os.getloadavg()[0],
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }


def run_maps(args: argparse.Namespace, methods: Methods) -> int:
    """``--map``: the policy, the heuristic and the expert on each map file's own set (static)."""
    report: dict = {
        **report_head(args, methods, "map_sizes --map"),
        "step_rule": step_rule(methods.nav),
        "maps": {},
    }
    print(f"{report['policy_name']} on map files: seed {args.seed}, at most {args.episodes} episodes per "
          f"map (expert {args.expert_episodes}), {report['step_rule']}, {knowing(args.known_map)}, "
          f"load {report['load_average_before']:.1f}")  # fmt: skip
    sets = []
    for spec in args.map:
        try:
            sampler = parse_map_spec(spec)
            es = make_map_eval_set(sampler, args.episodes, seed=args.seed)
        except ValueError as exc:
            print(f"bench.map_sizes: {exc}", file=sys.stderr)
            return 2
        note = "; ".join(mf.note for mf in sampler.maps)
        print(note)
        sets.append((spec, es, note))
    label = max(len(es.family) for _, es, _ in sets)
    print(header(f"{'map':<{label}}"))
    for spec, es, note in sets:
        started = time.perf_counter()
        rows = compare_on(es, methods, args.expert_episodes, f"{es.family:<{label}}")
        rows["note"] = note
        rows["astar_m"] = {"mean": float(es.shortest.mean()), "max": float(es.shortest.max())}
        rows["wall_s"] = time.perf_counter() - started
        report["maps"][spec] = rows
    report["load_average_after"] = os.getloadavg()[0]
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "maps.json").write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps(report))
    return 0


def plot(report: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = report["sizes"]
    rows = report["results"]
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.8))
    styles = {"policy": "o-", "previous": "d-.", "follower": "x-.", "heuristic": "s--", "expert": "^:"}
    for name, style in styles.items():
        for kind, colour in (("static", "C0"), ("dynamic", "C3")):
            ys = [
                rows[str(s)][kind][name]["success"] if name in rows[str(s)][kind] else np.nan for s in sizes
            ]
            axes[0].plot(sizes, ys, style, color=colour, label=f"{name}, {kind}")
            ys = [rows[str(s)][kind][name]["spl"] if name in rows[str(s)][kind] else np.nan for s in sizes]
            axes[1].plot(sizes, ys, style, color=colour)
    for kind, colour in (("static", "C0"), ("dynamic", "C3")):
        pol = [rows[str(s)][kind]["policy"] for s in sizes]
        axes[2].plot(sizes, [p["collision_static"] + p["collision_dynamic"] for p in pol], "o-", color=colour,
                     label=f"collisions, {kind}")  # fmt: skip
        axes[2].plot(sizes, [p["timeout"] for p in pol], "x--", color=colour, label=f"timeouts, {kind}")
    axes[3].plot(
        sizes, [report["throughput"][str(s)]["robot_steps_per_cpu_s"] for s in sizes], "o-", color="k"
    )
    axes[0].set(title="success", xlabel="map side (cells of 1 m)", ylim=(0, 1.02))
    axes[1].set(title="SPL", xlabel="map side (cells of 1 m)", ylim=(0, 1.02))
    axes[2].set(title=f"{report['policy_name']}: failures", xlabel="map side (cells of 1 m)")
    axes[3].set(title="world: robot-steps per CPU-second", xlabel="map side (cells of 1 m)", ylim=(0, None))
    axes[0].legend(fontsize=7, loc="lower left")
    axes[2].legend(fontsize=7)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.set_xticks(sizes)
    fig.suptitle(f"{report['policy_name']} against map size, seed {report['seed']}, "
                 f"{report['episodes']} episodes per set", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--policy", default="pretrained/nnql", help="saved policy directory")
    parser.add_argument(
        "--previous", help="another saved policy run on the same episodes, in its own observation (paired)"
    )
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 48, 64], help="map sides (cells)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per set")
    parser.add_argument(
        "--expert-episodes", type=int, default=500, help="the expert's episodes per set (0: none)"
    )
    parser.add_argument("--seed", type=int, default=0, help="evaluation seed (0: test, 1: validation)")
    parser.add_argument("--throughput-seconds", type=float, default=5.0, help="seconds per size (0: skip)")
    parser.add_argument("--max-steps", type=int, help="least step limit of an episode (default: the world's)")
    parser.add_argument(
        "--step-factor",
        type=float,
        help="step limit = max(max steps, step factor x the A* path's steps); default the world's "
        "(worlds.config.NavConfig.step_factor); 0: a fixed --max-steps",
    )
    parser.add_argument(
        "--map",
        nargs="+",
        help="map files (map_server .yaml, MovingAI .map, ASCII; key=value options as `evaluate --map`): "
        "one row per file instead of the size sweep",
    )
    parser.add_argument("--out", help="directory for map_sizes.json and map_sizes.png (--map: maps.json)")
    parser.add_argument(
        "--shield",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="act through the reading shield and its disc tracker (agents.shield), as `navlearn evaluate` "
        "does; with it the same network is also run without the shield (row 'network') and without the "
        "tracker (row 'one_frame'), paired",
    )
    parser.add_argument(
        "--known-map",
        action="store_true",
        help="give the robot its map (`navlearn evaluate --known-map`): the policy's, its network's and the "
        "follower's subgoal planned on the true map instead of the robot's own map",
    )
    args = parser.parse_args(argv)

    def loaded():  # the policy as this run gives it its map
        policy = load_policy(args.policy)
        return policy.use_known_map() if args.known_map else policy

    policy = loaded()
    nav = policy.nav_config()
    if args.max_steps:
        nav = replace(nav, max_steps=args.max_steps)
    if args.step_factor is not None:
        nav = replace(nav, step_factor=args.step_factor)
    previous = load_policy(args.previous) if args.previous else None
    if previous is not None and args.known_map:
        previous.use_known_map()
    if args.shield:  # both policies as `navlearn evaluate` runs them; the network alone beside them
        policy.use_shield(nav)
        if previous is not None:
            previous.use_shield(previous.nav_config())
    network = loaded() if args.shield else None
    one_frame = loaded().use_shield(nav, track_discs=False) if args.shield else None
    methods = Methods(policy, nav, previous, network, one_frame)
    if args.map:
        return run_maps(args, methods)
    report: dict = {
        **report_head(args, methods, "map_sizes"),
        "previous": args.previous,
        "sizes": args.sizes,
        "discs": {str(s): discs_for(s) for s in args.sizes},
        "max_steps": nav.max_steps,
        "step_factor": nav.step_factor,
        "results": {},
        "throughput": {},
    }
    print(f"{report['policy_name']} against map size: seed {args.seed}, {args.episodes} episodes per set "
          f"(expert {args.expert_episodes}), {step_rule(nav)}, "
          f"{knowing(args.known_map)}, "
          f"load {report['load_average_before']:.1f}")  # fmt: skip
    print(header(f"{'size':>4} {'set':<8}"))
    for size in args.sizes:
        started = time.perf_counter()
        per_set: dict = {}
        for kind, es in eval_sets(size, args.episodes, args.seed).items():
            per_set[kind] = compare_on(es, methods, args.expert_episodes, f"{size:>4} {kind:<8}")
        per_set["wall_s"] = time.perf_counter() - started
        report["results"][str(size)] = per_set
    if args.throughput_seconds > 0:
        for size in args.sizes:
            row = throughput(nav, size, args.throughput_seconds, args.seed)
            report["throughput"][str(size)] = row
            print(f"world at {size}x{size}: {row['robot_steps_per_cpu_s']:,.0f} robot-steps per CPU-second "
                  f"(one thread, {THROUGHPUT_ROBOTS} robots, heuristic driving)")  # fmt: skip
    report["load_average_after"] = os.getloadavg()[0]
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "map_sizes.json").write_text(json.dumps(report, indent=1) + "\n")
        if report["throughput"]:
            print(f"wrote {plot(report, out / 'map_sizes.png')}")
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
