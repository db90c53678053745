"""What the shielded policy still fails on, validation seed 1, 300 static episodes per size: each wall
collision is a *trap* when no action was clear at its last step (the robot must drive every step and
turns at most 90 degrees, so a pocket narrower than its turn has no way out) or a *miss* when the
chosen action was clear by the readings and still hit (a corner between two rays, or noise). One
JSON line.

    PYTHONPATH=. python results/navigation/shield/residual.py

``residual.json`` measured the shield of 9a9c128, which took the roomiest action when nothing was
clear. Today's shield turns round there (``screen.py``, option ``t``), so a trap no longer ends in a
collision and this script run today counts (almost) no traps.
"""

from __future__ import annotations

import json
from dataclasses import replace

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import fixed_sampler, make_eval_set
from worlds.config import LEARNING_NAV
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome


def main() -> None:
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    policy.use_shield(nav)
    out: dict = {"seed": 1, "episodes": 300}
    for size in (32, 48, 64):
        es = make_eval_set("unseen", 300, seed=1, size=size)
        env = NavigationEnv(replace(nav, obstacles=es.obstacles), maps=fixed_sampler(es.tasks, "residual"))
        counts = {"goal": 0, "trap": 0, "miss": 0, "timeout": 0}
        for task, seed in zip(es.tasks, es.seeds, strict=True):
            obs, info = env.reset(seed=seed, options={"task": task})
            done, clear = False, True
            while not done:
                clear = bool((policy.shield.room(obs[None])[-1] >= 0).any())  # the robot's own capsule
                obs, _, terminated, truncated, info = env.step(int(policy(obs[None])[0]))
                done = terminated or truncated
            outcome = int(info["outcome"])
            if outcome == int(Outcome.COLLISION_STATIC):
                counts["miss" if clear else "trap"] += 1
            elif outcome == int(Outcome.TIMEOUT):
                counts["timeout"] += 1
            elif outcome == int(Outcome.GOAL):
                counts["goal"] += 1
        env.close()
        out[str(size)] = counts
    print(json.dumps(out))


if __name__ == "__main__":
    main()
