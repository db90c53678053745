"""MAP refinement after NIRL's policy iteration (agents/nirl/refine_progress.py), measured where the
injected noise is known: the share of injected random actions relabelled to the expert's, and of
clean steps kept as recorded.

Two uses:

* ``--tune RUN``: choose the refinement's settings on a noisy demonstration set no reported run uses
  (seed 20000 + ``--demo-seed``, default 3; the bench's sets are seeds 0-2), with the prior of a
  saved NIRL run (its NNQL phase's, ``RUN/policy_iteration``, or with none its own rounds', ``RUN``)
  and a progress potential fitted on that set's own steps to go, as NIRL fits it. Rule: the most
  injected actions relabelled to the expert's with at least 99% of clean steps kept (if none keeps
  99%: the one that keeps most).
* ``--measure DIR ...``: the rates of saved NIRL runs of the bench (``bench/nirl.py`` writes them to
  ``runs/nirl_out/<split>-<set>-<seed>`` with ``--nirl policy_steps=N`` or ``--save-runs``) on their
  own noisy demonstrations (from ``--demo-cache``), with the given settings.

Prints one JSON object on its last line.

    python nirl_refine.py --tune runs/nirl_out/test-20noisy-0 --demo-cache runs/democache
    python nirl_refine.py --measure runs/nirl_out/test-20noisy-{0,1,2} --demo-cache runs/democache

Archived with the runs it made (results/nirl/); run it from the repository root with
``PYTHONPATH=. python results/nirl/scripts/nirl_refine.py``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import pickle
import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from agents.evaluation.policies import load_policy
from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner
from agents.nirl.persistence import load_potential
from agents.nirl.policy_iteration import POLICY_DIR
from agents.nirl.progress import ProgressPotential
from agents.nirl.refine_progress import ProgressRefine, fit_potential, refine_learner_demos
from agents.nnql.policy import NNQLPolicy
from agents.planning.demonstrate import generate_demos
from bench._nirl_options import cached, rates
from worlds.config import LEARNING_NAV

GRID = {
    "temperature": (0.0003, 0.001, 0.003, 0.01),
    "offset": (-1.0, -0.5, -0.25),
    "scale": (0.0, 0.1, 0.25, 0.5),
    "threshold": (0.5, 0.7, 0.9),
}


def noisy_set(seed: int, cache: str | None) -> tuple[list, np.ndarray]:
    """The 20 noisy demonstrations of demo seed ``seed`` (30% random actions) and the expert's labels."""

    def make():
        demos, _ = generate_demos("mixed:16", 20, seed=20_000 + seed, noise=0.3, config=LEARNING_NAV)
        labels = [d.labels.copy() for d in demos]
        for demo in demos:
            demo.expert_actions = None
        return demos, labels

    demos, labels = cached(cache, f"noisy-learning-{seed}", make)
    return demos, np.concatenate(labels)


def learner_for(demos, seed: int, potential=None) -> NIRLLearner:
    """A NIRL learner holding ``demos`` and the potential (a saved one, or fitted by the refinement's own
    regression when None: ``fit_potential`` on the recorded steps to go)."""
    inputs = "goal" if potential is None or potential.first_input else "observation"
    learner = NIRLLearner(NIRLConfig(seed=seed, potential_inputs=inputs), LEARNING_NAV)
    learner.add_demos(demos)
    if potential is not None:
        learner.fit.potential.load_state_dict(potential.state_dict())
    else:
        steps = learner.demos.storage.get(torch.arange(len(learner.demos)))
        fit_potential(learner.fit.potential, steps["observation"], steps["to_go"], learner.config.gamma)
    return learner


def saved_potential(run: Path) -> ProgressPotential:
    """The progress potential a NIRL run saved (any observation; agents.nirl.persistence)."""
    potential = load_potential(run)
    if potential is None:
        sys.exit(f"{run}: no progress potential (potential.safetensors) saved with this run")
    return potential


def prior_policy(run: Path) -> Callable[[np.ndarray], np.ndarray]:
    """The prior's Q-values of a saved run, in the NNQL phase's reward units (a step 0.01): its NNQL
    phase's policy (``RUN/policy_iteration``) when it had one, else the policy of NIRL's own rounds
    (``RUN``, saved with ``--save-runs``; a step costs 1 there, so its Q-values times ``1 - gamma``, as
    ``policy_iteration.warm_weights`` converts them)."""
    if (run / POLICY_DIR).is_dir():
        return NNQLPolicy.load(run / POLICY_DIR).q_values
    policy = load_policy(run)  # model "nirl", kind "q_network": its outputs are the Q-values
    gamma = NIRLConfig.from_dict(policy.config["nirl_config"]).gamma
    return lambda obs: policy.outputs(obs) * (1.0 - gamma)


