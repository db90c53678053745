"""How well NIRL's progress potential predicts an unseen expert's steps to go (issue 15, part 5).

The potential (``agents.nirl.progress``) is fitted as NIRL fits it - Adam (AdamW's decoupled decay
in the weight-decay rows), 750 steps of 128 states, the same MLP - on the 20 clean demonstrations of
bench/nirl.py's seed (the expert on ``mixed:16``, demo seed 10000 + seed), in LEARNING_NAV (or
``--nav``'s observation), with several inputs and regularisers; each is scored on 40 held-out
expert episodes (seed 30001 + seed, other maps): root-mean-square error of the steps to go (the
fitted discounted value inverted) and its correlation with them, mean of ``--fits`` fitting seeds.
CPU seconds; prints a table, then one JSON object on the last line.

    python nirl_potential.py                       # seed 0, 3 fits, LEARNING_NAV
    python nirl_potential.py --nav learning_plan   # with the own map's plan length observed

Archived with the runs it made (results/nirl/); run it from the repository root with
``PYTHONPATH=. python results/nirl/scripts/nirl_potential.py``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner
from agents.nirl.progress import ProgressPotential
from agents.nirl.refine_progress import fit_potential
from agents.planning.demonstrate import generate_demos
from bench.nirl import NAVS
from worlds.config import NavConfig
from worlds.perception import frame_layout

GAMMA = 0.99


def states(demos, nav: NavConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Observations of the demonstrated steps and the expert's steps to go from each (0: unknown), as
    NIRL's learner stores them (``NIRLLearner.add_demos``)."""
    learner = NIRLLearner(NIRLConfig(), nav)
    learner.add_demos(demos)
    steps = learner.demos.storage.get(torch.arange(len(learner.demos)))
    return steps["observation"], steps["to_go"]


def fit(
    obs, to_go, seed: int, hidden=(64, 64), weight_decay=0.0, steps=750, first_input=0
) -> ProgressPotential:
    """A potential fitted as NIRL fits it (``refine_progress.fit_potential``: Adam, batches of 128)."""
    torch.manual_seed(seed)
    potential = ProgressPotential(obs.shape[1], hidden, "relu", GAMMA, first_input)
    fit_potential(potential, obs, to_go, GAMMA, updates=steps, seed=seed, weight_decay=weight_decay)
    return potential


def score(potential, obs, to_go) -> tuple[float, float]:
    """(RMSE in steps, correlation) of the steps to go the potential implies on the known states."""
    known = to_go > 0
    with torch.no_grad():
        value = potential(obs[known])
    implied = torch.log(torch.clamp(1 + value * (1 - GAMMA), 1e-6, 1.0)) / np.log(GAMMA)
    truth = to_go[known].float()
    return float((implied - truth).pow(2).mean().sqrt()), float(
        np.corrcoef(implied.numpy(), truth.numpy())[0, 1]
    )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seed", type=int, default=0, help="bench/nirl.py's seed of the demonstrations")
    parser.add_argument("--fits", type=int, default=3, help="fitting seeds averaged per variant")
    parser.add_argument("--nav", choices=list(NAVS), default="learning", help="observation (bench/nirl.py's)")
    args = parser.parse_args()
    nav = NAVS[args.nav]
    train, _ = generate_demos("mixed:16", 20, seed=10_000 + args.seed, config=nav)
    heldout, _ = generate_demos("mixed:16", 40, seed=30_001 + args.seed, config=nav)
    (obs, to_go), (obs_h, to_go_h) = states(train, nav), states(heldout, nav)
    goal = nav.sensors.n_beams  # the goal and subgoal features follow the range readings
    variants = {
        "all 30 features (part 3-4)": {},
        "all, weight decay 0.01": {"weight_decay": 1e-2},
        "all, weight decay 0.1": {"weight_decay": 1e-1},
        "all, one layer of 32": {"hidden": (32,)},
        "all, 200 steps": {"steps": 200},
        "all, 3000 steps": {"steps": 3000},
        "goal and subgoal only": {"first_input": goal},
        "goal and subgoal only, one layer of 32": {"first_input": goal, "hidden": (32,)},
    }
    if "plan_length" in frame_layout(nav):
        variants["plan length only"] = {"first_input": frame_layout(nav)["plan_length"][0]}
    print(f"{int((to_go > 0).sum())} demonstrated states, {int((to_go_h > 0).sum())} held-out expert states")
    print("| inputs, fit | demos: RMSE / correlation | held-out expert: RMSE / correlation |")
    print("| --- | --- | --- |")
    rows = {}
    for name, options in variants.items():
        figures = []
        for seed in range(args.fits):
            potential = fit(obs, to_go, seed, **options)
            figures.append(score(potential, obs, to_go) + score(potential, obs_h, to_go_h))
        mean = np.mean(figures, axis=0)
        rows[name] = {
            "train_rmse": mean[0],
            "train_r": mean[1],
            "heldout_rmse": mean[2],
            "heldout_r": mean[3],
        }
        print(f"| {name} | {mean[0]:.2f} / {mean[1]:.3f} | {mean[2]:.2f} / {mean[3]:.3f} |")
    print(
        json.dumps(
            {
                "bench": "nirl_potential",
                "nav": args.nav,
                "seed": args.seed,
                "fits": args.fits,
                "variants": rows,
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
