"""Is the own map wrong where the robot times out? (docs/navigation-by-size.md section 12.) Replays
the given episodes of validation ``static:64`` (seed 1, the first N) with the subgoal follower (the own
map's plan through the shipped policy's shield) as before the change (``subgoal_prefers_seen`` off),
and after every step compares the robot's own map with the true map: cells seen blocked that are free
(a door the map closed) and cells seen free that are blocked. One JSON line per episode.

    PYTHONPATH=. python results/navigation/prefers_seen/own_map_check.py N EPISODE[,EPISODE...]
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import fixed_sampler, make_eval_set
from worlds.config import LEARNING_NAV
from worlds.heuristics import subgoal_scores
from worlds.own_map import FREE, SEEN_BLOCKED
from worlds.vector_env import NavigationVectorEnv


def main() -> None:
    n, episodes = int(sys.argv[1]), [int(v) for v in sys.argv[2].split(",")]
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    shield = policy.use_shield(nav).shield  # it reads no own map
    nav = replace(nav, observation=replace(nav.observation, subgoal_prefers_seen=False))
    scores = subgoal_scores(nav)
    es = make_eval_set("unseen", n, seed=1, size=64)
    for i in episodes:
        task = es.tasks[i]
        env = NavigationVectorEnv(1, nav, maps=fixed_sampler([task], f"check:{i}"))
        obs, _ = env.reset(seed=[es.seeds[i]], options={"tasks": [task]})
        steps, false_blocked, false_free = 0, 0, 0
        while True:
            occ = env.batch.perception.occ[0][: task.grid.height, : task.grid.width]
            false_blocked = max(false_blocked, int(((occ == SEEN_BLOCKED) & ~task.grid.blocked).sum()))
            false_free = max(false_free, int(((occ == FREE) & task.grid.blocked).sum()))
            action = np.asarray(shield.choose(scores(obs), obs)).reshape(1)
            obs, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated[0] or truncated[0]:
                break
        env.close()
        line = {"episode": i, "steps": steps, "timed_out": bool(truncated[0]), "most_false_free": false_free}
        print(json.dumps({**line, "most_false_blocked": false_blocked}), flush=True)


if __name__ == "__main__":
    main()
