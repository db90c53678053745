"""How well ``tracked.py``'s scan detector finds the discs (issue 39; docs/navigation-by-size.md
section 13): the shipped policy through its shield on the first EPISODES of validation seed 1's
``dynamic:SIZE`` set; at every step, the discs whose true centre is within 2.5 m of the robot against
the centres ``tracked.scan_discs`` finds in the scan within 2.5 m. A true disc with a found centre
within 0.3 m is found (a disc hidden behind a wall or another disc counts as missed); a found centre
with no true disc within 0.3 m is a false disc. One JSON line.

    PYTHONPATH=. python results/navigation/discs/detector.py SIZE EPISODES
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np
from collisions import shipped_on  # this folder's scripts: the same episodes, world and detector
from tracked import scan_discs, true_discs

NEAR = 2.5
"""metres: the discs that matter within a step or two"""
FOUND = 0.3
"""metres between a true and a found centre that count as the same disc"""


def main() -> None:
    size, n = int(sys.argv[1]), int(sys.argv[2])
    policy, nav, es, env = shipped_on(size, n)
    radius = es.obstacles.radius
    found = missed = false = 0
    errors = []
    for task, seed in zip(es.tasks, es.seeds, strict=True):
        obs, _ = env.reset(seed=seed, options={"task": task})
        done = False
        while not done:
            batch = env.batch
            x, y, theta = float(batch.x[0]), float(batch.y[0]), float(batch.theta[0])
            c, s = math.cos(theta), math.sin(theta)
            rel = true_discs(env) - [x, y]
            truth = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
            seen = scan_discs(batch.rays[0], nav.sensors.ray_angles, radius, nav.sensors.max_range)
            seen = seen[np.hypot(*seen.T) < NEAR]
            for centre in truth[np.hypot(*truth.T) < NEAR]:
                gap = np.hypot(*(seen - centre).T).min() if len(seen) else math.inf
                found, missed = found + int(gap < FOUND), missed + int(gap >= FOUND)
                if gap < FOUND:
                    errors.append(gap)
            nearest = [np.hypot(*(truth - centre).T).min() if len(truth) else math.inf for centre in seen]
            false += sum(int(gap >= FOUND) for gap in nearest)
            obs, _, terminated, truncated, _ = env.step(int(policy(obs[None])[0]))
            done = terminated or truncated
    print(json.dumps({
        "set": f"dynamic:{size}", "episodes": n, "seed": 1, "discs_near": found + missed,
        "found": found, "recall": found / max(found + missed, 1), "false_discs": int(false),
        "centre_error_m": round(float(np.mean(errors)), 4) if errors else None,
    }))  # fmt: skip


if __name__ == "__main__":
    main()
