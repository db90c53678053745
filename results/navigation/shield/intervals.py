"""Validation screen (seed 1 only): the reading shield's clear test on the 24 sector minima (shipped,
``sector``) against the 96 intervals between adjacent rays of the scan (each interval free up to the
smaller of its two rays; ``interval``), both with the shipped margins (0.1 m, then 0), and the interval
test without the margin (``interval0``); the disc tracker behind each. Paired on the same episodes;
``vs_sector``: episodes gained / lost against ``sector`` and the exact McNemar p.

    PYTHONPATH=. python results/navigation/shield/intervals.py SETS EPISODES [VARIANTS]

SETS: comma-separated ``static:SIZE`` / ``dynamic:SIZE``; VARIANTS: comma-separated names (default all).
Recorded in intervals.jsonl (docs/navigation-by-size.md, section 16).
"""

import json
import sys
import time
from dataclasses import replace

import numpy as np

from agents.disc_tracker import DiscTracker
from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate
from agents.shield import MARGINS, exit_distance, reach_table
from bench.map_sizes import named_set
from worlds.outcomes import Outcome

GOAL = int(Outcome.GOAL)


def interval_reach(nav, margin: float) -> np.ndarray:
    """``(n_actions, n_rays)``: how far action ``k``'s capsule (radius grown by ``margin``) reaches
    into the interval from ray ``r`` to ray ``r + 1``."""
    robot, angles = nav.robot, nav.sensors.ray_angles
    following = np.roll(angles, -1)
    following[-1] += 2 * np.pi
    t = np.linspace(0, 1, 65)
    table = np.empty((robot.n_actions, len(angles)))
    for k, turn in enumerate(robot.turns):
        for r in range(len(angles)):
            directions = angles[r] + t * (following[r] - angles[r])
            table[k, r] = exit_distance(directions - turn, robot.step, robot.radius + margin).max()
    return table


class Variant:
    """The shipped policy through its shield and tracker, the clear test read from sectors or intervals."""

    def __init__(self, base, intervals: bool, margins) -> None:
        self.base, self.intervals, self.shield = base, intervals, base.shield
        nav = base.nav_config()
        if intervals:
            self.reach = np.stack([interval_reach(nav, m) for m in margins])
        else:
            grown = [replace(nav, robot=replace(nav.robot, radius=nav.robot.radius + m)) for m in margins]
            self.reach = np.stack([reach_table(g) for g in grown])

    def __call__(self, obs):  # the runner drives a scan policy through scan_actor
        raise NotImplementedError("drive it through scan_actor")

    def scan_actor(self, n: int):
        sh = self.shield
        tracker = DiscTracker(n, sh.ray_angles, sh.max_range, sh.moves, sh.robot_radius, sh.disc_radius)

        def act(obs, rays, fresh):
            values = self.base.outputs(obs)
            if self.intervals:
                free = np.minimum(rays, np.roll(rays, -1, axis=1)).astype(np.float64)
            else:
                free = np.asarray(obs)[:, sh.readings].astype(np.float64) * sh.max_range
            room = (free[None, :, None, :] - self.reach[:, None]).min(axis=3)
            action = sh.pick(values, room)
            tracker.observe(rays, fresh)
            action = sh.keep_clear(action, values, room, tracker.clear())
            tracker.moved(action)
            return action

        return act


def main() -> None:
    sets, episodes = sys.argv[1].split(","), int(sys.argv[2])
    variants = {"sector": (False, MARGINS), "interval": (True, MARGINS), "interval0": (True, (0.0,))}
    if len(sys.argv) > 3:
        variants = {k: v for k, v in variants.items() if k in sys.argv[3].split(",")}
    first = next(iter(variants))
    for what in sets:
        es = named_set(what, episodes, 1)
        goals = {}
        for name, (intervals, margins) in variants.items():
            policy = load_policy("pretrained/nnql")
            nav = policy.nav_config()
            policy.use_shield(nav)
            started = time.time()
            runs = evaluate(Variant(policy, intervals, margins), es, nav).episodes[es.family]
            outcome = np.array([e.outcome for e in runs])
            goals[name] = outcome == GOAL
            spl = np.mean([(e.outcome == GOAL) * e.shortest / max(e.path_length, e.shortest) for e in runs])
            paired = ""
            if name != first:
                gained = int((goals[name] & ~goals[first]).sum())
                lost = int((goals[first] & ~goals[name]).sum())
                paired = f"+{gained}/-{lost} p={mcnemar_exact(gained, lost):.3g}"
            row = {
                "set": what,
                "variant": name,
                "n": len(outcome),
                "success": round(float(goals[name].mean()), 4),
                "spl": round(float(spl), 4),
                "coll": round(float(np.mean(outcome == int(Outcome.COLLISION_STATIC))), 4),
                "disc": round(float(np.mean(outcome == int(Outcome.COLLISION_DYNAMIC))), 4),
                "timeout": round(float(np.mean(outcome == int(Outcome.TIMEOUT))), 4),
                "vs_sector": paired,
                "s": round(time.time() - started),
            }
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
