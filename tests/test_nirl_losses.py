"""NIRL's pure maths: IQ-Learn's objective, SQIL's TD loss, MAP refinement, max-margin terms, features."""

import math

import numpy as np
import pytest
import torch

from agents.nirl.losses import (
    KEEP,
    RELABEL,
    REWEIGHT,
    absorbing_rewards,
    crash_value,
    implicit_reward,
    iq_loss,
    map_posterior,
    margin_violations,
    max_margin_loss,
    ranking_margin_loss,
    refine_steps,
    soft_td_loss,
    soft_value,
    sqil_rewards,
    structured_margins,
)
from agents.nirl.networks import RewardNetwork, direction_weights, goal_reached, state_action_features
from worlds.config import NavConfig

TURNS = torch.linspace(-math.pi / 2, math.pi / 2, 5)


def test_soft_value_is_a_smooth_max():
    q = torch.tensor([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    v = soft_value(q, alpha=0.5)
    assert v[0].item() == pytest.approx(0.5 * math.log(math.exp(2) + math.exp(4) + math.exp(6)))
    assert v[1].item() == pytest.approx(0.5 * math.log(3))
    assert soft_value(q, alpha=1e-3)[0].item() == pytest.approx(3.0, abs=1e-2)  # alpha -> 0: the max


def test_implicit_reward_is_the_inverse_soft_bellman_operator():
    q_taken = torch.tensor([5.0, 5.0, 5.0])
    next_value = torch.tensor([4.0, 4.0, 4.0])
    terminated = torch.tensor([False, True, False])
    r = implicit_reward(q_taken, next_value, terminated, gamma=0.9)
    assert r.tolist() == pytest.approx([5.0 - 3.6, 5.0, 5.0 - 3.6])  # nothing follows a termination


def test_iq_loss_by_hand():
    q_taken = torch.tensor([2.0, 1.0, 0.5, 3.0], requires_grad=True)
    value = torch.tensor([2.5, 1.5, 1.0, 3.0])
    next_value = torch.tensor([1.0, 2.0, 1.0, 9.0])
    terminated = torch.tensor([False, False, False, True])
    is_expert = torch.tensor([True, True, False, False])
    weights = torch.tensor([1.0, 0.5, 1.0, 1.0])
    gamma, chi2 = 0.5, 0.25
    terms = iq_loss(q_taken, value, next_value, terminated, is_expert, gamma, chi2, weights)
    r = [2.0 - 0.5, 1.0 - 1.0, 0.5 - 0.5, 3.0]  # Q - gamma V(s'), none after the termination
    expert = -(1.0 * r[0] + 0.5 * r[1]) / 1.5
    value_term = np.mean([2.5 - 0.5, 1.5 - 1.0, 1.0 - 0.5, 3.0 - 0.0])
    chi2_term = np.mean(np.square(r)) / (4 * chi2)
    assert terms.expert_term.item() == pytest.approx(expert)
    assert terms.value_term.item() == pytest.approx(value_term)
    assert terms.chi2_term.item() == pytest.approx(chi2_term)
    assert terms.loss.item() == pytest.approx(expert + value_term + chi2_term)
    assert terms.reward.tolist() == pytest.approx(r)
    terms.loss.backward()
    # d/dQ_i: -w_i / sum w (expert rows) + 2 r_i / (4 chi2 N)
    expected = [-1 / 1.5 + 2 * r[0] / 4, -0.5 / 1.5 + 2 * r[1] / 4, 2 * r[2] / 4, 2 * r[3] / 4]
    assert q_taken.grad.tolist() == pytest.approx(expected)
    with pytest.raises(ValueError, match="expert step"):
        iq_loss(q_taken, value, next_value, terminated, torch.zeros(4, dtype=torch.bool), gamma, chi2)


def test_iq_expert_reward_settles_at_twice_chi2_alpha():
    """With V held fixed, maximising E[r] - E[r^2] / (4 chi2) puts an expert step's reward at 2 chi2:
    the regulariser bounds the learned reward instead of letting the expert term push it forever."""
    q = torch.zeros(1, requires_grad=True)
    optimiser = torch.optim.SGD([q], lr=0.1)
    for _ in range(500):
        terms = iq_loss(
            q, torch.zeros(1), torch.zeros(1), torch.tensor([True]), torch.tensor([True]), 0.9, 0.5
        )
        optimiser.zero_grad()
        terms.loss.backward()
        optimiser.step()
    assert q.item() == pytest.approx(2 * 0.5, abs=1e-3)


def test_sqil_rewards_and_soft_td_loss():
    is_expert = torch.tensor([True, False])
    assert sqil_rewards(is_expert).tolist() == [1.0, 0.0]
    q_taken = torch.tensor([2.0, 1.0])
    loss = soft_td_loss(
        q_taken, sqil_rewards(is_expert), torch.tensor([1.0, 3.0]), torch.tensor([False, True]), 0.5
    )
    assert loss.item() == pytest.approx(((2.0 - 1.5) ** 2 + (1.0 - 0.0) ** 2) / 2)


def test_structured_margins_grow_with_the_turn_gap():
    margins = structured_margins(TURNS, scale=2.0)
    assert margins.shape == (5, 5)
    assert torch.all(margins.diagonal() == 0)
    assert torch.allclose(margins, margins.T)
    assert margins[0, 1] == pytest.approx(2.0 * (0.5 + 0.5 * 0.25))  # neighbouring turn
    assert margins[0, 4] == pytest.approx(2.0)  # opposite turn: the full scale
    assert torch.all(margins[2, [1, 3]] < margins[2, [0, 4]])


def test_max_margin_loss_is_zero_when_the_margin_holds():
    margins = structured_margins(TURNS, scale=1.0)
    q = torch.tensor([[0.0, 0.0, 2.0, 0.0, 0.0], [5.0, 1.0, 1.0, 1.0, 1.0]])
    actions = torch.tensor([2, 0])
    assert max_margin_loss(q, actions, margins).item() == 0.0
    assert margin_violations(q, actions, margins).item() == 0.0


def test_max_margin_loss_is_positive_when_the_margin_fails():
    margins = structured_margins(TURNS, scale=1.0)
    # demonstrated action 2 leads action 3 by only 0.1; the margin of that neighbour is 0.625
    q = torch.tensor([[0.0, 0.0, 1.0, 0.9, 0.0]])
    loss = max_margin_loss(q, torch.tensor([2]), margins)
    assert loss.item() == pytest.approx(0.9 + 0.625 - 1.0)
    assert margin_violations(q, torch.tensor([2]), margins).item() == 1.0
    # a demonstrated action that is not even the best: the hinge grows with the shortfall
    worse = max_margin_loss(torch.tensor([[0.0, 0.0, 0.0, 0.9, 0.0]]), torch.tensor([2]), margins)
    assert worse.item() > loss.item()


def test_max_margin_loss_weights_and_gradient():
    margins = structured_margins(TURNS, scale=1.0)
    q = torch.zeros(2, 5, requires_grad=True)
    actions = torch.tensor([1, 3])
    unweighted = max_margin_loss(q, actions, margins)
    halved = max_margin_loss(q, actions, margins, torch.tensor([0.5, 0.5]))
    assert halved.item() == pytest.approx(0.5 * unweighted.item())
    unweighted.backward()
    # raising the demonstrated action's value lowers the loss
    assert q.grad[0, 1] < 0 and q.grad[1, 3] < 0
    zero = max_margin_loss(q.detach(), actions, margins, torch.zeros(2))
    assert zero.item() == 0.0


def test_ranking_margin_loss():
    demo = torch.tensor([0.0, -0.1])
    assert ranking_margin_loss(demo, torch.tensor([-1.0, -2.0]), margin=0.5).item() == 0.0
    loss = ranking_margin_loss(demo, torch.tensor([-0.2]), margin=0.5)
    assert loss.item() == pytest.approx(((-0.2 + 0.5 - 0.0) + (-0.2 + 0.5 + 0.1)) / 2)
    weighted = ranking_margin_loss(demo, torch.tensor([-0.2]), 0.5, demo_weights=torch.tensor([1.0, 0.0]))
    assert weighted.item() == pytest.approx(0.3 / 2)


def test_map_posterior_is_bayes_rule():
    noise = 0.2
    uniform = torch.full((1, 5), 0.2)
    post = map_posterior(uniform, torch.tensor([3]), noise)
    assert post.sum().item() == pytest.approx(1.0)
    assert post[0, 3].item() == pytest.approx(1 - noise + noise / 5)
    prior = torch.tensor([[0.01, 0.01, 0.96, 0.01, 0.01]])
    post = map_posterior(prior, torch.tensor([4]), noise)
    expected = prior[0] * torch.tensor([0.04, 0.04, 0.04, 0.04, 0.84])
    assert torch.allclose(post[0], expected / expected.sum())
    assert post[0].argmax().item() == 2  # a confident prior overrides the recorded action
    noiseless = map_posterior(prior, torch.tensor([4]), 0.0)
    assert noiseless[0, 4].item() == pytest.approx(1.0)  # no noise: the recording is the truth


def test_refine_keeps_reweights_and_relabels():
    posterior = torch.tensor(
        [
            [0.0, 0.0, 0.9, 0.1, 0.0],  # recorded 2, MAP 2 -> keep
            [0.05, 0.05, 0.8, 0.05, 0.05],  # recorded 4, MAP 2 confident -> relabel
            [0.3, 0.3, 0.2, 0.1, 0.1],  # recorded 2, MAP 0 not confident -> reweight
        ]
    )
    refined = refine_steps(posterior, torch.tensor([2, 4, 2]), relabel_threshold=0.6)
    assert refined.decisions.tolist() == [KEEP, RELABEL, REWEIGHT]
    assert refined.labels.tolist() == [2, 2, 2]
    assert refined.weights.tolist() == pytest.approx([0.9, 0.8, 0.2])


def test_absorbing_rewards_only_penalise_collisions():
    reward = torch.tensor([-0.1, -0.2, -0.3])
    terminated = torch.tensor([False, True, True])
    at_goal = torch.tensor([False, True, False])
    out = absorbing_rewards(reward, terminated, at_goal, scale=2.0, gamma=0.9)
    assert crash_value(2.0, 0.9) == pytest.approx(-20.0)
    assert out.tolist() == pytest.approx([-0.1, -0.2, -0.3 - 18.0])


def test_direction_weights_interpolate_the_beams():
    nav = NavConfig()
    angles = nav.sensors.beam_angles  # -180, -135, ..., 135 degrees
    exact = direction_weights(angles, nav.robot.turns, full_circle=True)
    assert np.allclose(exact.sum(axis=0), 1.0)
    assert exact[:, 2].argmax() == 4 and exact[4, 2] == pytest.approx(1.0)  # straight ahead: beam 4
    between = direction_weights(angles, [math.pi / 8, math.pi - 0.1], full_circle=True)
    assert between[4, 0] == pytest.approx(0.5) and between[5, 0] == pytest.approx(0.5)
    assert between[0, 1] > 0.5 and between[7, 1] > 0  # near 180 degrees: beam 0 (-180), then 135
    fan = direction_weights(np.array([-0.5, 0.0, 0.5]), [1.0, 0.25], full_circle=False)
    assert fan[:, 0].tolist() == pytest.approx([0.0, 0.0, 1.0])  # clamped to the outermost beam
    assert fan[:, 1].tolist() == pytest.approx([0.0, 0.5, 0.5])


def test_state_action_features_and_reward_range():
    nav = NavConfig()
    obs = torch.rand(4, 11)
    obs[:, 9], obs[:, 10] = 1.0, 0.0  # goal at bearing +90 degrees
    weights = torch.as_tensor(direction_weights(nav.sensors.beam_angles, nav.robot.turns, True)).float()
    feats = state_action_features(obs, TURNS, weights, 8)
    assert feats.shape == (4, 5, 11 + 5 + 3)
    assert torch.allclose(feats[:, 2, 11 + 5], obs[:, 4])  # range straight ahead is beam 4
    assert torch.allclose(feats[:, 4, -1], torch.ones(4), atol=1e-6)  # turning +90 faces the goal
    net = RewardNetwork.for_navigation(nav, (16,), "relu", scale=2.0)
    reward = net(obs)
    assert reward.shape == (4, 5) and torch.all(reward < 0) and torch.all(reward > -2.0)


def test_goal_reached_reads_the_squashed_distance():
    obs = torch.zeros(3, 11)
    obs[:, 8] = torch.tensor([0.4 / 6.4, 0.5 / 6.5, 0.6 / 6.6])
    assert goal_reached(obs, 8, goal_tolerance=0.5, max_range=6.0).tolist() == [True, True, False]


def test_crash_absorbing_value_minimises_iq_loss_on_the_absorbing_self_loop():
    from agents.nirl.losses import crash_absorbing_value

    gamma, chi2 = 0.99, 0.5
    best = crash_absorbing_value(chi2, gamma)
    assert best == pytest.approx(-100.0)

    def row_loss(v: float) -> float:  # one non-expert self-loop row beside a fixed expert row
        q = torch.tensor([1.0, v])
        terms = iq_loss(q, q, torch.tensor([0.0, v]), torch.tensor([True, False]),
                        torch.tensor([True, False]), gamma, chi2)  # fmt: skip
        return float(terms.loss)

    assert row_loss(best) < row_loss(best + 5) and row_loss(best) < row_loss(best - 5)