def measure(run: Path, cache: str | None, settings: ProgressRefine) -> dict:
    seed = int(re.search(r"-(\d+)$", run.name)[1])
    path = Path(cache) / f"sets-learning-{seed}-0.3-20.pkl"  # bench/nirl.py --demo-cache wrote it
    sets, labels = pickle.loads(path.read_bytes())
    learner = learner_for(sets["20noisy"], seed, saved_potential(run))
    q_values = prior_policy(run)
    steps, refinement = refine_learner_demos(learner, q_values, settings)
    expert = np.concatenate(labels)
    return ({"run": str(run), "seed": seed} | rates(steps["action"], refinement.labels, expert)
            | {"prior": separation(q_values, steps, expert)})  # fmt: skip


def separation(q_values: Callable[[np.ndarray], np.ndarray], steps, expert: np.ndarray) -> dict:
    """How well the prior alone tells injected steps from clean ones, whatever the settings: the
    probability that an injected step's Q-gap (best Q minus the recorded action's, the NNQL phase's
    units) exceeds a clean step's (the ROC area; 0.5: no better than chance), and how often the
    prior's greedy action is the expert's on clean and on injected steps."""
    q = np.asarray(q_values(steps["observation"].numpy()))
    recorded = steps["action"].long().reshape(-1).numpy()
    expert = np.asarray(expert)[: len(recorded)]
    gap = q.max(axis=1) - q[np.arange(len(q)), recorded]
    injected = recorded != expert
    a, b = gap[injected], gap[~injected]
    auc = float((a[:, None] > b[None, :]).mean() + 0.5 * (a[:, None] == b[None, :]).mean())
    greedy = q.argmax(axis=1)
    return {
        "gap_auc": auc,
        "greedy_is_expert_clean": float((greedy[~injected] == expert[~injected]).mean()),
        "greedy_is_expert_injected": float((greedy[injected] == expert[injected]).mean()),
    }


def tune(run: Path, demo_seed: int, cache: str | None) -> dict:
    demos, expert = noisy_set(demo_seed, cache)
    learner = learner_for(demos, demo_seed)
    q_values = prior_policy(run)
    steps = learner.demos.storage.get(torch.arange(len(learner.demos)))
    recorded = steps["action"]
    rows = []
    for values in itertools.product(*GRID.values()):
        settings = ProgressRefine(**dict(zip(GRID, values, strict=True)))
        _, refinement = refine_learner_demos(learner, q_values, settings)
        rows.append(dict(zip(GRID, values, strict=True)) | rates(recorded, refinement.labels, expert))
        print(json.dumps(rows[-1]), flush=True)
    ok = [r for r in rows if r["clean_kept"] >= 0.99]
    if ok:
        best = max(ok, key=lambda r: (r["injected_relabelled_to_expert"], r["clean_kept"]))
    else:  # none keeps 99% of clean steps: the one that keeps most
        best = max(rows, key=lambda r: (r["clean_kept"], r["injected_relabelled_to_expert"]))
    return {
        "tuned_on": f"noisy demo seed {demo_seed}",
        "prior_run": str(run),
        "prior": separation(q_values, steps, expert),
        "best": best,
        "grid": len(rows),
    }


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--tune", type=Path, help="a saved NIRL run whose NNQL phase gives the prior")
    parser.add_argument("--demo-seed", type=int, default=3, help="noisy set of the tuning (not 0-2)")
    parser.add_argument("--measure", type=Path, nargs="*", default=[], help="saved noisy-set NIRL runs")
    parser.add_argument("--demo-cache", default="runs/democache")
    for name, default in vars(ProgressRefine()).items():
        parser.add_argument(f"--{name}", type=float, default=default)
    args = parser.parse_args()
    settings = ProgressRefine(**{k: getattr(args, k) for k in vars(ProgressRefine())})
    out: dict = {"settings": vars(settings)}
    if args.tune:
        out["tune"] = tune(args.tune, args.demo_seed, args.demo_cache)
    if args.measure:
        out["runs"] = [measure(run, args.demo_cache, settings) for run in args.measure]
        for key in ("injected_relabelled_to_expert", "clean_kept"):
            out[f"mean_{key}"] = float(np.mean([r[key] for r in out["runs"]]))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
