"""The shipped policy's timeouts through today's shield, validation seed 1, 300 static episodes of
64-cell maps: how far each drove against the shortest path, and how many turn-arounds it took (a
turn-around is a step that drives nothing, so their number is ``steps - path_length / step``, up to
the motion noise). One JSON line per timeout.

    PYTHONPATH=. python results/navigation/shield/timeouts.py > results/navigation/shield/timeouts.jsonl
"""

from __future__ import annotations

import json

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from worlds.config import LEARNING_NAV
from worlds.outcomes import Outcome


def main() -> None:
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    policy.use_shield(nav)
    es = make_eval_set("unseen", 300, seed=1, size=64)
    for i, e in enumerate(evaluate(policy, es, nav).episodes["unseen"]):
        if e.outcome == int(Outcome.TIMEOUT):
            print(json.dumps({
                "episode": i, "steps": e.steps, "path_length": round(e.path_length, 2),
                "shortest": round(e.shortest, 2), "path_over_shortest": round(e.path_length / e.shortest, 2),
                "turn_arounds": round(e.steps - e.path_length / nav.robot.step),
            }))  # fmt: skip


if __name__ == "__main__":
    main()
