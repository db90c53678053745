"""The observation ablation (issue 14): what must the robot perceive for NNQL to navigate?

Same NNQL (``navlearn train --local``'s code and default hyper-parameters), same budget of
robot-steps, several seeds, one observation per variant:

    A  today's: 8 beams, goal distance and bearing, one frame
    B  sector minima: 24 sectors, each the minimum of 4 of 96 exactly cast rays
    C  B + frame stack of 3 + previous action (one-hot)
    D  B + subgoal from the robot's own map (A* on what its rays have seen, unknown free)
    E  D + C
    E+geo  E trained with the geodesic progress reward in place of the straight-line one
    B+geo, D+geo  B and D with that reward (which part of E+geo helps: the reward, the subgoal?)
    F  B + a 16x16 egocentric patch of the robot's own map (occupancy, visits) read by a small CNN
       beside the MLP (agents.nnql.patch_network; no subgoal: learning alone)
    F+geo  F with the geodesic progress reward
    Fg+geo  F+geo with the goal also drawn into the CNN's input (PatchConfig.goal: one more image
          channel, the observation's goal at its place in the patch): the same observation
    Fge+geo  Fg+geo with the CNN's 800 features embedded in 64 before the head (PatchConfig.embed)
    Fgea+geo  Fge+geo with the action-local branch (PatchConfig.window=3): one MLP shared by the
          actions adds to each action's Q what it makes of the 7 readings around its heading and the
          goal seen from it
    G, G+geo  B and B+geo with NNQL's retired recurrent Q: measured, no longer run here (their
          figures: docs/notebook.md, results/perception/)

Each run keeps its best weights on the validation set (seed 1, periodic evaluations of
``--val-episodes``), then is evaluated on the validation set (seed 1) and on the test sets
(seed 0: unseen static maps and the same with 4 moving discs), ``--episodes`` each. The
hand-written goal-seeking heuristic runs on the same episodes. Reported per variant: success
[Wilson 95%] per seed and pooled, McNemar's exact test (paired, same episodes) against A, D+geo
(the default) and the heuristic for each seed, per map family (rects, discs, rooms), collisions
(static/dynamic), timeouts, SPL, path ratio to A*, robot-steps and wall time to reach 90%
validation success during training. The best variant by mean validation success is named.

Each (variant, seed) run writes ``OUT/<variant>-s<seed>/result.json`` and is skipped when that
file exists, so the runs can be split across processes and the report re-made from them; a run
directory whose training finished (summary.json) with the same settings is evaluated, not retrained:

    python bench/perception.py --steps 200000 --seeds 0 1 2            # human lines, JSON last
    python bench/perception.py --variants A B --seeds 0 --steps 20000   # a smoke run

``--bc`` adds behaviour cloning on the expert's demonstrations in each distinct observation of the
variants (rows ``BC:<variant>``; does the observation carry what the expert acts on?), ``--expert``
the expert itself (A* on the true map) on the same episodes:

    python bench/perception.py --variants A B C D E F --seeds 0 1 2 --bc --expert --cached-only

``--screen`` trains and evaluates on the validation set only (seed 1; runs in ``OUT/screen``), so
settings are chosen without looking at the test seed; use training seeds no reported run uses:

    python bench/perception.py --screen --variants F+geo Fg+geo --seeds 10 --steps 200000
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import wilson_interval
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import EvalResult, EvalSet, evaluate, make_eval_set
from agents.imitation.config import ImitationConfig
from agents.imitation.train import train_policy
from agents.nnql.config import NNQLConfig, PatchConfig
from agents.nnql.policy import NNQLPolicy
from agents.nnql.train_local import LocalTrainConfig, train_local
from agents.planning.demonstrate import generate_demos
from bench._common import parse_overrides
from bench.planning import expert_outcomes
from worlds.config import (
    LEARNING_NAV,
    LEGACY_OBSERVATION,
    NavConfig,
    ObservationConfig,
    RewardConfig,
    SensorConfig,
    observation_settings,
    with_observation,
)
from worlds.heuristics import goal_seeking_policy
from worlds.outcomes import Outcome
from worlds.tasks import MIXED_FAMILIES

SECTORS = SensorConfig(n_beams=24, n_rays=96)
HISTORY = {"previous_action": True, "frame_stack": 3}
VARIANTS: dict[str, NavConfig] = {
    "A": with_observation(NavConfig(), LEGACY_OBSERVATION),
    "B": NavConfig(sensors=SECTORS),
    "C": NavConfig(sensors=SECTORS, observation=ObservationConfig(**HISTORY)),
    "D": NavConfig(sensors=SECTORS, observation=ObservationConfig(subgoal="own_map")),
    "E": NavConfig(sensors=SECTORS, observation=ObservationConfig(subgoal="own_map", **HISTORY)),
    "E+geo": NavConfig(
        sensors=SECTORS,
        observation=ObservationConfig(subgoal="own_map", **HISTORY),
        rewards=RewardConfig(progress=0.0, geodesic_progress=0.1),
    ),
}
GEODESIC = RewardConfig(progress=0.0, geodesic_progress=0.1)
VARIANTS["B+geo"] = NavConfig(sensors=SECTORS, rewards=GEODESIC)
VARIANTS["D+geo"] = replace(VARIANTS["D"], rewards=GEODESIC)
PATCH = 16
"""side of variant F's own-map patch (cells of 1 m: 8 m each way, half a 16x16 training map)"""
VARIANTS["F"] = NavConfig(sensors=SECTORS, observation=ObservationConfig(patch_size=PATCH))
VARIANTS["F+geo"] = replace(VARIANTS["F"], rewards=GEODESIC)
VARIANTS["Fg+geo"] = VARIANTS["F+geo"]
VARIANTS["Fge+geo"] = VARIANTS["F+geo"]
VARIANTS["Fgea+geo"] = VARIANTS["F+geo"]
NNQL_OPTIONS: dict[str, dict] = {
    "Fg+geo": {"patch": PatchConfig(goal=True)},
    "Fge+geo": {"patch": PatchConfig(goal=True, embed=64)},
    "Fgea+geo": {"patch": PatchConfig(goal=True, embed=64, window=3)},
}
"""each variant's NNQLConfig fields besides its Q-network (the patch CNN with a patch, else the MLP
alone, as the recorded runs)"""
PAIRED_WITH = ("A", "D+geo", "Fge+geo")
"""each run is compared (McNemar, same seed, same episodes) with the runs of these variants when present
(Fge+geo: the no-planner variant each later one adds to)"""
SETS = (("validation", "unseen", 1), ("test", "unseen", 0), ("test_dynamic", "dynamic", 0))


