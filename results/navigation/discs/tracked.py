"""The disc tracker's parts, apart (issue 39; docs/navigation-by-size.md section 13): finding the
discs, and predicting where they go.

``oracle.py`` put the ceiling of a one-step view of the discs at 97.7% on validation ``dynamic:64``
(the shipped shield 95.0%). A tracker finds each disc and predicts its next centre. Two detectors:

- ``true``: each disc's true centre, from the world, as a perfect detector would report it;
- ``scan``: discs found in the robot's own scan (the 96 rays the world casts, of which the
  observation keeps the 24 sector minima; a real robot's LaserScan), as a lidar tracker finds them:
  consecutive ray endpoints closer than ``JUMP`` form a segment; a segment nearer than the rays on
  both sides of it (by ``JUMP``: something standing in front) and no wider than a disc
  (``2 * radius + 0.15`` m) is a disc, centred ``radius`` behind its nearest endpoint. Between frames
  the robot's own motion is taken as its action's, noise-free (dead reckoning: what it commanded).

Both predict alike: a disc's velocity is its last displacement (two frames: nearest centre within
``MATCH`` m of the last frame's, else standing), its next centre one more such step. Behind the
shipped shield, where the shield's choice would sweep the robot (noise-free: turn, then
``robot.step`` ahead; the turn-around in place) within the robot's radius plus the disc's plus the
margin of a disc's predicted sweep (``worlds.obstacles.swept_contact``, the world's own test), the
robot takes the first action that keeps clear of every predicted disc: the network's preference
among the shield's clear actions, then among the others, then the turn-around (``:turn``: the
turn-around before the others; ``:margins``: the same, the clear actions taken in the shield's own
order, those clear with its room to spare first; ``:clear``: never the others); where none does,
the shield's choice. Everything is in the robot's frame.

Variants ``DETECTOR:MARGIN[:turn|:margins|:clear]``. Printed per variant: success, outcomes,
McNemar against the shipped shield on the same episodes, and how often the prediction changed the
action; the last line is one JSON object.

    PYTHONPATH=. python results/navigation/discs/tracked.py SIZE EPISODES VARIANT ... [--static]

``--static``: validation ``static:SIZE`` instead, where nothing moves: every action the tracker
changes there is a wall feature taken for a moving disc.

The episodes and world are ``collisions.py``'s (``shipped_on``).
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np
from collisions import named, shipped_on  # this folder's collisions.py: the same episodes and world

from agents.evaluation.compare import mcnemar_exact
from agents.shield import MARGINS
from worlds.env import NavigationEnv
from worlds.obstacles import swept_contact
from worlds.outcomes import Outcome

JUMP = 0.25
"""metres between consecutive ray endpoints that split the scan into segments"""
MATCH = 0.6
"""metres a disc's centre may be from its last-frame centre to be the same disc (it moves 0.2 m a
step; the robot's own motion is known only as commanded)"""


def true_discs(env: NavigationEnv) -> np.ndarray:
    """``(k, 2)``: the discs' true centres in the world frame (a perfect detector)."""
    arrays = env.batch.disc_arrays
    k = int(arrays[10][0])
    return np.stack([arrays[0][0, :k], arrays[1][0, :k]], axis=1)


def scan_discs(ranges: np.ndarray, angles: np.ndarray, radius: float, max_range: float) -> np.ndarray:
    """``(k, 2)``: the disc centres a lidar tracker finds in one scan, in the robot's frame."""
    points = np.stack([ranges * np.cos(angles), ranges * np.sin(angles)], axis=1)
    n = len(ranges)
    split = np.hypot(*(points - np.roll(points, -1, axis=0)).T) > JUMP  # between ray i and i + 1
    if not split.any():
        return np.zeros((0, 2))
    first = int(np.argmax(split)) + 1  # a segment starts here
    centres, start = [], first
    for step in range(1, n + 1):
        i = (first + step - 1) % n
        if split[i]:  # the segment start .. i ends
            members = [(start + m) % n for m in range((i - start) % n + 1)]
            before, after = (start - 1) % n, (i + 1) % n
            near = ranges[members]
            in_front = ranges[before] > near.min() + JUMP and ranges[after] > near.min() + JUMP
            width = np.hypot(*(points[members[0]] - points[members[-1]]))
            if in_front and width <= 2 * radius + 0.15 and near.max() < max_range - 1e-6:
                j = members[int(np.argmin(near))]
                centres.append((ranges[j] + radius) * np.array([math.cos(angles[j]), math.sin(angles[j])]))
            start = (i + 1) % n
    return np.asarray(centres).reshape(-1, 2)


