"""Where the shipped disc tracker finds no action clear of the discs, which escape? (validation only)

The shield's disc tracker (``agents/disc_tracker.py``, docs/navigation-by-size.md section 15) keeps
the shield's choice unless a tracked disc's predicted sweep meets it; then it takes the first
disc-clear action of: the network's preference among the actions the readings leave clear, the
turn-around, the others (the readings rule them out). Its remaining failures at 64 cells are wall
collisions, and an escape into what the readings rule out is one way to get one. The variant here,
``least``: never the others; where no action the readings leave clear (nor the turn-around) is
disc-clear, the one of them that keeps the largest predicted distance from every disc's sweep.

Per set: the shipped tracker and the variant on the same validation episodes (seed 1), McNemar,
outcomes; the last line is one JSON object.

    PYTHONPATH=. python results/navigation/discs/escapes.py EPISODES SET ...   # e.g. 300 dynamic:64

The sets are ``bench/map_sizes.py``'s (``named_set``); the policy is the shipped one, acting through
its shield in ``LEARNING_NAV`` as ``collisions.py`` runs it.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from collisions import named  # this folder's collisions.py

from agents.disc_tracker import DiscTracker
from agents.evaluation import evaluate
from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.policies import load_policy
from bench.map_sizes import named_set
from worlds.config import LEARNING_NAV
from worlds.outcomes import Outcome


def sweep_gap(tracker: DiscTracker, i: int) -> np.ndarray:
    """``(n_actions + 1,)``: the least distance (m) between robot ``i``'s centre driving each action and
    every disc's centre sweeping to its predicted one, less the two radii (negative: contact)."""
    k = tracker.counts[i]
    if k == 0:
        return np.full(len(tracker.ends), np.inf)
    c, nxt = tracker.centres[i, :k], tracker.nxt[i, :k]
    rel0 = c[None, :, :]  # (1, k, 2): disc - robot at t = 0
    rel_v = (nxt - c)[None, :, :] - tracker.ends[:, None, :]  # (A, k, 2)
    vv = (rel_v**2).sum(axis=2)
    t = np.clip(-(rel0 * rel_v).sum(axis=2) / np.where(vv > 0, vv, 1.0), 0.0, 1.0)
    closest = np.hypot(*(rel0 + t[..., None] * rel_v).transpose(2, 0, 1))
    return closest.min(axis=1) - tracker.reach


class Least:
    """The shipped policy through its shield, with the ``least`` escape (module docstring)."""

    def __init__(self, policy) -> None:
        self.policy, self.shield = policy, policy.shield

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.policy(obs)

    def scan_actor(self, n: int):
        shield = self.shield
        tracker = DiscTracker(
            n, shield.ray_angles, shield.max_range, shield.moves, shield.robot_radius, shield.disc_radius
        )

        def act(obs, rays, fresh):
            values, room = self.policy.outputs(obs), shield.room(obs)
            action = shield.pick(values, room)
            tracker.observe(rays, fresh)
            clear = tracker.clear()
            for i in np.flatnonzero(~clear[np.arange(n), action]):
                order = np.argsort(-values[i], kind="stable")
                tries = [*order[room[-1, i][order] >= 0], shield.turn_around]
                good = [a for a in tries if clear[i, a]]
                if good:
                    action[i] = good[0]
                else:
                    gap = sweep_gap(tracker, i)
                    action[i] = max(tries, key=lambda a: gap[a])
            tracker.moved(action)
            return action

        return act


def main() -> None:
    n, sets = int(sys.argv[1]), sys.argv[2:]
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    policy.use_shield(nav)
    rows = []
    for what in sets:
        es = named_set(what, n, seed=1)
        runs = {}
        for name, p in (("shipped", policy), ("least", Least(policy))):
            runs[name] = np.array([e.outcome for e in evaluate(p, es, nav).episodes[es.family]])
        won = {k: v == int(Outcome.GOAL) for k, v in runs.items()}
        gained = int((won["least"] & ~won["shipped"]).sum())
        lost = int((won["shipped"] & ~won["least"]).sum())
        row = {
            "set": what,
            **{f"{k}_success": float(v.mean()) for k, v in won.items()},
            **{f"{k}_outcomes": named(v) for k, v in runs.items()},
            "gained": gained,
            "lost": lost,
            "p": mcnemar_exact(gained, lost),
        }
        rows.append(row)
        print(
            f"{what}: shipped {100 * row['shipped_success']:.1f}% {row['shipped_outcomes']}, least "
            f"{100 * row['least_success']:.1f}% {row['least_outcomes']}, +{gained} -{lost} p {row['p']:.2g}",
            flush=True,
        )
    out = {"episodes": n, "seed": 1, "rows": rows, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
