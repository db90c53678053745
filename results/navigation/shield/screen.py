"""Screens of the reading shield on the validation seed (issue 39), the choices behind agents/shield.py.

Each spec is ``M1/M2/...[:OPTIONS]``: margins in metres added to the robot's radius, tried in turn
(the policy's argmax among the actions clear with the first margin, else with the second, ...);
when none is clear at the last, the roomiest action at the last margin, or with option ``t`` the
robot's turn-around (``RobotConfig.turn_around``: half a turn in place; the row then counts the
turn-arounds taken). Option ``2`` keeps first the actions after which some action is clear again (a
two-step look-ahead from the same readings, every point of both capsules inside the readings' free
region). ``0`` is the shield before the turn-around (the roomiest action when nothing is clear);
``0.1/0:t`` is today's; ``none`` the network alone. The same episodes for every spec; one JSON line.

    PYTHONPATH=. python results/navigation/shield/screen.py 48 300 static none 0 0.03 0.06 0.1 0.05/0 0:2
    PYTHONPATH=. python results/navigation/shield/screen.py 64 300 static 0 0:t 0.1/0:t

``screen.jsonl`` (the margins and the look-ahead, before the turn-around) came from the first form
for 32, 48, 64 static and 48 dynamic. ``screen_turn_around.jsonl`` (2026-12-07, written by this
screen's turn-around when it stood in a file of its own, the same code) came from these runs, each
line the last of its run:

    for s in 16 32 48 64; do for k in static dynamic; do
      ... $s 300 $k 0 0:t 0.03/0:t 0.06/0:t 0.1/0:t
      ... $s 300 $k 0.15/0:t 0.2/0:t 0.2/0.1/0:t 0.3/0.1/0:t
    done; done

(and at 64 static ``0.03:t 0.06:t 0.06/0.03/0:t``: without a fallback to the plain capsule a margin
turns round far more often and times out).
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.shield import exit_distance, reach_table
from bench.map_sizes import discs_for
from worlds.config import LEARNING_NAV, NavConfig, ObstacleConfig
from worlds.outcomes import Outcome
from worlds.perception import frame_layout

VALIDATION_SEED = 1
POLICY = load_policy("pretrained/nnql")
NAV = POLICY.nav_config(LEARNING_NAV)
READINGS = slice(*frame_layout(NAV)["readings"])


def with_margin(margin: float) -> NavConfig:
    return replace(NAV, robot=replace(NAV.robot, radius=NAV.robot.radius + margin))


def second_reach(nav: NavConfig, samples: int = 4000) -> np.ndarray:
    """``(K, K, n_beams)``: how far the capsule of action k2 taken after action k reaches into each
    sector (the farthest of the points of its boundary, sampled), measured from the first pose."""
    robot, sensors = nav.robot, nav.sensors
    half = sensors.fov / sensors.n_beams / 2
    out = np.zeros((robot.n_actions, robot.n_actions, sensors.n_beams))
    for k, turn in enumerate(robot.turns):
        first = robot.step * np.array([np.cos(turn), np.sin(turn)])
        for k2, turn2 in enumerate(robot.turns):
            heading = turn + turn2
            delta = np.linspace(-np.pi, np.pi, samples)  # the capsule's boundary seen from `first`
            rho = exit_distance(delta, robot.step, robot.radius)
            x = first[0] + rho * np.cos(delta + heading)
            y = first[1] + rho * np.sin(delta + heading)
            dist, ang = np.hypot(x, y), np.arctan2(y, x)
            for j, centre in enumerate(sensors.beam_angles):
                inside = np.abs((ang - centre + np.pi) % (2 * np.pi) - np.pi) <= half
                out[k, k2, j] = dist[inside].max() if inside.any() else 0.0
    return out


class Screened:
    def __init__(self, spec: str):
        margins, _, options = spec.partition(":")
        self.observation = POLICY.observation
        self.reach = [reach_table(with_margin(float(m))) for m in margins.split("/")]
        self.two, self.turn_around = "2" in options, "t" in options
        self.turned = 0
        if self.two:
            self.second = second_reach(NAV)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        q = POLICY.outputs(obs)
        readings = obs[:, READINGS].astype(np.float64) * NAV.sensors.max_range
        rooms = [(readings[:, None, :] - reach[None]).min(axis=2) for reach in self.reach]
        action = np.full(len(obs), NAV.robot.turn_around) if self.turn_around else rooms[-1].argmax(axis=1)
        for room in reversed(rooms):
            clear = room >= 0
            action = np.where(clear.any(axis=1), np.where(clear, q, -np.inf).argmax(axis=1), action)
        if self.two:
            readings = obs[:, : NAV.sensors.n_beams] * NAV.sensors.max_range
            again = ((readings[:, None, None, :] - self.second[None]).min(axis=3) >= 0).any(axis=2)
            safe = (rooms[0] >= 0) & again
            action = np.where(safe.any(axis=1), np.where(safe, q, -np.inf).argmax(axis=1), action)
        self.turned += int((action == NAV.robot.turn_around).sum())
        return action.astype(np.int64)


def main() -> None:
    size, episodes, kind, *specs = sys.argv[1:]
    size, episodes = int(size), int(episodes)
    discs = ObstacleConfig(count=discs_for(size))
    family = "unseen" if kind == "static" else "dynamic"
    es = make_eval_set(family, episodes, seed=VALIDATION_SEED, size=size, obstacles=discs)
    out: dict = {"size": size, "kind": kind, "episodes": episodes, "seed": VALIDATION_SEED}
    for spec in specs:
        policy = POLICY if spec == "none" else Screened(spec)
        o = np.array([e.outcome for e in evaluate(policy, es).episodes[family]])
        out[spec] = {
            "success": round(float((o == int(Outcome.GOAL)).mean()), 4),
            "collision_static": int((o == int(Outcome.COLLISION_STATIC)).sum()),
            "collision_dynamic": int((o == int(Outcome.COLLISION_DYNAMIC)).sum()),
            "timeout": int((o == int(Outcome.TIMEOUT)).sum()),
        }
        if policy is not POLICY and policy.turn_around:
            out[spec]["turn_arounds"] = policy.turned
    print(json.dumps(out))


if __name__ == "__main__":
    main()