def mcnemar(a: np.ndarray, b: np.ndarray) -> dict:
    """McNemar's exact test on paired successes: discordant counts and the two-sided p-value."""
    only_a, only_b = int((a & ~b).sum()), int((~a & b).sum())
    return {"only_first": only_a, "only_second": only_b, "p": mcnemar_exact(only_a, only_b)}


def successes(result: EvalResult, family: str) -> np.ndarray:
    return np.array([r.outcome == Outcome.GOAL for r in result.episodes[family]])


def per_family(ok: np.ndarray, es: EvalSet) -> dict[str, float]:
    """Success rate per map family (rects, discs, rooms) of per-episode successes ``ok`` on ``es``."""
    families = np.array(es.map_families)
    return {f: float(ok[families == f].mean()) for f in MIXED_FAMILIES}


def summary(result: EvalResult, es: EvalSet) -> dict:
    """Success [Wilson], per map family, outcome rates, SPL and path ratio of one evaluated set."""
    m, ok = result.metrics[es.family], successes(result, es.family)
    return {
        "success": m.success.value,
        "ci": [m.success.low, m.success.high],
        "per_family": per_family(ok, es),
        "collision_static": m.collision_static.value,
        "collision_dynamic": m.collision_dynamic.value,
        "timeout": m.timeout.value,
        "spl": m.spl,
        "path_ratio": m.path_ratio if math.isfinite(m.path_ratio) else None,
    }


def evaluate_sets(policy, nav: NavConfig, sets: dict) -> dict[str, EvalResult]:
    return {name: evaluate(policy, es, config=nav) for name, es in sets.items()}


