"""NNQL recipes for moving discs: pooled success over training seeds, paired against references.

Reads the ``eval.json`` that ``navlearn evaluate --policy RUN --out DIR`` wrote for each run
(per-episode outcomes of the same seeded episodes) and reports, per group of runs (one run per
training seed), for each evaluation set: success pooled over the seeds [Wilson 95%], per seed,
per map family, static / disc collisions, timeouts, SPL and path / A* on solved episodes; then
exact McNemar tests of each group against each reference group, per seed and with the seeds
pooled (run k of a group paired with run k of the reference, or with its only run). Training
wall time and the kept version come from the run's ``summary.json`` (the eval directory's parent).

    python -m bench.disc_recipe --group base=runs/screen/base/val --group rate=runs/screen/rate/val \
        --reference base

Prints a table, then one JSON object on its last line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import wilson_interval

FAMILIES = ("rects", "discs", "rooms")
RUN_FIELDS = ("dir", "eval_seed", "wall_time", "selected_version", "env_steps")


def load_run(eval_dir: Path) -> dict:
    """Episodes per set of one evaluated run, and its training summary when there is one."""
    report = json.loads((eval_dir / "eval.json").read_text())
    summary_path = eval_dir.parent / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    return {
        "dir": str(eval_dir),
        "eval_seed": report["seed"],
        "episodes": report["episodes"],
        "wall_time": summary.get("wall_time"),
        "selected_version": summary.get("selected_version"),
        "env_steps": summary.get("env_steps"),
    }


def pooled(runs: list[dict], name: str) -> dict:
    """Success and the rest over every run's episodes of set ``name``."""
    episodes = [e for run in runs for e in run["episodes"][name]]
    n = len(episodes)
    outcome = np.array([e["outcome"] for e in episodes])
    solved = outcome == "goal"
    shortest = np.array([e["shortest"] for e in episodes])
    length = np.array([e["path_length"] for e in episodes])
    spl = float(np.mean(np.where(solved, shortest / np.maximum(length, shortest), 0.0)))
    low, high = wilson_interval(int(solved.sum()), n)
    entry = {
        "episodes": n,
        "success": float(solved.mean()),
        "ci95": [low, high],
        "per_seed": [float(np.mean([e["outcome"] == "goal" for e in r["episodes"][name]])) for r in runs],
        "collision_static": float(np.mean(outcome == "collision_static")),
        "collision_dynamic": float(np.mean(outcome == "collision_dynamic")),
        "timeout": float(np.mean(outcome == "timeout")),
        "spl": spl,
        "path_ratio": float(np.mean(length[solved] / shortest[solved])) if solved.any() else float("nan"),
    }
    families = np.array([e["map_family"] for e in episodes])
    entry["families"] = {f: float(solved[families == f].mean()) for f in FAMILIES if (families == f).any()}
    return entry


def solved_by_episode(run: dict, name: str) -> dict[int, bool]:
    return {e["seed"]: e["outcome"] == "goal" for e in run["episodes"][name]}


def paired(runs: list[dict], reference: list[dict], name: str) -> dict:
    """McNemar of ``runs`` against ``reference`` on set ``name``: per seed and pooled."""
    per_seed, a_total, b_total = [], 0, 0
    for k, run in enumerate(runs):
        ref = reference[k] if len(reference) == len(runs) else reference[0]
        mine, theirs = solved_by_episode(run, name), solved_by_episode(ref, name)
        if set(mine) != set(theirs):
            raise ValueError(f"{run['dir']} and {ref['dir']} were not evaluated on the same {name} episodes")
        a_only = sum(mine[s] and not theirs[s] for s in mine)
        b_only = sum(theirs[s] and not mine[s] for s in mine)
        per_seed.append({"only_this": a_only, "only_ref": b_only, "p": mcnemar_exact(a_only, b_only)})
        a_total, b_total = a_total + a_only, b_total + b_only
    return {
        "per_seed": per_seed,
        "pooled": {"only_this": a_total, "only_ref": b_total, "p": mcnemar_exact(a_total, b_total)},
    }


def report(groups: dict[str, list[dict]], references: list[str]) -> dict:
    sets = sorted({name for runs in groups.values() for run in runs for name in run["episodes"]})
    out = {}
    for label, runs in groups.items():
        entry = {
            "runs": [{k: r[k] for k in RUN_FIELDS} for r in runs],
            "sets": {name: pooled(runs, name) for name in sets if all(name in r["episodes"] for r in runs)},
        }
        entry["vs"] = {
            ref: {name: paired(runs, groups[ref], name) for name in entry["sets"]}
            for ref in references
            if ref != label
        }
        out[label] = entry
    return out


def print_table(result: dict) -> None:
    for label, entry in result.items():
        for name, s in entry["sets"].items():
            fam = " / ".join(f"{100 * v:.1f}" for v in s["families"].values())
            seeds = " / ".join(f"{100 * v:.1f}" for v in s["per_seed"])
            print(
                f"{label:<14} {name:<8} {100 * s['success']:5.1f}% [{100 * s['ci95'][0]:.1f}, "
                f"{100 * s['ci95'][1]:.1f}] n={s['episodes']} seeds {seeds} | families {fam} | coll "
                f"{100 * s['collision_static']:.1f}/{100 * s['collision_dynamic']:.1f}% timeout "
                f"{100 * s['timeout']:.1f}% SPL {s['spl']:.3f} path {s['path_ratio']:.3f}"
            )
            for ref, tests in entry["vs"].items():
                t = tests[name]
                per = ", ".join(f"{x['only_this']}/{x['only_ref']} p={x['p']:.2g}" for x in t["per_seed"])
                pool = t["pooled"]
                print(
                    f"{'':<14}   vs {ref}: pooled {pool['only_this']}/{pool['only_ref']} p={pool['p']:.3g}"
                    f" (per seed {per})"
                )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--group",
        action="append",
        required=True,
        metavar="LABEL=DIR[,DIR...]",
        help="a group of evaluated runs (eval directories, one per training seed)",
    )
    parser.add_argument("--reference", nargs="*", default=[], help="group labels to pair every group against")
    args = parser.parse_args()
    groups: dict[str, list[dict]] = {}
    for spec in args.group:
        label, _, dirs = spec.partition("=")
        groups[label] = [load_run(Path(d)) for d in dirs.split(",") if d]
    unknown = sorted(set(args.reference) - set(groups))
    if unknown:
        parser.error(f"--reference {unknown}: not a --group label")
    result = report(groups, args.reference)
    print_table(result)
    print(json.dumps({"groups": result}))


if __name__ == "__main__":
    main()
