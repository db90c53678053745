"""Screen of the shield's turn-around and margins on the validation seed (issue 39), the choices
behind agents/shield.py's MARGINS and its turn-around.

Each spec is ``M1/M2/...[:t]``: margins in metres added to the robot's radius, tried in turn (the
policy's argmax among the actions clear with the first margin, else with the second, ...); when
none is clear at the last, the roomiest action at the last margin, or with ``:t`` the robot's
turn-around (``RobotConfig.turn_around``: half a turn in place). ``0`` is the shield as it was
before the turn-around; ``0.1/0:t`` is the shipped one. The same episodes for every spec; one JSON
line per size and set, with the number of turn-arounds taken.

    PYTHONPATH=. python results/navigation/shield/screen_turn_around.py 64 300 static 0 0:t 0.1/0:t

The recorded lines (``screen_turn_around.jsonl``, 2026-12-07) came from these runs, each line the
last of its run:

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
from agents.shield import reach_table
from worlds.config import LEARNING_NAV, ObstacleConfig
from worlds.outcomes import Outcome
from worlds.perception import frame_layout

VALIDATION_SEED = 1
POLICY = load_policy("pretrained/nnql")
NAV = POLICY.nav_config(LEARNING_NAV)
READINGS = slice(*frame_layout(NAV)["readings"])


class Screened:
    def __init__(self, spec: str):
        margins, _, fallback = spec.partition(":")
        self.observation = POLICY.observation
        radii = (NAV.robot.radius + float(m) for m in margins.split("/"))
        self.reach = [reach_table(replace(NAV, robot=replace(NAV.robot, radius=r))) for r in radii]
        self.turn_around = fallback == "t"
        self.turned = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        q = POLICY.outputs(obs)
        readings = obs[:, READINGS].astype(np.float64) * NAV.sensors.max_range
        rooms = [(readings[:, None, :] - reach[None]).min(axis=2) for reach in self.reach]
        action = np.full(len(obs), NAV.robot.turn_around) if self.turn_around else rooms[-1].argmax(axis=1)
        for room in reversed(rooms):
            clear = room >= 0
            action = np.where(clear.any(axis=1), np.where(clear, q, -np.inf).argmax(axis=1), action)
        self.turned += int((action == NAV.robot.turn_around).sum())
        return action.astype(np.int64)


def main() -> None:
    size, episodes, kind, *specs = sys.argv[1:]
    size, episodes = int(size), int(episodes)
    discs = ObstacleConfig(count=max(4, round(4 * (size / 32) ** 2)))
    family = "unseen" if kind == "static" else "dynamic"
    es = make_eval_set(family, episodes, seed=VALIDATION_SEED, size=size, obstacles=discs)
    out: dict = {"size": size, "kind": kind, "episodes": episodes, "seed": VALIDATION_SEED}
    for spec in specs:
        policy = Screened(spec)
        o = np.array([e.outcome for e in evaluate(policy, es).episodes[family]])
        out[spec] = {
            "success": round(float((o == int(Outcome.GOAL)).mean()), 4),
            "collision_static": int((o == int(Outcome.COLLISION_STATIC)).sum()),
            "collision_dynamic": int((o == int(Outcome.COLLISION_DYNAMIC)).sum()),
            "timeout": int((o == int(Outcome.TIMEOUT)).sum()),
            "turn_arounds": policy.turned,
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