def scored(results: dict[str, EvalResult], sets: dict) -> dict:
    """Summaries, per-episode successes and path ratios to A* (None where it failed) of each set."""
    return {
        "sets": {name: summary(results[name], es) for name, es in sets.items()},
        "episodes": {name: successes(results[name], es.family).tolist() for name, es in sets.items()},
        "path_ratios": {
            name: [
                r.path_length / r.shortest if r.outcome == Outcome.GOAL else None
                for r in results[name].episodes[es.family]
            ]
            for name, es in sets.items()
        },
    }


def joint_path_ratios(runs: dict[str, list[dict]], name: str) -> None:
    """Path / A* of each learned run on the episodes of set ``name`` that every learned variant's run
    of the same seed solved (the issue's "path ratio on jointly solved episodes"), into
    ``sets[name]["path_ratio_joint"]`` with the number of those episodes."""
    learned = [r for v, records in runs.items() if v in VARIANTS for r in records if "path_ratios" in r]
    for seed in {r["seed"] for r in learned}:
        same = [r for r in learned if r["seed"] == seed]
        joint = np.logical_and.reduce([np.array(r["episodes"][name], dtype=bool) for r in same])
        for r in same:
            ratios = [x for x, ok in zip(r["path_ratios"][name], joint, strict=True) if ok]
            r["sets"][name]["path_ratio_joint"] = float(np.mean(ratios)) if ratios else None
            r["sets"][name]["jointly_solved"] = int(joint.sum())


def to_90(curve: list[dict]) -> dict:
    """Robot-steps and wall time of the first periodic validation evaluation at >= 90% success."""
    for point in curve:
        if point.get("eval_success", 0.0) >= 0.9:
            return {"steps": point["env_steps"], "wall_s": round(point["wall_time"], 1)}
    return {"steps": None, "wall_s": None}


def label(variant: str, args) -> str:
    """The variant's name with the run's ``--nnql`` / ``--rewards`` overrides, e.g. F+geo[n_step=3]."""
    given = [*getattr(args, "nnql", []), *getattr(args, "rewards", [])]
    return f"{variant}[{','.join(given)}]" if given else variant


def run_dir(out: str | Path, name: str, seed: int) -> Path:
    """A run's directory: its result.json, and for NNQL the trained policy and curve."""
    return Path(out) / f"{name}-s{seed}"


def run_one(variant: str, seed: int, args, sets: dict) -> dict:
    out = run_dir(args.out, label(variant, args), seed)
    cached = out / "result.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    nav = VARIANTS[variant]
    nav = replace(nav, rewards=replace(nav.rewards, **getattr(args, "reward_overrides", {})))
    run = LocalTrainConfig(
        steps=args.steps, envs=16, seed=seed, out=str(out), eval_every=args.steps // 4,
        eval_episodes=args.val_episodes, final_eval_episodes=0, progress=False,
        moving_discs=0,  # the variant's nav as it is: static maps, as the recorded runs
        maps="mixed:16", eval_sizes=(16,),  # 16x16 maps and validation, as the recorded runs
    )  # fmt: skip
    network = "patch" if nav.observation.patch_size else "mlp"
    options = {"dueling": False, "network": network, **NNQL_OPTIONS.get(variant, {}),
               **getattr(args, "nnql_overrides", {})}  # fmt: skip
    nnql = NNQLConfig(seed=seed, **options)  # a plain head unless overridden
    trained = finished(out, run, nav)
    if trained is None:
        start = time.perf_counter()
        result = train_local(run, nnql, nav=nav)
        trained = {"env_steps": result.env_steps, "wall": time.perf_counter() - start,
                   "selected_version": result.selected_version, "curve": result.curve}  # fmt: skip
    policy = NNQLPolicy.load(out).greedy()
    results = evaluate_sets(policy, nav, sets)
    record = {
        "variant": label(variant, args),
        "seed": seed,
        "train_robot_steps": trained["env_steps"],
        "train_wall_s": round(trained["wall"], 1),
        "selected_version": trained["selected_version"],
        "to_90_validation": to_90(trained["curve"]),
        **scored(results, sets),
    }
    cached.write_text(json.dumps(record) + "\n")
    return record


