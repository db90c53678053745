"""The world's cost of ``subgoal_prefers_seen`` on a whole big map (docs/navigation-by-size.md section
12): the subgoal follower (the own map's plan through the shipped policy's shield) on the first N
``.scen`` pairs of MAP (validation seed 1), the setting off then on; robot-steps per CPU-second.

    PYTHONPATH=. python results/navigation/prefers_seen/big_map_cost.py MAP N
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_map_eval_set
from worlds.config import LEARNING_NAV
from worlds.heuristics import subgoal_scores


def main() -> None:
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    shield = policy.use_shield(nav).shield
    es = make_map_eval_set(sys.argv[1], int(sys.argv[2]), seed=1)
    for on in (False, True):
        setting = replace(nav, observation=replace(nav.observation, subgoal_prefers_seen=on))
        scores = subgoal_scores(setting)
        cpu = time.process_time()
        result = evaluate(lambda o, s=scores: shield.choose(s(o), o), es, setting)
        cpu = time.process_time() - cpu
        steps = sum(e.steps for e in result.episodes[es.family])
        line = {"map": sys.argv[1], "pairs": len(es), "prefers_seen": on, "cpu_s": round(cpu, 1)}
        print(json.dumps({**line, "steps": steps, "steps_per_cpu_s": round(steps / cpu)}), flush=True)


if __name__ == "__main__":
    main()
