"""NIRL benchmark (issue 8, thesis ch. 5): NIRL against imitation on the same demonstrations,
and NIRL's environment steps against NNQL learning from scratch.

(a) expert demonstrations on training maps (``mixed:16``): the first 5, 10 and 20 of one
    clean set, and 20 demonstrations whose every action was, with probability 0.3, a random
    wall-free one (the recorded actions are what both learners see);
(b) per set: the imitation policy (behaviour cloning, agents.imitation) and NIRL (warm start
    + ``--iterations`` rounds of neural policy iteration, ``--steps-per-iteration`` robot-steps
    each), both evaluated greedily on the same 100 unseen generated maps, static and with 4
    moving discs: success rate (95% CI) and path length ratio to A*;
(c) NNQL from scratch (``train --local`` defaults) for ``--nnql-steps`` robot-steps, its
    greedy policy evaluated on the validation set every ``--nnql-eval-every`` steps; NIRL
    (20 clean demonstrations) evaluated on the same validation set after every iteration.
    Figure: robot-steps NIRL needs to reach the validation success NNQL reaches, divided by
    the robot-steps NNQL needs for it (aim <= 1/3). Demonstration steps are reported apart.

    python -m bench.nirl            # human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from agents.evaluation import evaluate, make_eval_set
from agents.imitation.config import ImitationConfig
from agents.imitation.train import train_policy
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.train_local import train_nirl
from agents.nnql.train_local import LocalTrainConfig, train_local
from agents.planning.demonstrate import generate_demos
from worlds.config import NavConfig

FAMILIES = ("unseen", "dynamic")


def figures(result, family: str) -> dict:
    m = result.metrics[family]
    return {
        "success": round(m.success.value, 3),
        "success_ci": [round(m.success.low, 3), round(m.success.high, 3)],
        "path_ratio": None if m.path_ratio is None else round(float(m.path_ratio), 3),
        "collision_static": round(m.collision_static.value, 3),
    }


def recorded_only(demos):
    """The demonstrations as a learner sees them: the actions taken, not the expert's own labels."""
    for demo in demos:
        demo.expert_actions = None
    return demos