class Tracker:
    """One robot's discs from frame to frame: centres in the robot's frame, velocities from the last
    displacement (two frames)."""

    def __init__(self, nav, detector: str, radius: float) -> None:
        self.nav, self.detector, self.radius = nav, detector, radius  # radius: the discs' (the set's)
        self.angles = nav.sensors.ray_angles
        self.previous: np.ndarray | None = None  # last frame's centres, in the current robot frame

    def reset(self) -> None:
        self.previous = None

    def frame(self, env: NavigationEnv) -> tuple[np.ndarray, np.ndarray]:
        """This frame's disc centres and predicted next centres, in the robot's frame."""
        batch = env.batch
        if self.detector == "true":
            x, y, theta = float(batch.x[0]), float(batch.y[0]), float(batch.theta[0])
            c, s = math.cos(theta), math.sin(theta)
            rel = true_discs(env) - [x, y]
            centres = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
        else:
            centres = scan_discs(batch.rays[0], self.angles, self.radius, self.nav.sensors.max_range)
        velocity = np.zeros_like(centres)
        if self.previous is not None and len(self.previous) and len(centres):
            gaps = np.hypot(*(centres[:, None, :] - self.previous[None, :, :]).transpose(2, 0, 1))
            nearest = gaps.argmin(axis=1)
            matched = gaps[np.arange(len(centres)), nearest] <= MATCH
            velocity[matched] = centres[matched] - self.previous[nearest[matched]]
        self.current = centres
        return centres, centres + velocity

    def moved(self, env: NavigationEnv, action: int, truth: tuple[float, float, float]) -> None:
        """Carry this frame's centres into the next robot frame: by the true motion for ``true``
        (what a perfect detector's centres already are), by the commanded motion for ``scan``."""
        if self.detector == "true":
            x0, y0, th0 = truth
            batch = env.batch
            dx, dy, turn = float(batch.x[0]) - x0, float(batch.y[0]) - y0, float(batch.theta[0]) - th0
            c0, s0 = math.cos(th0), math.sin(th0)
            step_x, step_y = c0 * dx + s0 * dy, -s0 * dx + c0 * dy
        else:
            turn, step = self.nav.robot.motion(action)
            step_x, step_y = step * math.cos(turn), step * math.sin(turn)
        shifted = self.current - [step_x, step_y]
        c, s = math.cos(turn), math.sin(turn)
        self.previous = np.stack(
            [c * shifted[:, 0] + s * shifted[:, 1], -s * shifted[:, 0] + c * shifted[:, 1]], 1
        )


def clear_of(nav, action: int, now: np.ndarray, nxt: np.ndarray, radius: float, margin: float) -> bool:
    """Does ``action``, noise-free from the robot's frame, keep clear of every disc's sweep from
    ``now`` to ``nxt``?"""
    turn, step = nav.robot.motion(action)
    x1, y1 = step * math.cos(turn), step * math.sin(turn)
    reach = nav.robot.radius + radius + margin
    return not any(swept_contact(0.0, 0.0, x1, y1, *now[j], *nxt[j], reach) for j in range(len(now)))


