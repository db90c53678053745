"""Replay of one smoothers_world episode with the robot given the map (validation seed 1), step by step:
the robot's pose, the waypoint and the plan's length, the network's Q-values and argmax, the room the
shield's readings leave each action with its 0.1 m to spare and with none, and the action taken.

    PYTHONPATH=. python results/maps/known_map_door.py [EPISODE] [own|known]   # default 12 known

Recorded in known_map_door.log (docs/navigation-by-size.md, section 16).
"""

import sys

import numpy as np

from agents.evaluation import make_map_eval_set
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import fixed_sampler
from worlds.outcomes import OUTCOME_NAMES
from worlds.tasks import parse_map_spec
from worlds.vector_env import NavigationVectorEnv

SPEC = "../shared/data/map_server/smoothers_world.yaml"


def main() -> None:
    episode = int(sys.argv[1]) if len(sys.argv) > 1 else 12
    known = (sys.argv[2] if len(sys.argv) > 2 else "known") == "known"
    es = make_map_eval_set(parse_map_spec(SPEC), 100, seed=1)
    policy = load_policy("pretrained/nnql")
    if known:
        policy.use_known_map()
    nav = policy.nav_config()
    policy.use_shield(nav)
    task = es.tasks[episode]
    env = NavigationVectorEnv(1, nav, maps=fixed_sampler([task], es.family))
    obs, _ = env.reset(seed=[es.seeds[episode]], options={"tasks": [task]})
    act, fresh = policy.scan_actor(1), np.ones(1, bool)
    perception, shield = env.batch.perception, policy.shield
    print(f"episode {episode} ({'known map' if known else 'own map'}): {task}")
    for step in range(nav.max_steps * 10):
        q, room = policy.outputs(obs)[0], shield.room(obs)[:, 0]
        action = act(obs, env.batch.rays, fresh)
        fresh[:] = False
        where = np.round(env.poses()[0], 2), np.round(perception.waypoint[0], 2)
        plan = round(float(perception.path_length[0]), 2)
        print(step, "pose", where[0], "waypoint", where[1], "plan", plan,
              "argmax", int(q.argmax()), "q", np.round(q, 2), "room 0.1", np.round(room[0], 2),
              "room 0", np.round(room[-1], 2), "action", int(action[0]))  # fmt: skip
        obs, _, terminated, truncated, info = env.step(action)
        if terminated[0] or truncated[0]:
            print("ended after", step + 1, "steps:", OUTCOME_NAMES[info["final_info"]["outcome"][0]])
            break


if __name__ == "__main__":
    main()
