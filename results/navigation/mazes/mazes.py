"""Why mazes of 1 m corridors fail (issue 39; docs/navigation-by-size.md section 14): the generated
``maze`` family (``worlds.generators``: depth-first mazes of 1-cell corridors, 1 m cells), which the
training mix (``mixed`` = rects, discs, rooms) and the test sets leave out, at SIZE cells, validation
seed 1. The methods of ``bench.map_sizes`` (:class:`bench.map_sizes.Methods`: the shipped policy through
its reading shield, the network alone, the goal-seeking heuristic, the subgoal follower through the
shield, and with ``--expert`` the lattice A* on the true map, the slow one) on the same episodes, and
``follower_unshielded``: the subgoal's action alone.

It prints the bench's rows, then one JSON line: per method the bench's figures (success with its
Wilson interval, collisions, timeouts, SPL; McNemar against the policy); and ``drift``: of 20,000 robots
driving straight ahead from a 1 m corridor's centreline with the world's motion noise
(``worlds.robot.move``, ``RobotConfig.rot_noise`` / ``trans_noise``), the share whose centre has left
the band a robot of its radius has in the corridor (0.25 m either side) within 10, 20 and 40 steps.
Every action turns by a multiple of 45 degrees, so a heading error accumulates and no action undoes it.

    PYTHONPATH=. python results/navigation/mazes/mazes.py SIZE EPISODES [--expert] [--noiseless]

``--noiseless`` runs the same episodes with the robot's motion noise off (``rot_noise`` and
``trans_noise`` 0): the control that says whether the accumulated heading error is what fails.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from bench.map_sizes import Methods, compare_on, episode_arrays, figures
from worlds.config import LEARNING_NAV, RobotConfig
from worlds.heuristics import subgoal_scores
from worlds.robot import move


def drift(robot: RobotConfig, corridor: float = 1.0, robots: int = 20_000) -> dict[str, float]:
    """Share of ``robots`` driving straight along a ``corridor``-wide corridor whose centre has left
    the band their radius leaves free within 10, 20 and 40 steps (with ``robot``'s noise and, where
    it holds its heading, ``held_headings``)."""
    rng = np.random.default_rng(0)
    band = corridor / 2 - robot.radius
    x, y, theta = np.zeros(robots), np.zeros(robots), np.zeros(robots)
    left = np.zeros(robots, bool)
    out = {}
    for k in range(1, 41):
        x, y, theta = move(
            x, y, theta, 0.0, robot.step, robot.trans_noise, robot.rot_noise, rng, robot.held_headings
        )
        left |= np.abs(y) > band
        if k in (10, 20, 40):
            out[str(k)] = round(float(left.mean()), 3)
    return out


def main() -> None:
    size, n, with_expert = int(sys.argv[1]), int(sys.argv[2]), "--expert" in sys.argv[3:]
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    if "--noiseless" in sys.argv[3:]:
        nav = replace(nav, robot=replace(nav.robot, rot_noise=0.0, trans_noise=0.0))
    es = make_eval_set("unseen", n, seed=1, size=size, families=("maze",))
    methods = Methods(policy.use_shield(nav), nav, network=load_policy("pretrained/nnql"))
    rows = compare_on(es, methods, n if with_expert else 0, f"maze:{size}")
    scores = subgoal_scores(nav)
    unshielded = evaluate(lambda obs: scores(obs).argmax(axis=1), es, nav)
    rows["follower_unshielded"] = figures(episode_arrays(unshielded, es.family), es.shortest)
    out: dict = {"size": size, "episodes": n, "seed": 1, "family": "maze", "rot_noise": nav.robot.rot_noise}
    out |= {"astar_m": round(float(es.shortest.mean()), 1), "methods": rows}
    out["drift"] = drift(nav.robot)
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
