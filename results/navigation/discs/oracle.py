"""How far a perfect view of the discs' motion could take the shield (issue 39;
docs/navigation-by-size.md section 13): the ceiling of the object-level disc tracker that section
proposes, measured before building it.

The shipped policy through its reading shield on validation seed 1's ``dynamic:SIZE`` set, the same
episodes twice: as shipped, and with an oracle behind the shield that, at every step, tries the
shield's choice on a copy of the world (the discs' true motion, the same noise draws: more than any
tracker can know) and, where it would hit something, takes instead the first action that would not
- the network's preference among the shield's clear actions first, then among the others, then the
turn-around; where none gets through, the shield's choice. So it knows one step ahead exactly what a
tracker could only predict. Printed: both runs' success and outcomes, McNemar, and how often the
oracle changed the action; the last line is one JSON object.

    PYTHONPATH=. python results/navigation/discs/oracle.py SIZE EPISODES

The episodes, the world and the copies are ``collisions.py``'s (``shipped_on``, ``survives``).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from collisions import named, shipped_on, survives  # this folder's collisions.py: the same world and copies

from agents.evaluation.compare import mcnemar_exact
from agents.shield import MARGINS
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome


def run(policy, env: NavigationEnv, es, oracle: bool) -> tuple[np.ndarray, dict[str, int]]:
    """Each episode's outcome, and with the oracle how many steps it was asked and changed."""
    shield = policy.shield
    outcomes, counts = [], {"steps": 0, "changed": 0, "none_survives": 0}
    for task, seed in zip(es.tasks, es.seeds, strict=True):
        obs, info = env.reset(seed=seed, options={"task": task})
        done = False
        while not done:
            outputs = policy.outputs(obs[None])
            action = int(shield.choose(outputs, obs[None])[0])
            if oracle:
                counts["steps"] += 1
                if not survives(env, (action,)):
                    room = shield.room(obs[None])[len(MARGINS) - 1, 0]  # the capsule alone
                    order = np.argsort(-outputs[0], kind="stable")
                    tries = [a for a in order if room[a] >= 0] + [a for a in order if room[a] < 0]
                    tries.append(shield.turn_around)
                    chosen = next((int(a) for a in tries if a != action and survives(env, (int(a),))), None)
                    if chosen is None:
                        counts["none_survives"] += 1
                    else:
                        action = chosen
                        counts["changed"] += 1
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        outcomes.append(int(info["outcome"]))
    return np.asarray(outcomes), counts


def main() -> None:
    size, n = int(sys.argv[1]), int(sys.argv[2])
    policy, _, es, env = shipped_on(size, n)
    shipped, _ = run(policy, env, es, oracle=False)
    ceiling, counts = run(policy, env, es, oracle=True)
    won, won_oracle = shipped == int(Outcome.GOAL), ceiling == int(Outcome.GOAL)
    gained, lost = int((won_oracle & ~won).sum()), int((won & ~won_oracle).sum())
    out = {
        "size": size, "episodes": n, "seed": 1,
        "shipped": {"success": float(won.mean()), "outcomes": named(shipped)},
        "oracle": {"success": float(won_oracle.mean()), "outcomes": named(ceiling), **counts},
        "gained": gained, "lost": lost, "p": mcnemar_exact(gained, lost),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }  # fmt: skip
    shipped_line = f"dynamic:{size} shipped {100 * won.mean():.1f}% {out['shipped']['outcomes']}"
    oracle_line = f"oracle behind the shield {100 * won_oracle.mean():.1f}% {out['oracle']['outcomes']}"
    print(
        f"{shipped_line}; {oracle_line}, +{gained} -{lost} p {out['p']:.2g}; the oracle changed "
        f"{counts['changed']} of {counts['steps']} actions, none got through at {counts['none_survives']}",
        flush=True,
    )
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
