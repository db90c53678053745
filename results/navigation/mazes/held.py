"""Does a held heading fix the 1 m mazes, and what does it do elsewhere? (issue 39;
docs/navigation-by-size.md section 14)

Section 14 found the robot's accumulated heading error to be what fails in 1 m corridors: every
action turns by a multiple of 45 degrees, so ``RobotConfig.rot_noise`` adds up as a random walk. A
robot that holds its heading (``RobotConfig.held_headings`` 8: before each action the heading is
turned to the nearest compass heading, as a base does with its odometry or IMU, and as
``navlearn drive`` turns by odometry) keeps one step's error only. This runs the shipped policy
(``pretrained/nnql``, through its reading shield, not retrained) and the subgoal follower in the
world as it is and with the held heading, on the same episodes (validation seed 1), per SET:
``maze:SIZE`` (the generated 1 m mazes, ``families=("maze",)``) or ``bench.map_sizes``'s
``static:SIZE`` / ``dynamic:SIZE``. Printed per set and method: success, outcomes, SPL, and McNemar
of held against not held; the last line is one JSON object with every row and the heading drift of
20,000 robots driving straight along a 1 m corridor either way.

    PYTHONPATH=. python results/navigation/mazes/held.py EPISODES SET ... [--exact-step]

``--exact-step`` adds a third world: the held heading and no noise on the distance driven
(``trans_noise`` 0), the control that says what of the rest is the distance's noise (along a
corridor it adds up too, and a turn into a side corridor makes it a sideways offset).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

import numpy as np
from mazes import drift  # this folder's mazes.py: the same corridor and robots

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from bench.map_sizes import episode_arrays, figures, named_set
from worlds.config import LEARNING_NAV
from worlds.heuristics import subgoal_scores
from worlds.outcomes import Outcome

HELD = 8
"""compass headings held: every 45 degrees, the actions' turns"""


def eval_set(what: str, episodes: int):
    kind, size = what.split(":")
    if kind == "maze":
        return make_eval_set("unseen", episodes, seed=1, size=int(size), families=("maze",))
    return named_set(what, episodes, seed=1)


def outcomes(array: np.ndarray) -> dict[str, int]:
    return {o.name: int((array == int(o)).sum()) for o in Outcome if (array == int(o)).any()}


def line(world: str, figures_of: dict) -> str:
    out = f"{world} {100 * figures_of['success']:.1f}% (SPL {figures_of['spl']:.2f}) {figures_of['outcomes']}"
    if "p" in figures_of:
        out += f" +{figures_of['gained']} -{figures_of['lost']} p {figures_of['p']:.2g}"
    return out


def main() -> None:
    episodes, sets = int(sys.argv[1]), [a for a in sys.argv[2:] if not a.startswith("--")]
    policy = load_policy("pretrained/nnql")
    nav = policy.nav_config(LEARNING_NAV)
    worlds = {"as_is": nav, "held": replace(nav, robot=replace(nav.robot, held_headings=HELD))}
    if "--exact-step" in sys.argv:
        worlds["held_exact_step"] = replace(
            nav, robot=replace(nav.robot, held_headings=HELD, trans_noise=0.0)
        )
    rows = []
    for what in sets:
        es = eval_set(what, episodes)
        for name, act in (("policy", None), ("follower", None)):
            won, row = {}, {"set": what, "method": name}
            for world, wnav in worlds.items():
                if name == "policy":
                    act = policy.use_shield(wnav)
                else:
                    scores, shield = subgoal_scores(wnav), policy.use_shield(wnav).shield

                    def act(obs, scores=scores, shield=shield):
                        return shield.choose(scores(obs), obs)

                arrays = episode_arrays(evaluate(act, es, wnav), es.family)
                won[world] = arrays["outcome"] == int(Outcome.GOAL)
                fig = figures(arrays, es.shortest)
                row[world] = {
                    "success": fig["success"],
                    "spl": fig["spl"],
                    "outcomes": outcomes(arrays["outcome"]),
                }
            for world in list(worlds)[1:]:
                gained, lost = (
                    int((won[world] & ~won["as_is"]).sum()),
                    int((won["as_is"] & ~won[world]).sum()),
                )
                row[world] |= {"gained": gained, "lost": lost, "p": mcnemar_exact(gained, lost)}
            rows.append(row)
            print(f"{what} {name}:", "; ".join(line(world, row[world]) for world in worlds), flush=True)
    out = {"episodes": episodes, "seed": 1, "held_headings": HELD, "rows": rows}
    out["drift"] = {world: drift(w.robot) for world, w in worlds.items()}
    out["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