def first_reaching(curve: list[tuple[float, float]], target: float) -> float | None:
    """Robot-steps of the first curve point whose success reaches ``target`` (None if none does)."""
    return next((steps for steps, success in curve if success >= target - 1e-9), None)


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per map type")
    parser.add_argument(
        "--iterations", type=int, default=10, help="NIRL policy-iteration rounds per demo set"
    )
    parser.add_argument("--steps-per-iteration", type=int, default=2048, help="NIRL robot-steps per round")
    parser.add_argument("--nnql-steps", type=int, default=60_000, help="NNQL robot-steps from scratch")
    parser.add_argument("--nnql-eval-every", type=int, default=6_000, help="NNQL validation every N steps")
    parser.add_argument("--val-episodes", type=int, default=50, help="validation episodes (both curves)")
    parser.add_argument("--noise", type=float, default=0.3, help="random-action probability of the noisy set")
    parser.add_argument("--seed", type=int, default=0, help="seed of demonstrations and learners")
    parser.add_argument("--plots", default="bench/plots", help="directory for the PNG plots")
    args = parser.parse_args()
    start = time.perf_counter()
    nav = NavConfig()
    sets = [make_eval_set(f, args.episodes, seed=0) for f in FAMILIES]

    clean, _ = generate_demos("mixed:16", 20, seed=10_000 + args.seed, config=nav)
    noisy, noisy_stats = generate_demos("mixed:16", 20, seed=20_000 + args.seed, noise=args.noise, config=nav)
    injected = sum(int((d.expert_actions != d.actions).sum()) for d in noisy if d.expert_actions is not None)
    noisy_steps = sum(len(d) for d in noisy)
    print(f"demonstrations: 20 clean ({sum(len(d) for d in clean)} steps), 20 noisy ({noisy_steps} steps, "
          f"{injected} actions differ from the expert's)")  # fmt: skip
    expert_labels = np.concatenate([d.labels for d in noisy])
    conditions = {"5": clean[:5], "10": clean[:10], "20": clean, "20 noisy": recorded_only(noisy)}

    rows, curves = {}, {}
    for name, demos in conditions.items():
        t0 = time.perf_counter()
        imitation = train_policy(demos, ImitationConfig(seed=args.seed), n_actions=nav.robot.n_actions)
        im_result = evaluate(imitation.policy(), sets, nav)
        t1 = time.perf_counter()
        # the 20-demo run goes on to NNQL's budget for the learning-time curve; the table takes
        # every condition's policy after --iterations rounds
        rounds = max(args.iterations, math.ceil(args.nnql_steps / args.steps_per_iteration))
        config = NIRLConfig(
            iterations=rounds if name == "20" else args.iterations,
            steps_per_iteration=args.steps_per_iteration,
            seed=args.seed,
        )
        curve: list[tuple[float, float]] = []
        tested = {}

        def validate(point, learner, curve=curve, tested=tested):
            if "eval_success" in point:
                curve.append((point["env_steps"], point["eval_success"]))
            if learner.iteration == args.iterations:
                tested["result"] = evaluate(learner.policy(), sets, nav)
                tested["env_steps"] = int(point["env_steps"])

        run = NIRLRun(out="", eval_every=1 if name == "20" else 0, eval_episodes=args.val_episodes,
                      final_eval_episodes=0, progress=False)  # fmt: skip
        nirl = train_nirl(demos, config, run, nav, on_iteration=validate)
        nirl_result = tested["result"]
        row = {
            "demo_episodes": len(demos),
            "demo_steps": int(sum(len(d) for d in demos)),
            "nirl_env_steps": tested["env_steps"],
            "imitation": {f: figures(im_result, f) for f in FAMILIES},
            "nirl": {f: figures(nirl_result, f) for f in FAMILIES},
            "seconds": {"imitation": round(t1 - t0, 1), "nirl": round(time.perf_counter() - t1, 1)},
        }
        if name == "20 noisy":
            steps, refined = nirl.learner.refine_all()
            wrong = steps["action"].numpy() != expert_labels[: len(steps)]
            labels = refined.labels.numpy()
            row["map_refinement"] = {
                "injected_steps": int(wrong.sum()),
                "injected_relabelled_to_expert": round(
                    float((labels[wrong] == expert_labels[wrong]).mean()), 3
                ),
                "clean_kept": round(float((labels[~wrong] == steps["action"].numpy()[~wrong]).mean()), 3),
            }
        if name == "20":
            curves["nirl"] = curve
            row["nirl_curve_env_steps"] = nirl.env_steps
        rows[name] = row
        for f in FAMILIES:
            im, ni = row["imitation"][f], row["nirl"][f]
            print(f"{name:>8} demos | {f:7} | imitation {im['success']:.0%} (path/A* {im['path_ratio']}) | "
                  f"NIRL {ni['success']:.0%} (path/A* {ni['path_ratio']}) "
                  f"after {row['nirl_env_steps']} robot-steps")  # fmt: skip

    t0 = time.perf_counter()
    nnql = train_local(
        LocalTrainConfig(
            steps=args.nnql_steps,
            eval_every=args.nnql_eval_every,
            eval_episodes=args.val_episodes,
            final_eval_episodes=0,
            out="",
            seed=args.seed,
            progress=False,
        )
    )
    curves["nnql"] = [(p["env_steps"], p["eval_success"]) for p in nnql.curve if "eval_success" in p]
    nnql_seconds = time.perf_counter() - t0
    target = max(s for _, s in curves["nnql"])
    nnql_steps = first_reaching(curves["nnql"], target)
    nirl_steps = first_reaching(curves["nirl"], target)
    ratio = None if nirl_steps is None else nirl_steps / nnql_steps
    reached = (
        f"{nirl_steps:.0f}"
        if nirl_steps is not None
        else f"never within {rows['20']['nirl_curve_env_steps']}"
    )
    print(f"NNQL from scratch: best validation success {target:.0%} first at {nnql_steps:.0f} robot-steps "
          f"({nnql_seconds:.0f} s); NIRL (20 demos) reaches it at {reached} robot-steps -> ratio "
          f"{ratio if ratio is None else round(ratio, 3)}")  # fmt: skip

    plots = Path(args.plots)
    plots.mkdir(parents=True, exist_ok=True)
    plot(rows, curves, target, plots)
    best_nirl = max((s for _, s in curves["nirl"]), default=float("nan"))
    # the reverse view: robot-steps each needs to reach the best validation success NIRL reaches
    nirl_best_steps = first_reaching(curves["nirl"], best_nirl)
    nnql_to_nirl_best = first_reaching(curves["nnql"], best_nirl)
    print(f"NIRL's best validation success {best_nirl:.0%} first at {nirl_best_steps:.0f} robot-steps; "
          f"NNQL reaches it at {nnql_to_nirl_best} robot-steps")  # fmt: skip
    summary = {
        "bench": "nirl",
        "episodes": args.episodes,
        "conditions": rows,
        "noisy_demos_kept": noisy_stats.kept,
        "nnql": {"target_success": target, "steps_to_target": nnql_steps, "curve": curves["nnql"]},
        "nirl_curve": curves["nirl"],
        "nirl_best_validation_success": best_nirl,
        "nirl_steps_to_own_best": nirl_best_steps,
        "nnql_steps_to_nirl_best": nnql_to_nirl_best,
        "nirl_steps_to_nnql_target": nirl_steps,
        "steps_ratio_nirl_over_nnql": ratio,
        "aims": {
            "nirl_20_demos_success_ge_0.95": rows["20"]["nirl"]["unseen"]["success"] >= 0.95,
            "nirl_beats_imitation_on_noisy": all(
                rows["20 noisy"]["nirl"][f]["success"] > rows["20 noisy"]["imitation"][f]["success"]
                for f in FAMILIES
            ),
            "steps_ratio_le_1/3": ratio is not None and ratio <= 1 / 3,
        },
        "wall_seconds": round(time.perf_counter() - start, 1),
    }
    print(json.dumps(summary))
    return 0


