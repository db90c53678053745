"""Recording expert demonstrations in the environment (thesis ch. 3, "multiple demonstrations").

The expert (:class:`agents.planning.expert.Expert`) drives the robot of a
``worlds.env.NavigationEnv``; each episode is kept as the robot's own
observations, actions, rewards, terminations and truncations, with its poses and
task, as an :class:`agents.demos.Demo`. With ``noise > 0`` each step takes, with
that probability, a random action among those that do not hit a wall, standing
in for an imperfect human demonstrator; the expert replans from wherever that
leaves the robot. The action actually taken is the one recorded, and the
expert's own choice is kept beside it (``Demo.expert_actions``): imperfect demos
for NIRL, and the corrective labels DART (Laskey et al. 2017) trains on.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agents.demos import Demo, make_demo
from agents.planning.expert import Expert, ExpertConfig
from agents.planning.lattice import LatticeConfig
from worlds.config import NavConfig
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome


@dataclass
class DemoStats:
    """What a generation run produced."""

    episodes: int = 0
    kept: int = 0
    steps: int = 0
    outcomes: dict[str, int] | None = None
    replans: int = 0


def record_episode(
    env, expert: Expert, seed: int, noise: float, rng: np.random.Generator
) -> tuple[Demo, int]:
    """Run one expert episode in ``env`` (a NavigationEnv) reset with ``seed``; returns the
    demonstration and the number of replans."""
    obs, info = env.reset(seed=seed)
    task = info["task"]
    expert.reset(task, info["pose"])
    observations, poses = [obs], [info["pose"]]
    actions, chosen, rewards, terms, truncs = [], [], [], [], []
    done = False
    while not done:
        action = expert.act(info["pose"], obs)
        chosen.append(action)
        if noise > 0 and rng.random() < noise:
            safe = expert.safe_actions(info["pose"])
            if len(safe):
                action = int(rng.choice(safe))
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        poses.append(info["pose"])
        actions.append(action)
        rewards.append(reward)
        terms.append(terminated)
        truncs.append(truncated)
        done = terminated or truncated
    demo = make_demo(
        observations,
        actions,
        rewards,
        terms,
        truncs,
        poses,
        task,
        "astar",
        seed,
        noise,
        info["outcome"],
        chosen,
    )
    return demo, expert.replans


def generate_demos(
    maps: str,
    n_episodes: int,
    seed: int = 0,
    noise: float = 0.0,
    config: NavConfig | None = None,
    keep_failures: bool = False,
    expert_config: ExpertConfig | None = None,
    lattice: LatticeConfig | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[list[Demo], DemoStats]:
    """Run ``n_episodes`` expert episodes on tasks from the map spec ``maps``; episode ``i``
    resets the env with seed ``seed + i``. Only episodes that reach the goal are kept unless
    ``keep_failures``. ``progress(1)`` is called after each episode."""

    if not 0.0 <= noise <= 1.0:
        raise ValueError(f"noise must be a probability in [0, 1], got {noise}")
    config = config or NavConfig()
    env = NavigationEnv(config, maps=maps)
    expert = Expert(config, expert_config, lattice)
    rng = np.random.default_rng([seed, 1013])
    demos: list[Demo] = []
    stats = DemoStats(outcomes={})
    for i in range(n_episodes):
        demo, replans = record_episode(env, expert, seed + i, noise, rng)
        outcome = Outcome(demo.metadata["outcome"]).name.lower()
        stats.outcomes[outcome] = stats.outcomes.get(outcome, 0) + 1
        stats.episodes += 1
        stats.replans += replans
        if keep_failures or demo.metadata["outcome"] == Outcome.GOAL:
            demos.append(demo)
            stats.kept += 1
            stats.steps += len(demo)
        if progress is not None:
            progress(1)
    return demos, stats