def finished(out: Path, run: LocalTrainConfig, nav: NavConfig) -> dict | None:
    """The training record of a run directory whose training finished with these settings (its
    evaluation was cut, or it was trained by ``train_local`` elsewhere, e.g. bench/sb3_compare.py's
    NNQL run): summary.json, curve.jsonl and the saved policy's observation; None if there is none.
    Its wall time is ``train_local``'s own (without building the env)."""
    if not (out / "summary.json").is_file():
        return None
    summary = json.loads((out / "summary.json").read_text())
    same = {k: summary["run"][k] for k in ("steps", "envs", "seed", "eval_every", "eval_episodes", "maps")}
    want = {"steps": run.steps, "envs": run.envs, "seed": run.seed, "eval_every": run.eval_every,
            "eval_episodes": run.eval_episodes, "maps": run.maps}  # fmt: skip
    if same != want or NNQLPolicy.load(out).observation != observation_settings(nav):
        raise ValueError(f"{out} holds a run with other settings ({same}), not {want} in this variant")
    curve = [json.loads(line) for line in (out / "curve.jsonl").read_text().splitlines() if line.strip()]
    return {"env_steps": summary["env_steps"], "wall": summary["wall_time"],
            "selected_version": summary["selected_version"], "curve": curve}  # fmt: skip


def heuristic(sets: dict, out: Path) -> dict:
    cached = out / "heuristic.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    nav = VARIANTS["A"]
    results = evaluate_sets(goal_seeking_policy(nav), nav, sets)
    record = scored(results, sets)
    out.mkdir(parents=True, exist_ok=True)
    cached.write_text(json.dumps(record) + "\n")
    return record


BC_EPISODES = 500
"""expert episodes behaviour cloning learns from, per observation and seed: episode seeds 10,000 + 1,000 x
seed onwards, so each seed's demonstrations are its own (none of the evaluation sets' maps)"""
BC_CONFIG = {"batch_size": 32, "patience": 30, "max_epochs": 400, "val_fraction": 0.25}
"""ImitationConfig of the clones: bench/nirl.py's behaviour-cloning baseline"""


def bc_variants(variants: list[str]) -> dict[str, str]:
    """One behaviour-cloning run per distinct observation among ``variants``: name -> the variant
    whose observation it clones (the first of VARIANTS' order with it; the reward plays no part)."""
    seen: dict[str, str] = {}
    for v in VARIANTS:
        key = json.dumps(observation_settings(VARIANTS[v]), sort_keys=True)
        if v in variants and key not in seen:
            seen[key] = v
    return {f"BC:{v}": v for v in seen.values()}


def run_bc(name: str, variant: str, seed: int, out: Path, sets: dict) -> dict:
    """Behaviour cloning on BC_EPISODES expert episodes recorded in ``variant``'s observation: does
    the observation carry what the expert (planning on the true map) acts on? Its ``train_wall_s`` is
    recording the demonstrations and training. Cached in OUT/<name>-s<seed>/result.json."""
    cached = run_dir(out, name, seed) / "result.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    nav = VARIANTS[variant]
    start = time.perf_counter()
    demos, _ = generate_demos("mixed:16", BC_EPISODES, seed=10_000 + 1_000 * seed, config=nav)
    trained = train_policy(
        demos, ImitationConfig(seed=seed, **BC_CONFIG), n_actions=nav.robot.n_actions,
        observation=observation_settings(nav),
    )  # fmt: skip
    wall = time.perf_counter() - start
    record = {"variant": name, "seed": seed, "train_robot_steps": 0, "train_wall_s": round(wall, 1),
              "demo_episodes": len(demos), "demo_steps": int(sum(len(d) for d in demos)),
              "bc_epochs": len(trained.history), "to_90_validation": None}  # fmt: skip
    record.update(scored(evaluate_sets(trained.policy(), nav, sets), sets))
    cached.parent.mkdir(parents=True, exist_ok=True)
    cached.write_text(json.dumps(record) + "\n")
    return record


