"""A reading shield with a second frame, screened on validation (issue 39; docs/navigation-by-size.md
section 13): does knowing that a reading is coming closer stop the 64-cell disc collisions?

Section 13 found 7 of 11 disc collisions on validation ``dynamic:64`` escapable by an action the
one-frame shield did not take, and proposed a shield that reads two frames. This is that shield,
built from what the robot has (its readings and its own last action, nothing of the true discs):
each sector's last reading is moved by the last action's motion (turn, then drive ``robot.step``;
``RobotConfig.motion``) into the new frame, the lowest endpoint landing in a sector is what a static
world would show there now, and a reading more than ``tol`` metres below that (and under 3 m) is
taken as something coming at the robot: the shield judges actions against it shortened by
``speed`` metres (the world's discs move 0.2 m a step) - every action (``TOL/SPEED``), or only the
actions that drive towards that sector, within 90 degrees of their turn (``TOL/SPEED/ahead``): an
action's capsule holds the robot's own disc, so a reading shortened below the robot's radius plus
the margin leaves no action clear but the turn-around in place. The network sees the observation
unchanged.

Each variant runs the same episodes as the shipped shield (validation seed 1, ``bench.map_sizes``'s
set); printed per variant: success, outcomes, McNemar against the shipped shield,
and over every robot-step of the evaluation wave how often the second frame changed the action
and how often the change was the turn-around. The last line is one JSON object.

    PYTHONPATH=. python results/navigation/discs/two_frames.py SET EPISODES TOL/SPEED[/ahead] ...

``SET`` is ``dynamic:SIZE`` (the question) or ``static:SIZE`` (no discs: every action the second
frame changes there is the robot's own parallax read as motion).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate
from bench.map_sizes import episode_arrays, named_set
from worlds.config import LEARNING_NAV, NavConfig
from worlds.outcomes import Outcome

NEAR = 3.0
"""metres: only readings nearer than this count as coming (a disc farther off cannot reach the
robot within one step)"""


class TwoFrameShield:
    """``policy``'s network through its reading shield, the shield reading two frames. One instance
    per evaluation wave: row ``i`` is robot ``i`` throughout (the runner's waves)."""

    def __init__(self, policy, nav: NavConfig, tol: float, speed: float, ahead_only: bool) -> None:
        self.policy, self.shield, self.tol, self.speed = policy, policy.shield, tol, speed
        robot, sensors = nav.robot, nav.sensors
        self.phi, self.width = sensors.beam_angles, sensors.fov / sensors.n_beams
        motions = [robot.motion(a) for a in range(robot.n_actions + 1)]  # the turn-around is the last
        self.turn, self.step = (np.array(m) for m in zip(*motions, strict=True))
        facing = np.cos(self.phi[None, :] - np.asarray(robot.turns)[:, None]) > 0  # (K, J)
        self.ahead = facing if ahead_only else np.ones_like(facing)
        self.previous: tuple[np.ndarray, np.ndarray] | None = None
        self.steps = self.changed = self.changed_to_turn_around = 0

    def expected(self, readings: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Per sector of the new frame, the lowest of the last frame's endpoints moved into it by the
        robot's last action (inf where none lands)."""
        turn, step = self.turn[actions][:, None], self.step[actions][:, None]
        x = readings * np.cos(self.phi) - step * np.cos(turn)
        y = readings * np.sin(self.phi) - step * np.sin(turn)
        nx, ny = np.cos(turn) * x + np.sin(turn) * y, -np.sin(turn) * x + np.cos(turn) * y
        sector = np.round((np.arctan2(ny, nx) - self.phi[0]) / self.width).astype(int) % len(self.phi)
        out = np.full(readings.shape, np.inf)
        rows = np.broadcast_to(np.arange(len(readings))[:, None], sector.shape)
        np.minimum.at(out, (rows, sector), np.hypot(nx, ny))
        return out

    def choose(self, outputs: np.ndarray, readings: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """``ReadingShield.choose`` with action ``k`` judged against ``seen`` in the sectors it drives
        towards (``ahead_only``: within 90 degrees of its turn; else every sector) and against
        ``readings`` elsewhere."""
        shield = self.shield
        per_action = np.where(self.ahead[None], seen[:, None, :], readings[:, None, :])  # (N, K, J)
        room = (per_action[None] - shield.reach[:, None]).min(axis=3)  # (margins, N, K)
        return shield.pick(outputs, room)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        shield = self.shield
        readings = obs[:, shield.readings].astype(np.float64) * shield.max_range
        outputs = self.policy.outputs(obs)
        seen = readings
        if self.previous is not None and len(self.previous[0]) == len(obs):
            expected = self.expected(*self.previous)
            coming = np.isfinite(expected) & (readings < expected - self.tol) & (readings < NEAR)
            seen = np.where(coming, np.maximum(readings - self.speed, 0.0), readings)
        action = self.choose(outputs, readings, seen)
        one_frame = shield.choose(outputs, obs)
        self.steps += len(obs)
        self.changed += int((action != one_frame).sum())
        self.changed_to_turn_around += int(
            ((action != one_frame) & (action == self.shield.turn_around)).sum()
        )
        self.previous = (readings, action)
        return action


def outcomes(array: np.ndarray) -> dict[str, int]:
    return {o.name: int((array == int(o)).sum()) for o in Outcome if (array == int(o)).any()}


def main() -> None:
    what, episodes = sys.argv[1], int(sys.argv[2])
    variants = [(float(v.split("/")[0]), float(v.split("/")[1]), v.endswith("/ahead")) for v in sys.argv[3:]]
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    policy.use_shield(nav)
    es = named_set(what, episodes, seed=1)
    base = episode_arrays(evaluate(policy, es, nav), es.family)["outcome"]
    won = base == int(Outcome.GOAL)
    print(f"{what} one frame (shipped): {100 * won.mean():.1f}%", outcomes(base), flush=True)
    rows = []
    for tol, speed, ahead_only in variants:
        two = TwoFrameShield(policy, nav, tol, speed, ahead_only)
        out = episode_arrays(evaluate(two, es, nav), es.family)["outcome"]
        won2 = out == int(Outcome.GOAL)
        gained, lost = int((won2 & ~won).sum()), int((~won2 & won).sum())
        row = {
            "tol": tol,
            "ahead_only": ahead_only,
            "speed": speed,
            "success": float(won2.mean()),
            "outcomes": outcomes(out),
            "gained": gained,
            "lost": lost,
            "p": mcnemar_exact(gained, lost),
            "changed_share": two.changed / two.steps,
            "changed_to_turn_around": two.changed_to_turn_around,
            "changed": two.changed,
        }
        rows.append(row)
        where = "the sectors each action drives towards" if ahead_only else "every sector"
        print(f"  two frames, tol {tol} m, speed {speed} m, in {where}: {100 * row['success']:.1f}%",
              row["outcomes"],
              f"+{gained} -{lost} p {row['p']:.2g}; the action changed on "
              f"{100 * row['changed_share']:.1f}% of robot-steps, {two.changed_to_turn_around} of "
              f"{two.changed} to the turn-around", flush=True)  # fmt: skip
    print(json.dumps({
        "set": what, "seed": 1, "episodes": episodes,
        "one_frame": {"success": float(won.mean()), "outcomes": outcomes(base)},
        "two_frames": rows, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }))  # fmt: skip


if __name__ == "__main__":
    main()
