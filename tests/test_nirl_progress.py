"""The progress potential and its shaped reward (agents/nirl/progress.py), the crash clip (losses)."""

import dataclasses

import numpy as np
import pytest
import torch

from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner, goal_features_from
from agents.nirl.losses import crash_clip_loss
from agents.nirl.progress import (
    ProgressPotential,
    potential_loss,
    shaped_progress_reward,
    steps_to_go,
    unit_cost_value,
)
from worlds.config import LEARNING_NAV, ObservationConfig

GAMMA = 0.99


def test_steps_to_go_counts_down_only_for_episodes_that_reached_the_goal():
    assert steps_to_go(4, True).tolist() == [4, 3, 2, 1]
    assert steps_to_go(3, False).tolist() == [0, 0, 0]


def test_unit_cost_value_is_the_discounted_sum_of_unit_costs():
    k = torch.tensor([1, 2, 30])
    expected = [-sum(GAMMA**i for i in range(n)) for n in (1, 2, 30)]
    assert np.allclose(unit_cost_value(k, GAMMA).numpy(), expected, atol=1e-4)


class Exact(ProgressPotential):
    """A potential that reads its value from the observation's first entry (an exact fit)."""

    def forward(self, obs):
        return obs[:, 0]


def test_shaped_reward_is_zero_along_an_exactly_fitted_path_and_a_crash_costs_the_rest():
    potential = Exact(2, (4,), "relu", GAMMA)
    to_go = torch.tensor([3, 2, 1])
    values = unit_cost_value(to_go, GAMMA)
    obs = torch.stack([values, torch.zeros(3)], dim=1)
    next_obs = torch.cat([obs[1:], torch.zeros(1, 2)])
    terminated = torch.tensor([False, False, True])
    at_goal = torch.tensor([False, False, True])
    reward = shaped_progress_reward(potential, obs, next_obs, terminated, at_goal, GAMMA)
    assert torch.allclose(reward, torch.zeros(3), atol=1e-4)
    # the same last step ending in a collision: never arriving, far worse than any path step
    crash = shaped_progress_reward(potential, obs, next_obs, terminated, torch.zeros(3, dtype=bool), GAMMA)
    assert crash[2] < -90 and torch.allclose(crash[:2], torch.zeros(2), atol=1e-4)


def test_potential_regression_learns_the_steps_to_go_and_ignores_unknown_ones():
    torch.manual_seed(0)
    potential = ProgressPotential(1, (32,), "relu", GAMMA)
    to_go = torch.arange(1, 41)
    obs = (to_go.float() / 40.0)[:, None]
    unknown = torch.zeros(40, dtype=torch.int64)
    assert potential_loss(potential, obs, unknown, GAMMA) is None
    optimizer = torch.optim.Adam(potential.parameters(), lr=1e-2)
    first = float(potential_loss(potential, obs, to_go, GAMMA).detach())
    for _ in range(400):
        loss = potential_loss(potential, obs, to_go, GAMMA)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    assert float(loss.detach()) < 0.01 * first
    phi = potential(obs).detach()
    assert bool((phi[1:] < phi[:-1]).float().mean() > 0.9)  # more steps to go, lower value


def test_crash_clip_penalises_only_crash_steps_above_the_demonstrated_reward():
    q = torch.tensor([-20.0, -99.5, 0.0], requires_grad=True)
    next_value = torch.full((3,), -100.0)
    expert_rewards = torch.tensor([-0.3, -0.3])
    crashed = torch.tensor([True, True, False])
    loss = crash_clip_loss(q, next_value, crashed, expert_rewards, GAMMA)
    # step 0 earns -20 + 99 = 79 > -0.3: penalised; step 1 earns -0.5 < -0.3: not; step 2 is no crash
    assert torch.isclose(loss, torch.tensor((79.0 + 0.3) ** 2 / 3), rtol=1e-4)
    loss.backward()
    assert q.grad[0] > 0 and q.grad[1] == 0 and q.grad[2] == 0
    none = crash_clip_loss(q, next_value, torch.zeros(3, dtype=bool), expert_rewards, GAMMA)
    assert float(none) == 0.0


def test_a_goal_potential_reads_only_the_features_after_the_range_readings():
    learner = NIRLLearner(NIRLConfig(potential_inputs="goal"), LEARNING_NAV)
    potential, n_beams = learner.potential, LEARNING_NAV.sensors.n_beams
    obs = torch.rand(64, potential.architecture["obs_dim"])
    other = obs.clone()
    other[:, :n_beams] = torch.rand(64, n_beams)  # other range readings, the same goal and subgoal
    assert torch.equal(potential(obs), potential(other))
    other[:, n_beams] += 0.1  # another goal distance
    assert not torch.allclose(potential(obs), potential(other))
    rebuilt = ProgressPotential.from_architecture(potential.architecture)  # as persistence.load_potential
    rebuilt.load_state_dict(potential.state_dict())
    assert torch.equal(rebuilt(obs), potential(obs)) and rebuilt.first_input == n_beams
    # a potential saved before first_input existed reads every feature
    old = {
        k: v for k, v in ProgressPotential(30, (8,), "relu", GAMMA).architecture.items() if k != "first_input"
    }
    assert ProgressPotential.from_architecture(old).first_input == 0
    with pytest.raises(ValueError, match="potential_inputs"):
        NIRLConfig(potential_inputs="ranges")
    stacked = dataclasses.replace(
        LEARNING_NAV, observation=ObservationConfig(subgoal="own_map", frame_stack=3)
    )
    with pytest.raises(ValueError, match="frame_stack=3"):
        goal_features_from(stacked)