def expert(sets: dict, out: Path) -> dict:
    """The expert (A* on the true map, the demonstrations' source) on the same episodes, as a run
    with seed None; cached in OUT/expert.json. SPL and path ratio are not measured for it."""
    cached = out / "expert.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    record: dict = {"variant": "expert", "seed": None, "train_wall_s": None, "train_robot_steps": 0,
                    "to_90_validation": None, "sets": {}, "episodes": {}}  # fmt: skip
    for name, es in sets.items():
        outcomes = np.array(expert_outcomes(es, VARIANTS["D+geo"]))
        ok = outcomes == Outcome.GOAL
        record["episodes"][name] = ok.tolist()
        record["sets"][name] = {
            "success": float(ok.mean()),
            "ci": list(wilson_interval(int(ok.sum()), len(ok))),
            "per_family": per_family(ok, es),
            "collision_static": float(np.mean(outcomes == Outcome.COLLISION_STATIC)),
            "collision_dynamic": float(np.mean(outcomes == Outcome.COLLISION_DYNAMIC)),
            "timeout": float(np.mean(outcomes == Outcome.TIMEOUT)),
            "spl": None,
            "path_ratio": None,
        }
    out.mkdir(parents=True, exist_ok=True)
    cached.write_text(json.dumps(record) + "\n")
    return record


def reference(spec: str, sets: dict, out: Path) -> tuple[str, dict]:
    """``VARIANT=DIR``: a saved policy (e.g. pretrained/nnql for D+geo) evaluated on the same episodes,
    a run of VARIANT with seed None (compared with every seed's run); cached in OUT/ref-VARIANT.json."""
    variant, _, path = spec.partition("=")
    cached = out / f"ref-{variant}.json"
    if cached.is_file():
        return variant, json.loads(cached.read_text())
    policy = load_policy(path)
    config = json.loads((Path(path) / "config.json").read_text())
    results = evaluate_sets(policy, policy.nav_config(), sets)
    record = {"variant": variant, "seed": None, "reference": str(path), "train_wall_s": None,
              "train_robot_steps": config.get("env_steps"), "to_90_validation": None}  # fmt: skip
    record.update(scored(results, sets))
    cached.write_text(json.dumps(record) + "\n")
    return variant, record


