"""The table of ``python -m bench.nirl --report``: pooled success with Wilson intervals per learner
and demonstration set, McNemar's exact test of NIRL against behaviour cloning, SQIL and DQfD on the
same episodes, MAP refinement, the learned reward's scale, robot-steps to a validation success, the
grid-world check; one JSON object on the last line. The grid's names (families, demonstration sets,
learners) are defined here, where the table reads them, and imported by ``bench/nirl.py``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import wilson_interval as wilson

FAMILIES = ("unseen", "dynamic")
SETS = ("5", "10", "20", "20noisy")
METHODS = ("bc", "sqil", "dqfd", "nirl", "maxmargin", "nnql", "nnql_line", "expert")


def mcnemar(a: list[int], b: list[int]) -> tuple[int, int, float]:
    """McNemar's exact test on paired successes (agents.evaluation.compare): (only a, only b, p)."""
    only_a = sum(x and not y for x, y in zip(a, b, strict=True))
    only_b = sum(y and not x for x, y in zip(a, b, strict=True))
    return only_a, only_b, mcnemar_exact(only_a, only_b)


def paired(latest: dict, first: tuple[str, str], second: tuple[str, str], family: str) -> tuple[list, list]:
    """Per-episode outcomes of two (method, demo set) cells on the same episodes, the seeds both ran
    concatenated: (first's, second's)."""
    a, b = [], []
    for seed in range(10):
        x, y = latest.get((*first, seed)), latest.get((*second, seed))
        if x and y:
            a += x["test"][family]["solved"]
            b += y["test"][family]["solved"]
    return a, b


def first_reaching(curve, target: float):
    """Robot-steps of the first curve point (steps, success[, dynamic success]) at ``target``, or None."""
    return next((point[0] for point in curve if point[1] >= target - 1e-9), None)


def median_steps(steps: list) -> float | None:
    """Median over seeds of the robot-steps to a success level; a seed that never got there counts
    as more than any other (None when the median itself is such a seed, or there are none)."""
    if not steps:
        return None
    ordered = sorted(steps, key=lambda s: math.inf if s is None else s)
    mid = len(ordered) // 2
    pick = ordered[mid] if len(ordered) % 2 else (ordered[mid - 1], ordered[mid])
    if isinstance(pick, tuple):
        return None if None in pick else float(sum(pick) / 2)
    return None if pick is None else float(pick)


