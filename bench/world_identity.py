"""Do two checkouts step the same world? Fixed rollouts of the vector env in this tree and in another
(e.g. main before a speed change), each in its own subprocess, compared bit for bit: observations,
rewards and terminal observations, 400 steps of 24 robots per case.

Cases: ``LEARNING_NAV`` on mixed / rooms / rects / discs maps, with the known-map subgoal, with the
own-map patch + frame stack + previous action, ``NavConfig()`` (8 beams) and ``LEARNING_NAV`` with
0-4 moving discs; random and goal-seeking actions each.

    python -m bench.world_identity --against /path/to/other/checkout   # JSON on the last line
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = """
import dataclasses, sys
import numpy as np
from worlds.config import LEARNING_NAV, NavConfig, with_moving_discs
from worlds.heuristics import goal_seeking_policy
from worlds.vector_env import NavigationVectorEnv
def obs_of(**kw):
    return dataclasses.replace(LEARNING_NAV, observation=dataclasses.replace(LEARNING_NAV.observation, **kw))
configs = {"learning": LEARNING_NAV, "known": obs_of(subgoal="known_map"),
           "patch": obs_of(patch_size=8, frame_stack=3, previous_action=True), "default": NavConfig(),
           "discs": with_moving_discs(LEARNING_NAV, 4)}
out = {}
for name, config in configs.items():
    for maps in ("mixed:16", "rooms:12x20", "rects:16", "discs:16") if name == "learning" else ("mixed:16",):
        for policy in ("random", "goal"):
            env = NavigationVectorEnv(24, config, maps=maps, threads=1)
            obs, _ = env.reset(seed=5)
            seek, width = goal_seeking_policy(config), config.sensors.n_beams + 3
            rng = np.random.default_rng(5)
            frames, rewards, finals = [obs.copy()], [], []
            for _ in range(400):
                actions = seek(obs[:, :width]) if policy == "goal" else rng.integers(5, size=24)
                obs, reward, terminated, truncated, _ = env.step(actions)
                frames.append(obs.copy())
                rewards.append(reward.copy())
                finals.append(np.where((terminated | truncated)[:, None], env.batch.final_obs, 0.0))
            key = f"{name} {maps} {policy}"
            out[key + " obs"], out[key + " reward"] = np.stack(frames), np.stack(rewards)
            out[key + " final_obs"] = np.stack(finals)
np.savez(sys.argv[1], **out)
"""


def rollouts(tree: Path, path: Path) -> dict[str, np.ndarray]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    subprocess.run([sys.executable, "-c", CHILD, str(path)], cwd=tree, env=env, check=True)
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--against", required=True, metavar="PATH", help="the other checkout")
    args = parser.parse_args()
    here, other = Path(__file__).resolve().parent.parent, Path(args.against).resolve()
    with tempfile.TemporaryDirectory() as tmp:
        mine, theirs = rollouts(here, Path(tmp, "a.npz")), rollouts(other, Path(tmp, "b.npz"))
    differ = [k for k in theirs if k not in mine or mine[k].tobytes() != theirs[k].tobytes()]
    for key in theirs:
        print(f"{key:40s} {'identical' if key not in differ else 'DIFFERENT'} {theirs[key].shape}")
    print(json.dumps({"bench": "world_identity", "this_tree": str(here), "other_tree": str(other),
                      "arrays": len(theirs), "different": differ, "identical": not differ}))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
