"""MAP refinement with the hindsight prior (agents/nirl/hindsight.py), measured where the injected
noise is known: the share of injected random actions relabelled to the expert's own, and of clean
steps kept as recorded - beside the same refinement with the true map's costs (what a perfect seen
map would give; the true map is read here only, by the bench).

* ``--tune``: choose the temperature and threshold on a noisy demonstration set no reported run uses
  (seed 20000 + ``--demo-seed``, default 3; the bench's sets are seeds 0-2). Rule (nirl_refine.py's):
  the most injected actions relabelled to the expert's with at least 99% of clean steps kept.
* ``--measure``: the rates on the 20 noisy demonstrations of the bench's test seeds (``--seeds``, the
  sets bench/nirl.py trains on), with the given settings.

Prints one JSON object on its last line.

    python nirl_hindsight.py --tune --demo-cache runs/democache
    python nirl_hindsight.py --measure --seeds 0 1 2 --demo-cache runs/democache

Archived with the runs it made (results/nirl/); run it from the repository root with
``PYTHONPATH=. python results/nirl/scripts/nirl_hindsight.py``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time

import numpy as np
import torch
from nirl_refine import noisy_set  # its sibling in this folder

from agents.nirl.hindsight import HindsightSettings, costs_along, demo_costs, hindsight_prior, seen_map
from agents.nirl.losses import map_posterior, refine_steps
from bench._nirl_options import cached, rates
from bench.nirl import demo_sets
from worlds.config import LEARNING_NAV

TEMPERATURES = (0.05, 0.1, 0.2, 0.3, 0.5)
THRESHOLDS = (0.5, 0.7, 0.9, 0.95)
NOISE = 0.3
HARMFUL = 0.5
"""an injected action costing at least this much more than the best (m, one robot step) is harmful"""
NEAR_BEST = 0.1
"""... and one within this of the best (m) is as good as the expert's"""


def true_costs(demo, nav) -> np.ndarray:
    """(T, A) the same action costs on the true map (the bench's reference, never the learner's)."""
    return costs_along(demo, demo.task().grid, nav)


def map_figures(demos, nav, margin: float) -> dict:
    """How the seen maps compare with the true ones: agreement on the cells a ray reached, true walls
    among them missed, free cells taken for walls."""
    agree, missed, false = [], [], []
    for demo in demos:
        truth = demo.task().grid.blocked
        blocked, reached = seen_map(
            demo.observations, demo.poses, nav, truth.shape, demo.grid.cell_size, margin
        )
        agree.append(float((blocked[reached] == truth[reached]).mean()))
        missed.append(int((truth & reached & ~blocked).sum()))
        false.append(int((blocked & ~truth).sum()))
    return {"agreement_on_reached": float(np.mean(agree)), "walls_missed": int(np.sum(missed)),
            "false_walls": int(np.sum(false))}  # fmt: skip


def decide(costs, recorded, expert, temperature: float, threshold: float, true: np.ndarray) -> dict:
    """The refinement under the prior of ``costs`` (T, A): the bench's rates, and the injected steps split
    by what they cost on the true map ``true`` (T, A): harmful ones (at least HARMFUL metres worse than
    the best action) replaced by a near-best action, harmless ones (at most NEAR_BEST worse) changed."""
    prior = torch.as_tensor(hindsight_prior(costs, temperature), dtype=torch.float32)
    observed = torch.as_tensor(recorded)
    refinement = refine_steps(map_posterior(prior, observed, NOISE), observed, threshold, judge_recorded=True)
    labels = refinement.labels.numpy()
    rows = np.arange(len(recorded))
    best = true.min(axis=1)
    harm, label_harm = true[rows, recorded] - best, true[rows, labels] - best
    injected, changed = recorded != expert, labels != recorded
    harmful, harmless = injected & (harm >= HARMFUL), injected & (harm <= NEAR_BEST)
    return rates(recorded, labels, expert) | {
        "harmful_injected": int(harmful.sum()),
        "harmful_replaced_by_near_best": float((changed & (label_harm <= NEAR_BEST))[harmful].mean()),
        "harmless_injected": int(harmless.sum()),
        "harmless_changed": float(changed[harmless].mean()),
    }


def set_costs(demos, nav, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    seen = np.concatenate([demo_costs(d, nav, margin) for d in demos])
    true = np.concatenate([true_costs(d, nav) for d in demos])
    recorded = np.concatenate([d.actions for d in demos])
    return seen, true, recorded


def tune(demo_seed: int, cache: str | None, margin: float) -> dict:
    nav = LEARNING_NAV
    demos, expert = noisy_set(demo_seed, cache)
    seen, true, recorded = set_costs(demos, nav, margin)
    rows = []
    for temperature, threshold in itertools.product(TEMPERATURES, THRESHOLDS):
        row = {"temperature": temperature, "threshold": threshold}
        row |= decide(seen, recorded, expert, temperature, threshold, true)
        row["true_map"] = decide(true, recorded, expert, temperature, threshold, true)
        rows.append(row)
        print(json.dumps(row), flush=True)
    ok = [r for r in rows if r["clean_kept"] >= 0.99]
    best = max(ok, key=lambda r: (r["injected_relabelled_to_expert"], r["clean_kept"])) if ok else None
    return {"tuned_on": f"noisy demo seed {demo_seed}", "maps": map_figures(demos, nav, margin),
            "best": best, "grid": rows}  # fmt: skip


def measure(seeds: list[int], cache: str | None, settings: HindsightSettings) -> dict:
    nav = LEARNING_NAV
    out = []
    for seed in seeds:
        t0 = time.perf_counter()
        sets, labels = cached(cache, f"sets-learning-{seed}-{NOISE}-20", demo_sets, seed, NOISE, nav, 20)
        demos, expert = sets["20noisy"], np.concatenate(labels)
        seen, true, recorded = set_costs(demos, nav, settings.margin)
        row = {"seed": seed} | decide(seen, recorded, expert, settings.temperature, settings.threshold, true)
        row["true_map"] = decide(true, recorded, expert, settings.temperature, settings.threshold, true)
        row["maps"] = map_figures(demos, nav, settings.margin)
        row["seconds"] = round(time.perf_counter() - t0, 1)
        out.append(row)
        print(json.dumps(row), flush=True)
    keys = ("injected_relabelled_to_expert", "injected_changed", "clean_kept",
            "harmful_replaced_by_near_best", "harmless_changed")  # fmt: skip
    pooled = {k: float(np.mean([r[k] for r in out])) for k in keys}
    return {"runs": out, "mean": pooled}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--tune", action="store_true", help="grid of temperature x threshold on --demo-seed")
    parser.add_argument("--demo-seed", type=int, default=3, help="noisy set of the tuning (not 0-2)")
    parser.add_argument("--measure", action="store_true", help="rates on the test sets of --seeds")
    parser.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2])
    parser.add_argument("--demo-cache", default="runs/democache")
    defaults = HindsightSettings()
    for name in ("temperature", "threshold", "margin"):
        parser.add_argument(f"--{name}", type=float, default=getattr(defaults, name))
    args = parser.parse_args()
    if not (args.tune or args.measure):
        parser.error("give --tune and/or --measure")
    settings = HindsightSettings(args.temperature, args.threshold, args.margin)
    out: dict = {"bench": "nirl_hindsight", "settings": vars(settings)}
    if args.tune:
        out["tune"] = tune(args.demo_seed, args.demo_cache, settings.margin)
    if args.measure:
        out["measure"] = measure(args.seeds, args.demo_cache, settings)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