def report(path: Path) -> int:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    latest = {(r["method"], r["set"], r["seed"]): r for r in rows}  # a re-run replaces its line
    rows = list(latest.values())
    table, summary = [], {"bench": "nirl", "cells": {}}
    navs = sorted({r.get("nav", "default") for r in rows if r["method"] != "gridcheck"})
    summary["nav"] = navs
    print(f"observation: {', '.join(navs)} (rows without a record: the first table's, NavConfig())")
    print("| learner | demos | seeds | unseen success (pooled) [95% CI] | per seed "
          "| dynamic success [95% CI] |"
          " collisions (unseen) |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for method in METHODS:
        larger = sorted({r["set"] for r in rows if r["set"].isdigit() and r["set"] not in SETS}, key=int)
        for set_name in (*SETS, *larger, "-"):
            cell = [r for r in rows if r["method"] == method and r["set"] == set_name]
            if not cell:
                continue
            cell.sort(key=lambda r: r["seed"])
            entry = {"seeds": [r["seed"] for r in cell]}
            text = []
            for family in FAMILIES:
                solved = sum(sum(r["test"][family]["solved"]) for r in cell)
                n = sum(len(r["test"][family]["solved"]) for r in cell)
                low, high = wilson(solved, n)
                entry[family] = {"success": solved / n, "ci": [low, high], "n": n,
                                 "per_seed": [r["test"][family]["success"] for r in cell]}  # fmt: skip
                text.append(f"{solved / n:.1%} [{low:.1%}, {high:.1%}]")
            per_seed = " / ".join(f"{s:.0%}" for s in entry["unseen"]["per_seed"])
            collisions = np.mean([r["test"]["unseen"]["collision_static"] for r in cell])
            print(
                f"| {method} | {set_name} | {len(cell)} | {text[0]} | {per_seed} | {text[1]} "
                f"| {collisions:.0%} |"
            )
            summary["cells"][f"{method}/{set_name}"] = entry
            table.append(entry)
    # paired comparison on the same episodes: NIRL vs each learner from the same demonstrations
    # (behaviour cloning, SQIL, DQfD), same demo set and seed
    for baseline in ("bc", "sqil", "dqfd"):
        comparisons = {}
        for set_name in SETS:
            for family in FAMILIES:
                a, b = paired(latest, ("nirl", set_name), (baseline, set_name), family)
                if a:
                    only_nirl, only_other, p = mcnemar(a, b)
                    comparisons[f"{set_name}/{family}"] = {
                        "nirl": float(np.mean(a)), baseline: float(np.mean(b)), "only_nirl": only_nirl,
                        f"only_{baseline}": only_other, "p": p, "n": len(a),
                    }  # fmt: skip
                    print(f"McNemar NIRL vs {baseline.upper()}, {set_name} demos, {family}: {np.mean(a):.1%} "
                          f"vs {np.mean(b):.1%}, {only_nirl} episodes only NIRL solved, {only_other} only "
                          f"{baseline.upper()}, p = {p:.2g} (n = {len(a)})")  # fmt: skip
        summary[f"nirl_vs_{baseline}"] = comparisons
    refinement = [(r["method"], r["map_refinement"]) for r in rows if "map_refinement" in r]
    refinement += [("nirl, after policy iteration", r["map_refinement_progress"])
                   for r in rows if "map_refinement_progress" in r]  # fmt: skip
    if refinement:
        summary["map_refinement"] = refinement
        for method, item in refinement:
            print(f"MAP refinement ({method}, 20 noisy): {item['injected_relabelled_to_expert']:.1%} of "
                  f"{item['injected_steps']} injected steps relabelled to the expert's action "
                  f"({item['injected_changed']:.1%} changed), "
                  f"{item['clean_kept']:.1%} of {item['clean_steps']} clean steps kept")  # fmt: skip
    scales = [
        (r["set"], r["seed"], r["reward_scale"])
        for r in rows
        if r["method"] == "nirl" and "reward_scale" in r
    ]
    summary["reward_scale"] = scales
    scratch = ("nnql", "nnql_line")  # NNQL from scratch on the geodesic / the straight-line progress reward
    curves = {
        m: [r["curve"] for r in rows if r["method"] == m and r["set"] in ("20", "-") and "curve" in r]
        for m in ("nirl", *scratch)
    }
    summary["curves"] = curves
    learning = {}
    for target in (0.9, 0.8, 0.6, 0.5):
        steps = {m: [first_reaching(c, target) for c in curves[m]] for m in curves}
        medians = {m: median_steps(v) for m, v in steps.items()}
        entry = {**steps, "median": medians}
        for m in scratch:  # NIRL's median over NNQL's
            known = medians["nirl"] is not None and medians[m] is not None
            entry["ratio" if m == "nnql" else f"ratio_{m}"] = medians["nirl"] / medians[m] if known else None
        learning[str(target)] = entry
        shown = {m: "undefined" if entry[k] is None else f"{entry[k]:.2f}"
                 for m, k in zip(scratch, ("ratio", "ratio_nnql_line"), strict=True)}  # fmt: skip
        print(
            f"robot-steps to {target:.0%} validation success: NIRL (20 demos) {steps['nirl']}, "
            f"NNQL (geodesic reward) {steps['nnql']}, NNQL (straight-line reward) {steps['nnql_line']}; "
            f"medians {medians['nirl']} / {medians['nnql']} / {medians['nnql_line']}, "
            f"ratios {shown['nnql']} / {shown['nnql_line']}"
        )
    summary["steps_to_validation_success"] = learning
    against = {}
    for set_name in SETS:  # NIRL against NNQL from scratch on each reward, paired by seed
        for method in scratch:
            for family in FAMILIES:
                a, b = paired(latest, ("nirl", set_name), (method, "-"), family)
                if a:
                    only_nirl, only_nnql, p = mcnemar(a, b)
                    entry = {"nirl": float(np.mean(a)), method: float(np.mean(b)), "p": p}
                    against[f"{set_name}/{method}/{family}"] = entry | {
                        "only_nirl": only_nirl,
                        "only_nnql": only_nnql,
                    }
                    print(
                        f"McNemar NIRL ({set_name} demos) vs {method}, {family}: {np.mean(a):.1%} vs "
                        f"{np.mean(b):.1%}, {only_nirl} / {only_nnql}, p = {p:.2g} (n = {len(a)})"
                    )
    summary["nirl_vs_nnql"] = against
    grid = [r for r in rows if r["method"] == "gridcheck"]
    if grid:
        summary["gridcheck"] = grid
        for g in grid:
            print(f"grid world (seed {g['seed']}): re-planned under the learned reward, "
                  f"{g['agreement']:.1%} of "
                  f"{g['states']} states take a truly optimal action")  # fmt: skip

    def cell(name, family="unseen"):
        return summary["cells"].get(name, {}).get(family, {}).get("success")

    noisy = summary["nirl_vs_bc"].get("20noisy/unseen", {})
    summary["targets"] = {
        "nirl_20_clean_unseen_ge_0.95": cell("nirl/20"),
        "nirl_20_clean_dynamic_ge_0.90": cell("nirl/20", "dynamic"),
        "nirl_20_noisy_unseen_ge_0.90": cell("nirl/20noisy"),
        "nirl_minus_bc_noisy_unseen_ge_0.10": None if not noisy else noisy["nirl"] - noisy["bc"],
        "mcnemar_p_noisy_unseen_lt_0.01": noisy.get("p"),
        "gridworld_agreement_ge_0.95": [g["agreement"] for g in grid],
        "steps_to_0.9_ratio_le_0.33": learning["0.9"]["ratio"],
        "steps_to_0.8_ratio_vs_straight_line_nnql": learning["0.8"]["ratio_nnql_line"],
    }
    print(json.dumps(summary))
    return 0