def plot(rows: dict, curves: dict, target: float, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    names = list(rows)
    x = np.arange(len(names))
    for ax, family in zip(axes[:2], FAMILIES, strict=True):
        for offset, learner in ((-0.2, "imitation"), (0.2, "nirl")):
            values = [rows[n][learner][family]["success"] for n in names]
            low = [v - rows[n][learner][family]["success_ci"][0] for n, v in zip(names, values, strict=True)]
            high = [rows[n][learner][family]["success_ci"][1] - v for n, v in zip(names, values, strict=True)]
            ax.bar(x + offset, values, 0.4, yerr=[low, high], capsize=3, label=learner.upper())
        ax.set(xticks=x, xticklabels=[f"{n} demos" for n in names], ylim=(0, 1), ylabel="success rate",
               title=f"{family} maps ({'4 moving discs' if family == 'dynamic' else 'static'})")  # fmt: skip
        ax.grid(axis="y", alpha=0.3)
        ax.legend()
    ax = axes[2]
    for name, curve in curves.items():
        ax.plot(
            *zip(*curve, strict=True),
            "o-",
            ms=3,
            label=f"{name.upper()}" + (" (20 demos)" if name == "nirl" else " (scratch)"),
        )
    ax.axhline(target, ls="--", color="gray", lw=1, label="NNQL best")
    ax.set(
        xlabel="robot-steps (environment)", ylabel="validation success", ylim=(0, 1), title="learning time"
    )
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "nirl.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