def run(policy, nav, env, es, variant: str | None) -> tuple[np.ndarray, dict[str, int]]:
    """Each episode's outcome (the shipped shield when ``variant`` is None), and how often the
    prediction changed the action."""
    shield = policy.shield
    outcomes, counts = [], {"steps": 0, "changed": 0, "none_clear": 0, "discs_seen": 0}
    tracker = None
    if variant is not None:
        detector, margin, *rest = variant.split(":")
        margin, then, tracker = (
            float(margin),
            (rest or ["others"])[0],
            Tracker(nav, detector, es.obstacles.radius),
        )
    for task, seed in zip(es.tasks, es.seeds, strict=True):
        obs, info = env.reset(seed=seed, options={"task": task})
        if tracker is not None:
            tracker.reset()
        done = False
        while not done:
            outputs = policy.outputs(obs[None])
            action = int(shield.choose(outputs, obs[None])[0])
            if tracker is not None:
                counts["steps"] += 1
                now, nxt = tracker.frame(env)
                counts["discs_seen"] += len(now)
                if not clear_of(nav, action, now, nxt, tracker.radius, margin):
                    rooms = shield.room(obs[None])[:, 0]  # per margin of the shield, the widest first
                    room = rooms[len(MARGINS) - 1]  # the capsule alone
                    order = np.argsort(-outputs[0], kind="stable")
                    if then == "margins":  # the shield's own order: clear with room to spare first
                        tries = list(dict.fromkeys(a for r in rooms for a in order if r[a] >= 0))
                    else:
                        tries = [a for a in order if room[a] >= 0]
                    others = [] if then == "clear" else [a for a in order if room[a] < 0]
                    tries += (
                        [shield.turn_around, *others]
                        if then in ("turn", "margins")
                        else [*others, shield.turn_around]
                    )
                    alternatives = (int(a) for a in tries if a != action)
                    chosen = next(
                        (a for a in alternatives if clear_of(nav, a, now, nxt, tracker.radius, margin)), None
                    )
                    if chosen is None:
                        counts["none_clear"] += 1
                    else:
                        action, counts["changed"] = chosen, counts["changed"] + 1
                truth = (float(env.batch.x[0]), float(env.batch.y[0]), float(env.batch.theta[0]))
            obs, _, terminated, truncated, info = env.step(action)
            if tracker is not None:
                tracker.moved(env, action, truth)
            done = terminated or truncated
        outcomes.append(int(info["outcome"]))
    return np.asarray(outcomes), counts


def main() -> None:
    size, n = int(sys.argv[1]), int(sys.argv[2])
    kind = "static" if "--static" in sys.argv[3:] else "dynamic"
    variants = [v for v in sys.argv[3:] if not v.startswith("--")]
    policy, nav, es, env = shipped_on(size, n, kind)
    shipped, _ = run(policy, nav, env, es, None)
    won = shipped == int(Outcome.GOAL)
    print(f"{kind}:{size} shipped {100 * won.mean():.1f}% {named(shipped)}", flush=True)
    rows = []
    for variant in variants:
        outcomes, counts = run(policy, nav, env, es, variant)
        won2 = outcomes == int(Outcome.GOAL)
        gained, lost = int((won2 & ~won).sum()), int((won & ~won2).sum())
        row = {"variant": variant, "success": float(won2.mean()), "outcomes": named(outcomes), **counts}
        rows.append(row | {"gained": gained, "lost": lost, "p": mcnemar_exact(gained, lost)})
        head = (
            f"  {variant}: {100 * won2.mean():.1f}% {row['outcomes']} +{gained} -{lost} p {rows[-1]['p']:.2g}"
        )
        print(
            f"{head}; changed {counts['changed']} of {counts['steps']} actions, nothing clear at "
            f"{counts['none_clear']}, {counts['discs_seen'] / max(counts['steps'], 1):.2f} discs seen a step",
            flush=True,
        )
    out = {
        "set": f"{kind}:{size}",
        "episodes": n,
        "seed": 1,
        "shipped": {"success": float(won.mean())},
        "tracked": rows,
    }
    out["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