def pooled(records: list[dict], name: str) -> dict:
    """Success over every seed's episodes of set ``name`` with its Wilson interval, and the mean."""
    wins = sum(int(np.sum(r["episodes"][name])) for r in records)
    n = sum(len(r["episodes"][name]) for r in records)
    low, high = wilson_interval(wins, n)
    spl = [r["sets"][name]["spl"] for r in records if r["sets"][name]["spl"] is not None]  # none: the expert
    joint = [r["sets"][name].get("path_ratio_joint") for r in records]  # see joint_path_ratios
    return {
        "success": wins / n,
        "ci": [low, high],
        "per_seed": [r["sets"][name]["success"] for r in records],
        "per_family": {
            f: float(np.mean([r["sets"][name]["per_family"][f] for r in records])) for f in MIXED_FAMILIES
        },
        "spl": float(np.mean(spl)) if spl else None,
        "path_ratio_joint": float(np.mean(joint)) if joint and None not in joint else None,
    }


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(report["variants"])
    fig, axes = plt.subplots(1, 3, figsize=(max(13.0, 1.2 * len(names)), 4.2), sharey=True)
    lowest = min(report["variants"][v][s]["success"] for v in names for s, _, _ in SETS)
    bottom = min(0.4, math.floor(10 * lowest) / 10 - 0.1)
    for ax, set_name in zip(axes, [s for s, _, _ in SETS], strict=True):
        for x, v in enumerate(names):
            p = report["variants"][v][set_name]
            ax.bar(x, p["success"], color="tab:blue", alpha=0.6)
            ax.errorbar(x, p["success"], yerr=[[p["success"] - p["ci"][0]], [p["ci"][1] - p["success"]]],
                        color="k", capsize=3)  # fmt: skip
            ax.plot([x] * len(p["per_seed"]), p["per_seed"], "o", color="tab:orange", ms=4)
        h = report["heuristic"][set_name]["success"]
        ax.axhline(h, color="tab:red", ls="--", label=f"heuristic {h:.0%}")
        ax.axhline(0.98 if set_name != "test_dynamic" else 0.90, color="tab:green", ls=":", label="target")
        slanted = {"rotation": 45, "ha": "right"} if len(names) > 6 else {}
        ax.set_xticks(range(len(names)), names, **slanted)
        ax.set(title=set_name.replace("_", " "), ylim=(bottom, 1.0))
        ax.grid(axis="y", alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    axes[0].set_ylabel("success (bars: pooled, dots: seeds)")
    fig.suptitle(
        f"NNQL, {report['steps'] // 1000}k robot-steps per run, {report['episodes']} episodes per set"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def screen(args) -> None:
    """Validation success of each (variant, seed) run, nothing of the test sets; JSON last."""
    name, family, seed = SETS[0]
    sets = {name: make_eval_set(family, args.episodes, seed=seed)}
    args.out = str(Path(args.out) / "screen")
    report = {"steps": args.steps, "episodes": args.episodes, "runs": []}
    for v in args.variants:
        for s in args.seeds:
            r = run_one(v, s, args, sets)
            m = r["sets"][name]
            name_v = label(v, args)
            print(f"{name_v} seed {s}: validation {m['success']:.1%} [{m['ci'][0]:.1%}, {m['ci'][1]:.1%}], "
                  f"collisions {m['collision_static']:.1%}, timeouts {m['timeout']:.1%}, "
                  f"train {r['train_wall_s']:.0f} s, to 90% {r['to_90_validation']}")  # fmt: skip
            keep = ("train_wall_s", "to_90_validation")
            report["runs"].append({"variant": name_v, "seed": s, "validation": m, **{k: r[k] for k in keep}})
    print(json.dumps(report))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=200_000, help="training budget per run (robot-steps)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per evaluation set")
    parser.add_argument("--val-episodes", type=int, default=100, help="episodes of the periodic validations")
    parser.add_argument("--out", default="runs/perception", help="run directories and result files")
    parser.add_argument("--png", default="results/perception/perception.png")
    parser.add_argument(
        "--reference", nargs="*", default=[], metavar="VARIANT=DIR",
        help="saved policies evaluated on the same episodes as runs of VARIANT (e.g. D+geo=pretrained/nnql)",
    )  # fmt: skip
    parser.add_argument(
        "--cached-only", action="store_true", help="report the runs already in --out, train nothing"
    )
    parser.add_argument(
        "--screen", action="store_true",
        help="train and evaluate on the validation set only (OUT/screen): choose without the test seed",
    )  # fmt: skip
    parser.add_argument(
        "--bc", action="store_true",
        help=f"add behaviour cloning on {BC_EPISODES} expert episodes per seed in each distinct observation "
        "of --variants (rows BC:<variant>): does the observation carry what the expert acts on?",
    )  # fmt: skip
    parser.add_argument("--expert", action="store_true",
                        help="add the expert (A* on the true map) on the same episodes")  # fmt: skip
    parser.add_argument("--nnql", nargs="+", default=[], metavar="KEY=VALUE",
                        help="with --screen: NNQLConfig overrides (JSON values), e.g. n_step=3")  # fmt: skip
    parser.add_argument("--rewards", nargs="+", default=[], metavar="KEY=VALUE",
                        help="with --screen: RewardConfig overrides, e.g. collision=-3")  # fmt: skip
    args = parser.parse_args()
    args.nnql_overrides = parse_overrides(parser, args.nnql, NNQLConfig, "--nnql")
    args.reward_overrides = parse_overrides(parser, args.rewards, RewardConfig, "--rewards")
    if (args.nnql or args.rewards) and not args.screen:
        parser.error("--nnql / --rewards are screening options: add --screen (the table is of the variants)")

    start = time.perf_counter()
    if args.screen:
        screen(args)
        return
    sets = {name: make_eval_set(family, args.episodes, seed=seed) for name, family, seed in SETS}
    base = heuristic(sets, Path(args.out))
    if args.cached_only:
        done = {v: [s for s in args.seeds if (run_dir(args.out, v, s) / "result.json").is_file()]
                for v in args.variants}  # fmt: skip
        runs = {v: [run_one(v, s, args, sets) for s in seeds] for v, seeds in done.items() if seeds}
    else:
        runs = {v: [run_one(v, s, args, sets) for s in args.seeds] for v in args.variants}
    for name, variant in (bc_variants(args.variants) if args.bc else {}).items():
        seeds = [s for s in args.seeds if not args.cached_only
                 or (run_dir(args.out, name, s) / "result.json").is_file()]  # fmt: skip
        if seeds:
            runs[name] = [run_bc(name, variant, s, Path(args.out), sets) for s in seeds]
    if args.expert:
        runs["expert"] = [expert(sets, Path(args.out))]
    for spec in args.reference:
        variant, record = reference(spec, sets, Path(args.out))
        runs.setdefault(variant, []).append(record)
    for name, _, _ in SETS:
        joint_path_ratios(runs, name)
    report: dict = {"steps": args.steps, "seeds": args.seeds, "episodes": args.episodes, "variants": {}}
    report["heuristic"] = base["sets"]
    for v, records in runs.items():
        entry = {name: pooled(records, name) for name, _, _ in SETS}
        entry["seeds"] = [r["seed"] for r in records]
        entry["train_wall_s"] = [r["train_wall_s"] for r in records]
        entry["to_90_validation"] = [r["to_90_validation"] for r in records]
        for name, _, _ in SETS:
            for r in records:
                r["sets"][name]["mcnemar_vs_heuristic"] = mcnemar(
                    np.array(r["episodes"][name]), np.array(base["episodes"][name])
                )
                for other in PAIRED_WITH:
                    a = next((x for x in runs.get(other, []) if x["seed"] in (r["seed"], None)), None)
                    if a is not None and other != v:
                        r["sets"][name][f"mcnemar_vs_{other}"] = mcnemar(
                            np.array(r["episodes"][name]), np.array(a["episodes"][name])
                        )
        entry["runs"] = [
            {k: r[k] for k in ("seed", "train_wall_s", "to_90_validation", "sets")} for r in records
        ]
        report["variants"][v] = entry
    learned = [v for v in report["variants"] if v in VARIANTS]  # NNQL's, not the clones or the expert
    best = max(learned, key=lambda v: report["variants"][v]["validation"]["success"])
    report["best_by_validation"] = best
    report["learning_nav_is"] = next((v for v, nav in VARIANTS.items() if nav == LEARNING_NAV), None)
    report["wall_s"] = round(time.perf_counter() - start, 1)

    print(f"NNQL, {args.steps} robot-steps per run, seeds {args.seeds}, {args.episodes} episodes per set")
    print(
        f"{'variant':<11} {'validation':<22} {'test unseen':<22} {'test dynamic':<22} "
        "rects/discs/rooms (test)"
    )
    for v, e in [*report["variants"].items(), ("heur.", None)]:
        v = v if e is None else f"{v} ({len(e['seeds'])})"
        cells = []
        for name, _, _ in SETS:
            p = e[name] if e else {**base["sets"][name]}
            cells.append(f"{p['success']:6.1%} [{p['ci'][0]:.1%},{p['ci'][1]:.1%}]")
        fam = (e or base["sets"])["test"]["per_family"]
        families = "/".join(f"{fam[f]:.0%}" for f in fam)
        print(f"{v:<11} " + " ".join(f"{c:<22}" for c in cells) + " " + families)
    for v, e in report["variants"].items():
        for r in e["runs"]:
            t = r["sets"]["test"]
            vs = "".join(f", vs {o} {t[f'mcnemar_vs_{o}']['p']:.3g}" for o in PAIRED_WITH
                         if f"mcnemar_vs_{o}" in t)  # fmt: skip
            spl = "-" if t["spl"] is None else f"{t['spl']:.2f}"
            if t.get("path_ratio_joint") is not None:
                spl += f", path/A* {t['path_ratio_joint']:.2f} on the {t['jointly_solved']} jointly solved"
            print(f"  {v} seed {r['seed']}: test {t['success']:.1%}, SPL {spl}, collisions "
                  f"{t['collision_static']:.1%}, timeouts {t['timeout']:.1%}, McNemar p vs heuristic "
                  f"{t['mcnemar_vs_heuristic']['p']:.3g}" + vs
                  + (f"; train {r['train_wall_s']:.0f} s, to 90% val {r['to_90_validation']}"
                     if r["seed"] is not None else " (not trained here)"))  # fmt: skip
    print(f"best by validation success: {best}; worlds.config.LEARNING_NAV is {report['learning_nav_is']}")
    Path(args.png).parent.mkdir(parents=True, exist_ok=True)
    plot(report, Path(args.png))
    print(json.dumps(report))


if __name__ == "__main__":
    main()
