"""The maths of NIRL as pure functions: inverse soft-Q learning (IQ-Learn), MAP refinement,
and the max-margin terms of the optional max-margin fit.

All take and return torch tensors, hold no state and are unit-tested alone
(tests/test_nirl_losses.py).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

KEEP, REWEIGHT, RELABEL = 0, 1, 2
"""What MAP refinement did with a demonstrated step."""


def soft_value(q_values: torch.Tensor, alpha: float) -> torch.Tensor:
    """Soft state value ``V(s) = alpha * logsumexp(Q(s, .) / alpha)`` (N,) of the policy
    ``softmax(Q / alpha)``: the maximum-entropy value IQ-Learn's Q-function carries."""
    return alpha * torch.logsumexp(q_values / alpha, dim=1)


def implicit_reward(
    q_taken: torch.Tensor, next_value: torch.Tensor, terminated: torch.Tensor, gamma: float
) -> torch.Tensor:
    """The reward a soft Q-function holds, by the inverse soft Bellman operator (Garg et al. 2021,
    eq. 6): ``r(s, a, s') = Q(s, a) - gamma * (1 - terminated) * V(s')``. After a termination
    nothing follows (an absorbing state of value 0); time-limit truncations bootstrap."""
    return q_taken - gamma * (~terminated.bool()).to(q_taken.dtype) * next_value


class IQLoss(NamedTuple):
    """The terms of IQ-Learn's objective (to minimise: ``loss``) and the rewards they saw."""

    loss: torch.Tensor
    expert_term: torch.Tensor
    """``-E_expert[w r]``: demonstrated steps must earn a high implicit reward"""
    value_term: torch.Tensor
    """``E_rho[V(s) - gamma V(s')]``: the sampled form of ``(1 - gamma) E[V(s_0)]``"""
    chi2_term: torch.Tensor
    """``E[r^2] / (4 chi2_alpha)``: the chi-squared divergence's regulariser (bounds the reward)"""
    reward: torch.Tensor
    """(N,) implicit rewards of the batch (detached)"""


def iq_loss(
    q_taken: torch.Tensor,
    value: torch.Tensor,
    next_value: torch.Tensor,
    terminated: torch.Tensor,
    is_expert: torch.Tensor,
    gamma: float,
    chi2_alpha: float,
    expert_weights: torch.Tensor | None = None,
) -> IQLoss:
    """Inverse soft-Q learning's objective with the chi-squared divergence (Garg et al., NeurIPS
    2021, eq. 10 and its online form, sec. 5.1), for one mixed batch of expert and own steps:

    ``-E_expert[w (Q(s,a) - gamma V(s'))] + E_all[V(s) - gamma V(s')] + E_all[r^2] / (4 chi2_alpha)``

    ``q_taken`` (N,) is ``Q(s, a)``, ``value`` (N,) ``V(s)`` and ``next_value`` (N,) ``V(s')``
    (soft values, see :func:`soft_value`); ``is_expert`` (N,) bool marks demonstrated steps, whose
    weights ``expert_weights`` (N,) come from MAP refinement (1 when None; other rows ignored).
    The value term over every step ("online" IQ-Learn) pushes values down where the learner goes
    without the expert; with no own steps it is the offline form over expert states.
    """
    is_expert = is_expert.bool().reshape(-1)
    if not bool(is_expert.any()):
        raise ValueError("iq_loss needs at least one expert step in the batch")
    next_term = gamma * (~terminated.bool()).to(q_taken.dtype) * next_value
    reward = q_taken - next_term
    weights = (
        torch.ones_like(reward) if expert_weights is None else expert_weights.reshape(-1).to(reward.dtype)
    )
    expert_term = -(weights * reward)[is_expert].sum() / weights[is_expert].sum().clamp_min(1e-8)
    value_term = (value - next_term).mean()
    chi2_term = (reward**2).mean() / (4.0 * chi2_alpha)
    loss = expert_term + value_term + chi2_term
    return IQLoss(loss, expert_term.detach(), value_term.detach(), chi2_term.detach(), reward.detach())


def crash_absorbing_value(chi2_alpha: float, gamma: float) -> float:
    """Value of the absorbing state a collision leads to, at the optimum of IQ-Learn's objective there.

    Only the learner's own episodes reach it, and it only loops on itself: each visit adds
    ``V - gamma V`` (value term) and ``r^2 / (4 chi2_alpha)`` with ``r = (1 - gamma) V`` (regulariser)
    and no expert term, minimised at ``r = -2 chi2_alpha``: ``V = -2 chi2_alpha / (1 - gamma)``.
    Treating a crash as "nothing follows" (value 0) instead made it about as good as a demonstrated
    path at IQ-Learn's reward scale (collision values near 0 and above)."""
    return -2.0 * chi2_alpha / (1.0 - gamma)


