"""Validation screen of the own map's plan preferring seen cells (issue 39; docs/navigation-by-size.md
section 12): the shipped policy through its reading shield, and the subgoal follower (the own map's
plan through the same shield, no network), with ``observation.subgoal_prefers_seen`` off and on, on
the same episodes of validation seed 1.

    PYTHONPATH=. python results/navigation/prefers_seen/screen.py SET EPISODES METHODS

SET is ``static:SIZE`` / ``dynamic:SIZE`` (generated maps, discs by ``bench.map_sizes.discs_for``) or a
map file (its ``.scen`` pairs);
METHODS is ``policy`` or ``policy,follower``. One JSON line: per setting and method, success (%),
timeouts, SPL, each episode's success (``ok``, for paired tests) and the seconds it took. The shipped
``pretrained/nnql`` records the chosen setting (on) in its config.json; this script sets each on a copy.
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
from worlds.heuristics import subgoal_scores
from worlds.outcomes import Outcome


def policy_with(prefers_seen: bool, where: Path):
    """``pretrained/nnql`` observing with ``subgoal_prefers_seen`` set, through its shield; its nav."""
    shutil.copytree("pretrained/nnql", where, dirs_exist_ok=True)
    config = json.loads((where / "config.json").read_text())
    config["observation"]["observation.subgoal_prefers_seen"] = prefers_seen
    (where / "config.json").write_text(json.dumps(config))
    policy = load_policy(where)
    nav = policy.nav_config(LEARNING_NAV)
    return policy.use_shield(nav), nav


def main() -> None:
    what, n, methods = sys.argv[1], int(sys.argv[2]), sys.argv[3].split(",")
    es = named_set(what, n, seed=1)
    family = es.family
    out: dict = {"set": what, "n": n}
    with tempfile.TemporaryDirectory() as tmp:
        for setting in (False, True):
            policy, nav = policy_with(setting, Path(tmp) / str(setting))
            scores = subgoal_scores(nav)
            runs = {"policy": policy, "follower": lambda o, p=policy, s=scores: p.shield.choose(s(o), o)}
            for method in methods:
                started = time.time()
                result = evaluate(runs[method], es, nav)
                outcomes = np.array([e.outcome for e in result.episodes[family]])
                ok = outcomes == int(Outcome.GOAL)
                out[f"{method}:{'on' if setting else 'off'}"] = {
                    "success": round(ok.mean() * 100, 2),
                    "timeouts": int((outcomes == int(Outcome.TIMEOUT)).sum()),
                    "spl": round(result.to_dict()["metrics"][family]["spl"], 3),
                    "ok": "".join(str(int(v)) for v in ok),
                    "s": round(time.time() - started),
                }
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
