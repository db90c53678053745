"""NIRL's NNQL phase (agents/nirl/policy_iteration.py): the fixed learned reward is the one the
replay holds, the environment's reward never reaches it, and `train_nirl` hands over to NNQL's trainer."""

import numpy as np
import pytest
import torch

from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.networks import goal_reached
from agents.nirl.policy_iteration import FixedReward
from agents.nirl.progress import ProgressPotential, shaped_progress_reward
from agents.nirl.train_local import train_nirl
from agents.nnql.config import NNQLConfig
from agents.nnql.train_local import LocalTrainConfig, train_local
from agents.planning.demonstrate import generate_demos
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim
from worlds.vector_env import NavigationVectorEnv

GAMMA = 0.99
N_BEAMS = LEARNING_NAV.sensors.n_beams


def potential_reward(seed: int = 0) -> FixedReward:
    torch.manual_seed(seed)
    potential = ProgressPotential(observation_dim(LEARNING_NAV), (16,), "relu", GAMMA)
    return FixedReward(potential, GAMMA, N_BEAMS, LEARNING_NAV.goal_tolerance, LEARNING_NAV.sensors.max_range)


@pytest.fixture
def nan_env_reward(monkeypatch):
    """The environment pays NaN for every step: any learner that reads it learns NaN."""
    step = NavigationVectorEnv.step

    def poisoned(self, actions):
        obs, reward, terminated, truncated, info = step(self, actions)
        return obs, np.full_like(np.asarray(reward, dtype=np.float32), np.nan), terminated, truncated, info

    monkeypatch.setattr(NavigationVectorEnv, "step", poisoned)


def stored(learner) -> dict:
    steps = learner.replay.storage.get(torch.arange(len(learner.replay)))
    return {
        "obs": steps["observation"].numpy(),
        "next_obs": steps[("next", "observation")].numpy(),
        "terminated": steps[("next", "terminated")].reshape(-1).numpy(),
        "reward": steps[("next", "reward")].reshape(-1).numpy(),
    }


def test_fixed_reward_is_the_shaped_progress_reward_of_the_batch():
    reward = potential_reward()
    rng = np.random.default_rng(0)
    dim = observation_dim(LEARNING_NAV)
    obs, next_obs = rng.random((6, dim), dtype=np.float32), rng.random((6, dim), dtype=np.float32)
    terminated = np.array([False, False, True, True, False, False])
    batch = {"obs": obs, "next_obs": next_obs, "terminated": terminated}
    batch["next_obs"][3, N_BEAMS] = 0.0  # the goal reached on step 3, a collision on step 2
    got = reward(batch)
    obs, next_obs = torch.as_tensor(batch["obs"]), torch.as_tensor(batch["next_obs"])
    at_goal = goal_reached(next_obs, N_BEAMS, LEARNING_NAV.goal_tolerance, LEARNING_NAV.sensors.max_range)
    assert at_goal.tolist() == [False, False, False, True, False, False]
    expected = shaped_progress_reward(reward.potential, obs, next_obs, torch.as_tensor(batch["terminated"]),
                                      at_goal, GAMMA)  # fmt: skip
    assert got.dtype == np.float32 and np.allclose(got, (1 - GAMMA) * expected.numpy())
    assert got[2] < -0.5 < got[3]  # the collision's absorbing never-arriving value, the goal's zero potential


def test_the_env_reward_never_reaches_nnqls_replay_when_the_learned_reward_is_given(nan_env_reward):
    run = LocalTrainConfig(steps=400, envs=4, eval_every=0, final_eval_episodes=0, out="", progress=False,
                           moving_discs=0, maps="mixed:16")  # fmt: skip
    nnql = NNQLConfig(learning_starts=64, batch_size=32, utd_ratio=0.25, gamma=GAMMA)
    reward = potential_reward()
    result = train_local(run, nnql, reward=reward)
    data = stored(result.learner)
    assert len(data["reward"]) == 400 and np.isfinite(data["reward"]).all()
    assert np.allclose(data["reward"], reward(data), atol=1e-5)
    assert result.updates > 0
    assert all(np.isfinite(w).all() for w in result.learner.get_weights().values())
    # the counter-check: without the learned reward the same poisoned env fills the replay with NaN
    plain = train_local(run, nnql)
    assert np.isnan(stored(plain.learner)["reward"]).all()


def test_train_nirl_runs_iq_rounds_then_nnqls_trainer_on_the_fixed_reward(nan_env_reward, tmp_path):
    demos, _ = generate_demos("mixed:16", 3, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(iterations=3, fix_reward_after=1, warmstart_updates=10, q_updates=8, reward_updates=4,
                        steps_per_iteration=64, policy_steps=320, seed=0)  # fmt: skip
    run = NIRLRun(envs=4, maps="mixed:16", out=str(tmp_path / "run"), eval_every=0, final_eval_episodes=0,
                  progress=False, policy_eval_every=0)  # fmt: skip
    result = train_nirl(demos, config, run)
    assert result.learner.iteration == 1 and result.iq_steps == 64  # only the IQ-Learn rounds
    assert result.env_steps == 64 + 320 and result.policy_result.env_steps == 320
    assert result.policy_result.policy is not None
    data = stored(result.policy_result.learner)
    assert np.isfinite(data["reward"]).all()
    assert np.allclose(data["reward"], FixedReward.of(result.learner)(data), atol=1e-5)
    assert (tmp_path / "run" / "policy_iteration" / "model.safetensors").exists()


def test_policy_steps_needs_the_progress_reward_fixed_after_iq_rounds():
    with pytest.raises(ValueError, match="policy_steps"):
        NIRLConfig(policy_steps=1000, fix_reward_after=0)
    with pytest.raises(ValueError, match="policy_steps"):
        NIRLConfig(policy_steps=1000, fixed_reward="network")