def crash_clip_loss(
    q_taken: torch.Tensor,
    next_value: torch.Tensor,
    crashed: torch.Tensor,
    expert_rewards: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """Squared hinge that keeps the learner's crash steps from out-earning demonstrated ones:
    ``sum_crash relu(r_crash - mean(r_expert))^2 / N`` with ``r_crash = Q(s, a) - gamma V_abs`` (the
    implicit reward of a step into the collision's absorbing state) and the batch's demonstrated
    rewards detached (a ceiling, not a target). Without it crash steps earned +47..+84 against
    about -1 per demonstrated step after few updates: the absorbing target alone is reached slowly."""
    crashed = crashed.reshape(-1).bool()
    if not bool(crashed.any()) or expert_rewards.numel() == 0:
        return q_taken.sum() * 0.0
    ceiling = expert_rewards.detach().mean()
    r_crash = q_taken[crashed] - gamma * next_value[crashed]
    return torch.relu(r_crash - ceiling).pow(2).sum() / len(q_taken)


def sqil_rewards(is_expert: torch.Tensor) -> torch.Tensor:
    """SQIL's fixed rewards (Reddy, Dragan & Levine, ICLR 2020): 1 on demonstrated steps, 0 on own."""
    return is_expert.to(torch.float32).reshape(-1)


def soft_td_loss(
    q_taken: torch.Tensor,
    reward: torch.Tensor,
    next_value: torch.Tensor,
    terminated: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """Soft Q-learning's squared TD error ``(Q(s,a) - r - gamma (1 - d) V_target(s'))^2`` (mean)."""
    target = reward + gamma * (~terminated.bool()).to(q_taken.dtype) * next_value
    return ((q_taken - target.detach()) ** 2).mean()


def crash_value(scale: float, gamma: float) -> float:
    """Value of the absorbing state a collision leads to: stuck forever at the largest cost,
    ``-scale / (1 - gamma)``. Collisions are infeasible moves, as obstacles are in a planner's
    model; the learned reward only prices feasible ones."""
    return -scale / (1.0 - gamma)


def absorbing_rewards(
    reward: torch.Tensor, terminated: torch.Tensor, reached_goal: torch.Tensor, scale: float, gamma: float
) -> torch.Tensor:
    """One-step rewards with the collision absorbing state folded in: ``R + gamma * crash_value``
    on terminations that are not the goal (the TD target bootstraps nothing after a termination)."""
    crashed = terminated.bool() & ~reached_goal.bool()
    return reward + crashed.to(reward.dtype) * gamma * crash_value(scale, gamma)


def structured_margins(turns: torch.Tensor, scale: float) -> torch.Tensor:
    """Margin matrix ``L[e, a]`` (A, A): how much the demonstrated action ``e`` must beat action ``a``.

    ``L[e, e] = 0``; otherwise ``scale * (0.5 + 0.5 * |turn_a - turn_e| / max gap)``: a
    neighbouring turn must lose by half the scale, the opposite turn by the full scale
    (the loss function of the structured prediction is the turn error, not just 0/1).
    """
    turns = torch.as_tensor(turns, dtype=torch.float32).reshape(-1)
    gap = (turns[None, :] - turns[:, None]).abs()
    widest = gap.max()
    relative = gap / widest if widest > 0 else torch.zeros_like(gap)
    margins = scale * (0.5 + 0.5 * relative)
    margins.fill_diagonal_(0.0)
    return margins


def max_margin_loss(
    q_values: torch.Tensor,
    actions: torch.Tensor,
    margins: torch.Tensor,
    weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Structured hinge of maximum margin planning over one decision (Ratliff et al. 2006).

    ``mean_i w_i * (max_a [Q(s_i, a) + L[a_i, a]] - Q(s_i, a_i))``: zero exactly when every
    demonstrated action ``a_i`` beats each other action ``a`` by at least ``L[a_i, a]``,
    positive otherwise. The max includes ``a_i`` itself (margin 0), so no term is negative.
    ``q_values`` (N, A), ``actions`` (N,) int, ``margins`` (A, A), ``weights`` (N,) or None.
    """
    actions = actions.long().reshape(-1)
    augmented = q_values + margins[actions]
    demonstrated = q_values.gather(1, actions[:, None]).squeeze(1)
    hinge = augmented.max(dim=1).values - demonstrated
    if weights is not None:
        hinge = hinge * weights.reshape(-1).to(hinge.dtype)
    return hinge.mean()


def ranking_margin_loss(
    demo_rewards: torch.Tensor,
    policy_rewards: torch.Tensor,
    margin: float,
    demo_weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Trajectory-level margin between demonstrated and self-generated steps, from samples.

    ``mean_{i,j} max(0, R_policy_j + margin - R_demo_i)`` over every pair of a demonstrated
    step's reward (N,) and a step of the learner's own experience (M,): the sampled form of
    maximum margin planning's "the demonstration must out-score the planner's own path", with
    the planner's path replaced by the policy's sampled experience (no model needed). Zero once
    every demonstrated step out-scores every sampled one by ``margin``; ``demo_weights`` (N,)
    scale each demonstrated step's pairs.
    """
    gaps = torch.relu(policy_rewards.reshape(1, -1) + margin - demo_rewards.reshape(-1, 1))
    if demo_weights is not None:
        gaps = gaps * demo_weights.reshape(-1, 1).to(gaps.dtype)
    return gaps.mean()


def margin_violations(q_values: torch.Tensor, actions: torch.Tensor, margins: torch.Tensor) -> torch.Tensor:
    """Fraction of steps whose demonstrated action does not beat every other by its margin."""
    actions = actions.long().reshape(-1)
    augmented = q_values + margins[actions]
    demonstrated = q_values.gather(1, actions[:, None]).squeeze(1)
    return (augmented.max(dim=1).values > demonstrated + 1e-6).float().mean()


def map_posterior(prior: torch.Tensor, observed: torch.Tensor, noise: float | torch.Tensor) -> torch.Tensor:
    """Posterior over the intended action given the demonstrated one (Bayes' rule), (N, A).

    The demonstrator meant action ``a*`` (prior ``prior[i, a*]``, the current policy's
    probabilities) and recorded it, except with probability ``noise`` (a number, or (N,) per
    step) a uniformly random action: ``P(observed | a*) = (1 - noise) [observed = a*] + noise / A``.
    """
    n_actions = prior.shape[1]
    observed = observed.long().reshape(-1)
    noise = torch.as_tensor(noise, dtype=prior.dtype, device=prior.device)
    noise = noise.reshape(-1, 1).expand(len(observed), 1)
    likelihood = (noise / n_actions).expand_as(prior).clone()
    likelihood.scatter_add_(1, observed[:, None], 1.0 - noise)
    joint = prior * likelihood
    return joint / joint.sum(dim=1, keepdim=True).clamp_min(1e-12)


class Refinement(NamedTuple):
    """MAP refinement of demonstrated steps: the label to learn from, its weight and the decision."""

    labels: torch.Tensor
    """(N,) int64: the recorded action, or the MAP action where it was relabelled"""
    weights: torch.Tensor
    """(N,) float: posterior probability of the label"""
    decisions: torch.Tensor
    """(N,) int64: KEEP, REWEIGHT or RELABEL"""


def kept_as_recorded(observed: torch.Tensor) -> Refinement:
    """Every demonstrated step kept as recorded, weight 1 (refinement off, not started, or a clean
    demonstrator, whose posterior is certain of the recorded action)."""
    observed = observed.long().reshape(-1)
    ones = torch.ones(len(observed), device=observed.device)
    return Refinement(observed, ones, torch.full_like(observed, KEEP))


def refine_steps(
    posterior: torch.Tensor, observed: torch.Tensor, relabel_threshold: float, judge_recorded: bool = False
) -> Refinement:
    """Keep, re-weight or relabel each demonstrated step from its posterior.

    The MAP action replaces the recorded one when it differs and its posterior reaches
    ``relabel_threshold`` (RELABEL); otherwise the recorded action stays, weighted by its
    own posterior - KEEP when it is the MAP action, REWEIGHT when the posterior doubts it
    but names no confident alternative. With ``judge_recorded`` the test is on the recorded
    action instead: it is replaced by the MAP action when it was noise with posterior at least
    ``relabel_threshold`` (its own posterior at most ``1 - relabel_threshold``) - for a prior that
    splits its mass over several near-equal actions, where no single one reaches the threshold
    even when the recorded action is surely a random one (agents.nirl.hindsight).
    """
    observed = observed.long().reshape(-1)
    best_p, best = posterior.max(dim=1)
    kept_p = posterior.gather(1, observed[:, None]).squeeze(1)
    confident = kept_p <= 1.0 - relabel_threshold if judge_recorded else best_p >= relabel_threshold
    relabel = (best != observed) & confident
    labels = torch.where(relabel, best, observed)
    weights = torch.where(relabel, best_p, kept_p)
    decisions = torch.full_like(observed, REWEIGHT)
    decisions[best == observed] = KEEP
    decisions[relabel] = RELABEL
    return Refinement(labels, weights, decisions)
