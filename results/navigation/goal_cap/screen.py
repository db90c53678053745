"""Validation screen of the shipped network's goal-distance cap (issue 39; docs/navigation-by-size.md
section 11): the policy through its reading shield, its network reading the goal's distance capped at
each of CAPS metres (0: as observed), on the same episodes of validation seed 1.

    PYTHONPATH=. python results/navigation/goal_cap/screen.py SET EPISODES CAP...

SET is ``static:SIZE`` / ``dynamic:SIZE`` (generated maps, discs by ``bench.map_sizes.discs_for``) or a
map file (its ``.scen`` pairs). One JSON line: per cap, success (%), timeouts, SPL, each episode's
success (``ok``, for paired tests) and the seconds it took. The shipped ``pretrained/nnql`` records the
chosen cap (20 m) in its config.json; this script sets each cap on a copy.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate
from bench.map_sizes import named_set
from worlds.config import LEARNING_NAV
from worlds.outcomes import Outcome


def policy_with_cap(cap: float, where: Path):
    """``pretrained/nnql`` with ``goal_distance_cap`` set to ``cap`` metres (0: none), through its shield."""
    shutil.copytree("pretrained/nnql", where, dirs_exist_ok=True)
    config = json.loads((where / "config.json").read_text())
    config["goal_distance_cap"] = cap if cap > 0 else None
    (where / "config.json").write_text(json.dumps(config))
    policy = load_policy(where)
    return policy.use_shield(policy.nav_config(LEARNING_NAV))


def main() -> None:
    what, n, caps = sys.argv[1], int(sys.argv[2]), [float(c) for c in sys.argv[3:]]
    nav = load_policy("pretrained/nnql").nav_config(LEARNING_NAV)
    es = named_set(what, n, seed=1)
    family = es.family
    out: dict = {"set": what, "n": n}
    with tempfile.TemporaryDirectory() as tmp:
        for cap in caps:
            policy = policy_with_cap(cap, Path(tmp) / str(cap))
            started = time.time()
            result = evaluate(policy, es, nav)
            outcomes = np.array([e.outcome for e in result.episodes[family]])
            ok = outcomes == int(Outcome.GOAL)
            out[str(cap)] = {
                "success": round(ok.mean() * 100, 1),
                "timeouts": int((outcomes == int(Outcome.TIMEOUT)).sum()),
                "spl": round(result.to_dict()["metrics"][family]["spl"], 3),
                "ok": [int(v) for v in ok],
                "s": round(time.time() - started),
            }
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
