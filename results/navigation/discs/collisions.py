"""What the shipped policy's disc collisions are (issue 39; docs/navigation-by-size.md section 13): the
policy through its reading shield on validation seed 1's ``dynamic:SIZE`` set (``bench.map_sizes``'s
discs: 16 at 64 cells), and for every episode that ends on a moving disc, from the world as it stood
one step before the hit:

- ``action``, ``turn_around``: what the shield let the robot do (the turn-around drives nothing);
- ``gap`` (m): the nearest disc's free distance to the robot then, ``closing`` (m per step): how fast
  that disc was coming at the robot's centre (the discs move 0.2 m a step);
- ``safe_actions``: how many of the robot's actions (the turn-around included) would not have hit
  anything in that step, each tried on a copy of the world (the discs' true motion, the same noise);
- ``safe2``: whether some pair of actions gets through two steps.

An action that is safe by this oracle but not taken is a collision a shield that knew where the discs
are going (their velocity, from two frames) could have turned away; ``safe_actions == 0`` means the
robot could not have escaped by the time the shield had its last choice. One JSON line per collision,
then a summary line.

    PYTHONPATH=. python results/navigation/discs/collisions.py SIZE EPISODES
"""

from __future__ import annotations

import copy
import json
import sys
from dataclasses import replace

import numpy as np

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import fixed_sampler
from bench.map_sizes import named_set
from worlds.config import LEARNING_NAV
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome

COLLISIONS = (int(Outcome.COLLISION_DYNAMIC), int(Outcome.COLLISION_STATIC))


def survives(env: NavigationEnv, actions: tuple[int, ...]) -> bool:
    """Does a copy of ``env`` take ``actions`` without a collision?"""
    trial = copy.deepcopy(env)
    for action in actions:
        trial.step(action)
        if int(trial.batch.outcome[0]) in COLLISIONS:
            return False
    return True


def shipped_on(size: int, n: int, kind: str = "dynamic"):
    """The shipped policy through its reading shield, its world, validation seed 1's ``KIND:SIZE``
    set of ``n`` episodes (``dynamic``: with discs; ``static``), and a one-robot env that plays them
    (``reset`` with each episode's seed and task)."""
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    policy.use_shield(nav)
    es = named_set(f"{kind}:{size}", n, seed=1)
    env = NavigationEnv(replace(nav, obstacles=es.obstacles), maps=fixed_sampler(es.tasks, "discs"))
    return policy, nav, es, env


def named(outcomes: np.ndarray) -> dict[str, int]:
    """How many episodes ended each way, by the outcome's name."""
    return {o.name: int((outcomes == int(o)).sum()) for o in Outcome if (outcomes == int(o)).any()}


def main() -> None:
    size, n = int(sys.argv[1]), int(sys.argv[2])
    policy, nav, es, env = shipped_on(size, n)
    actions = range(nav.robot.n_actions + 1)  # the turn-around is the last
    rows, counts = [], {}
    for episode, (task, seed) in enumerate(zip(es.tasks, es.seeds, strict=True)):
        obs, info = env.reset(seed=seed, options={"task": task})
        done, steps = False, 0
        while not done:
            before = copy.deepcopy(env)
            action = int(policy(obs[None])[0])
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
        name = Outcome(int(info["outcome"])).name
        counts[name] = counts.get(name, 0) + 1
        if int(info["outcome"]) != int(Outcome.COLLISION_DYNAMIC):
            continue
        b = before.batch
        k = int(b.disc_arrays[10][0])
        ox, oy, ovx, ovy, orad = (b.disc_arrays[m][0, :k] for m in range(5))
        rx, ry = float(b.x[0]), float(b.y[0])
        gaps = np.hypot(ox - rx, oy - ry) - orad - nav.robot.radius
        j = int(np.argmin(gaps))
        towards = np.array([rx - ox[j], ry - oy[j]]) / max(np.hypot(rx - ox[j], ry - oy[j]), 1e-9)
        safe = [a for a in actions if survives(before, (a,))]
        rows.append({
            "episode": episode, "step": steps, "action": action,
            "turn_around": action == nav.robot.turn_around,
            "gap": round(float(gaps[j]), 3), "closing": round(float(towards @ [ovx[j], ovy[j]]), 3),
            "safe_actions": len(safe),
            "safe2": any(survives(before, (a, a2)) for a in safe for a2 in actions),
        })  # fmt: skip
        print(json.dumps(rows[-1]), flush=True)
    print(json.dumps({
        "size": size, "episodes": n, "seed": 1, "outcomes": counts, "disc_collisions": len(rows),
        "one_step_avoidable": sum(r["safe_actions"] > 0 for r in rows),
        "two_step_avoidable": sum(r["safe2"] for r in rows),
        "turn_arounds": sum(r["turn_around"] for r in rows),
        "avoidable_not_turning": sum(r["safe_actions"] > 0 and not r["turn_around"] for r in rows),
    }))  # fmt: skip


if __name__ == "__main__":
    main()
