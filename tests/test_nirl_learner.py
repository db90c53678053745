"""NIRL learner: MAP refinement on noisy demonstrations, a tiny map solved end to end, files."""

import math

import numpy as np
import pytest
import torch

from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.learner import NIRLLearner
from agents.nirl.losses import KEEP, RELABEL
from worlds.config import NavConfig

TINY_MAP = """\
##########
#S.......#
#........#
#...##...#
#...##...#
#........#
#.......G#
##########
"""

SMALL = {
    "hidden_sizes": (32, 32),
    "reward_hidden_sizes": (32,),
    "batch_size": 64,
    "demo_batch_size": 64,
    "replay_capacity": 20_000,
}


def goal_seeking_steps(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random observations and the action whose turn faces the goal best (a synthetic expert)."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(0.3, 1.0, size=(n, 11)).astype(np.float32)
    bearing = rng.uniform(-math.pi, math.pi, size=n)
    obs[:, 9], obs[:, 10] = np.sin(bearing), np.cos(bearing)
    turns = NavConfig().robot.turns
    gap = np.abs(np.angle(np.exp(1j * (bearing[:, None] - turns[None, :]))))
    return obs, gap.argmin(axis=1)


class Episode:
    """The fields NIRLLearner.add_demos reads from an agents.demos.Demo."""

    def __init__(self, observations, actions):
        self.observations = observations
        self.actions = actions
        self.terminations = np.zeros(len(actions), bool)
        self.truncations = np.zeros(len(actions), bool)
        self.truncations[-1] = True


def test_map_refinement_down_weights_injected_wrong_actions():
    obs, expert = goal_seeking_steps(800, seed=0)
    rng = np.random.default_rng(1)
    injected = rng.random(len(expert)) < 0.25
    shift = rng.integers(1, 5, size=len(expert))
    recorded = np.where(injected, (expert + shift) % 5, expert)
    learner = NIRLLearner(NIRLConfig(**SMALL, warmstart_updates=300, seed=0))
    episodes = [Episode(obs[i : i + 21], recorded[i : i + 20]) for i in range(0, 780, 20)]
    learner.add_demos(episodes)
    learner.warm_start()
    steps, refined = learner.refine_all()
    n = len(steps)  # episode e holds rows 20 e .. 20 e + 19: stored step i is row i
    assert n == 780 and torch.equal(steps["action"], torch.as_tensor(recorded[:n]))
    wrong = torch.as_tensor(injected[:n])
    true_action = torch.as_tensor(expert[:n])
    # weight left on the recorded action: its posterior, or 0 where it was relabelled
    on_recorded = torch.where(refined.labels == steps["action"], refined.weights, torch.zeros(n))
    assert on_recorded[wrong].mean() < 0.5 * on_recorded[~wrong].mean()
    relabelled = refined.decisions == RELABEL
    assert (relabelled[wrong]).float().mean() > 0.5
    assert (refined.labels[wrong & relabelled] == true_action[wrong & relabelled]).float().mean() > 0.9
    assert (refined.decisions[~wrong] == KEEP).float().mean() > 0.9


def test_without_refinement_every_step_keeps_its_action():
    obs, expert = goal_seeking_steps(42, seed=2)
    learner = NIRLLearner(NIRLConfig(**SMALL, refine=False))
    learner.add_demos([Episode(obs[:21], expert[:20]), Episode(obs[21:42], expert[21:41])])
    steps, refined = learner.refine_all()
    assert torch.equal(refined.labels, steps["action"])
    assert torch.all(refined.weights == 1) and torch.all(refined.decisions == KEEP)


@pytest.mark.slow
def test_nirl_on_a_tiny_map_reaches_the_goal(tmp_path):
    from agents.evaluation.policies import load_policy
    from agents.nirl.train_local import train_nirl
    from agents.planning.demonstrate import generate_demos
    from worlds.env import NavigationEnv
    from worlds.outcomes import Outcome

    tiny = tmp_path / "tiny.txt"
    tiny.write_text(TINY_MAP)  # S and G markers: one fixed task
    nav = NavConfig(pool_size=1)
    demos, _ = generate_demos(str(tiny), 6, seed=0, config=nav)
    assert len(demos) >= 4
    config = NIRLConfig(
        **SMALL,
        warmstart_updates=200,
        iterations=6,
        steps_per_iteration=384,
        reward_updates=20,
        q_updates=128,
        temperature_decay_iterations=6,
    )  # 3 iterations reached 8/10 only by luck of the random streams (6/10 once start headings changed)
    out = tmp_path / "run"
    run = NIRLRun(envs=8, maps=str(tiny), out=str(out), eval_every=0, final_eval_episodes=0, progress=False)
    result = train_nirl(demos, config, run, nav)
    assert result.env_steps == 6 * 384 and result.learner.iteration == 6
    policy = load_policy(out)  # the saved greedy policy, as `navlearn evaluate` loads it
    assert policy.model == "nirl" and policy.kind == "q_network"
    env = NavigationEnv(nav, maps=str(tiny))
    outcomes = []
    for seed in range(10):
        obs, _ = env.reset(seed=100 + seed)
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(int(policy(obs[None])[0]))
            done = terminated or truncated
        outcomes.append(info["outcome"])
    assert sum(o == Outcome.GOAL for o in outcomes) >= 8, outcomes
    for name in (
        "weights_history.safetensors",
        "weights.png",
        "curve.jsonl",
        "summary.json",
        "reward.safetensors",
    ):
        assert (out / name).is_file()


def test_checkpoint_and_weight_history_round_trip(tmp_path):
    from agents.nirl.weights import WeightHistory, plot_weight_changes

    obs, expert = goal_seeking_steps(84, seed=3)
    config = NIRLConfig(**SMALL, warmstart_updates=10, q_updates=4, reward_updates=2)
    learner = NIRLLearner(config)
    learner.add_demos([Episode(obs[:42], expert[:41]), Episode(obs[42:], expert[42:83])])
    learner.add_experience(
        {"obs": obs[:80], "action": expert[:80], "reward": np.zeros(80), "next_obs": obs[1:81],
         "terminated": np.zeros(80, bool), "truncated": np.zeros(80, bool)}
    )  # fmt: skip
    history = WeightHistory()
    for _ in range(14):  # 10 warm-start updates, then one iteration of 4 Q updates
        learner.update()
    history.record(0, reward=learner.reward_weights(), policy=learner.get_weights())
    assert learner.warm_updates == 10 and learner.iteration == 1 and learner.reward_steps == 10 + 2
    learner.save_checkpoint(tmp_path / "ckpt")
    restored = NIRLLearner(config)
    restored.load_checkpoint(tmp_path / "ckpt")
    assert len(restored.demos) == len(learner.demos) == 82
    assert (restored.version, restored.iteration, restored.warm_updates) == (14, 1, 10)
    for name, value in learner.get_weights().items():
        assert np.array_equal(restored.get_weights()[name], value)
    for name, value in learner.reward_weights().items():
        assert np.array_equal(restored.reward_weights()[name], value)
    learner.update()
    history.record(1, reward=learner.reward_weights(), policy=learner.get_weights())
    history.save(tmp_path / "history.safetensors")
    loaded = WeightHistory.load(tmp_path / "history.safetensors")
    assert loaded.iterations == [0, 1] and set(loaded.snapshots) == set(history.snapshots)
    changes = loaded.layer_changes("policy")
    assert set(changes) == {"0.weight", "2.weight", "4.weight"}
    assert all(c["step"][1] > 0 and c["drift"][0] == 0 for c in changes.values())
    assert plot_weight_changes(loaded, tmp_path / "w.png").stat().st_size > 10_000
