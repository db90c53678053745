"""MAP refinement after policy iteration: which demonstrated steps were the expert's, which were noise.

The thesis' posterior over the action the demonstrator meant, ``a*``, given the recorded one
(``losses.map_posterior``: with probability ``noise`` the recorded action is a uniformly random
one) needs a prior ``P(a* | s)`` that has not fitted the noisy labels - a policy fitted to them
spreads the noise over every action and explains it away (it relabels almost none of the
injected actions). Here the prior is the policy NNQL learned on the fixed reward
(``agents.nirl.policy_iteration``): it saw the demonstrations only through the progress potential,
never their actions. The evidence is the recorded step itself: the robot executed the recorded
action, and a random action rarely makes the expert's progress. With ``d`` the step's shaped
progress reward (``progress.shaped_progress_reward``: about 0 along an expert path, about -1 or
less for a step that gains nothing), the likelihood of the step is ``p_clean(d)`` when the
recorded action was the intended one and ``p_noise(d)`` when it was random, and

    P(a*, recorded, d) = prior(a*) [(1 - noise) [recorded = a*] lambda(d) + noise / A],

``lambda(d) = p_clean(d) / p_noise(d) = exp((d - offset) / scale)`` (a logistic split of the
steps' progress, the evidence neutral at ``offset``). ``losses.refine_steps`` then keeps,
re-weights or relabels each step. ``refined_to_go`` re-counts the steps the expert needed from
each state with the relabelled (noise) steps left out, and ``fit_potential`` re-fits the progress
potential on them.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from agents.nirl.losses import RELABEL, Refinement, refine_steps
from agents.nirl.networks import goal_reached
from agents.nirl.progress import ProgressPotential, potential_loss, shaped_progress_reward


@dataclass
class ProgressRefine:
    """Settings of the refinement, chosen by results/nirl/scripts/nirl_refine.py --tune on noisy demo
    seed 3 (no reported run uses it) under the rule "most injected steps relabelled with >= 99% of
    clean steps kept"; the progress evidence barely tells the injected steps from clean ones, so it
    relabels few."""

    temperature: float = 0.01
    """prior softmax(Q / temperature) over the NNQL phase's Q-values (its reward's units: a step
    costs 0.01, policy_iteration.FixedReward)"""
    offset: float = -1.0
    """shaped progress reward at which a step is as likely clean as noise"""
    scale: float = 0.1
    """width of the logistic evidence (0: no evidence from progress, the prior alone)"""
    threshold: float = 0.9
    """relabel when the MAP action differs from the recorded one with this posterior"""


def step_progress(
    potential: ProgressPotential, steps, n_beams: int, goal_tolerance: float, max_range: float, gamma: float
) -> torch.Tensor:
    """(N,) shaped progress reward of demonstrated steps (a TensorDict of transitions)."""
    next_obs = steps[("next", "observation")]
    terminated = steps[("next", "terminated")].reshape(-1).bool()
    at_goal = goal_reached(next_obs, n_beams, goal_tolerance, max_range)
    return shaped_progress_reward(potential, steps["observation"], next_obs, terminated, at_goal, gamma)


def progress_posterior(
    q_values: torch.Tensor,
    recorded: torch.Tensor,
    progress: torch.Tensor,
    noise: float | torch.Tensor,
    settings: ProgressRefine,
) -> torch.Tensor:
    """(N, A) posterior over the intended action (module docstring)."""
    n_actions = q_values.shape[1]
    prior = torch.softmax(q_values / settings.temperature, dim=1)
    noise = torch.as_tensor(noise, dtype=prior.dtype).reshape(-1, 1).expand(len(recorded), 1)
    evidence = torch.ones_like(progress)
    if settings.scale > 0:
        evidence = torch.exp(((progress - settings.offset) / settings.scale).clamp(-30.0, 30.0))
    likelihood = (noise / n_actions).expand_as(prior).clone()
    likelihood.scatter_add_(1, recorded.long().reshape(-1, 1), (1.0 - noise) * evidence.reshape(-1, 1))
    joint = prior * likelihood
    return joint / joint.sum(dim=1, keepdim=True).clamp_min(1e-12)


def refine_demos(
    q_values: Callable[[np.ndarray], np.ndarray],
    potential: ProgressPotential,
    steps,
    nav_terms: tuple[int, float, float],
    gamma: float,
    noise,
    settings: ProgressRefine,
) -> Refinement:
    """Refinement of every demonstrated step in ``steps`` (TensorDict); ``q_values`` is the prior
    policy's numpy Q function (``NNQLPolicy.q_values``), ``nav_terms`` (n_beams, goal tolerance,
    max range) tell the goal from a collision."""
    q = torch.as_tensor(q_values(steps["observation"].numpy()), dtype=torch.float32)
    with torch.no_grad():
        progress = step_progress(potential, steps, *nav_terms, gamma)
    recorded = steps["action"].long().reshape(-1)
    posterior = progress_posterior(q, recorded, progress, noise, settings)
    return refine_steps(posterior, recorded, settings.threshold)


def refined_to_go(episodes: torch.Tensor, to_go: torch.Tensor, decisions: torch.Tensor) -> torch.Tensor:
    """Steps the expert still needed from each state, counting only steps not relabelled as noise
    (at least 1 on an episode that reached the goal; 0, unknown, stays 0)."""
    out = torch.zeros_like(to_go)
    kept = (decisions != RELABEL).long()
    for episode in torch.unique(episodes):
        idx = torch.nonzero(episodes == episode).reshape(-1)
        if int(to_go[idx[0]]) == 0:
            continue
        remaining = torch.flip(torch.cumsum(torch.flip(kept[idx], [0]), 0), [0])
        out[idx] = remaining.clamp_min(1)
    return out


def fit_potential(
    potential: ProgressPotential,
    obs: torch.Tensor,
    to_go: torch.Tensor,
    gamma: float,
    updates: int = 2_000,
    lr: float = 1e-3,
    batch_size: int = 128,
    seed: int = 0,
    weight_decay: float = 0.0,
) -> float:
    """Regress ``potential`` on (obs, to_go) for ``updates`` minibatch steps (Adam; decoupled
    ``weight_decay``, AdamW's, when > 0); returns the last loss."""
    generator = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.AdamW(potential.parameters(), lr=lr, weight_decay=weight_decay)
    loss = torch.tensor(float("nan"))
    for _ in range(updates):
        idx = torch.randint(len(obs), (min(batch_size, len(obs)),), generator=generator)
        loss = potential_loss(potential, obs[idx], to_go[idx], gamma)
        if loss is None:
            continue
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return float(loss.detach())


def refine_learner_demos(learner, q_values: Callable[[np.ndarray], np.ndarray], settings: ProgressRefine):
    """Every demonstrated step ``learner`` (a NIRLLearner with a progress potential) holds, and its
    refinement under the prior of ``q_values`` -> (steps TensorDict in storage order, Refinement)."""
    steps = learner.demos.storage.get(torch.arange(len(learner.demos))).to("cpu")
    nav_terms = (learner.reward.n_beams, learner.goal_tolerance, learner.max_range)
    potential = learner.fit.potential.cpu()
    gamma = learner.config.gamma
    return steps, refine_demos(q_values, potential, steps, nav_terms, gamma, steps["noise"], settings)


def refine_after_policy_iteration(
    learner, q_values: Callable[[np.ndarray], np.ndarray], settings: ProgressRefine | None = None
) -> tuple[Refinement, ProgressPotential]:
    """Refine every demonstration ``learner`` holds under the prior of the NNQL phase's ``q_values``
    (``refine_learner_demos``), then re-fit a copy of its potential on the refined steps to go ->
    (refinement in storage order, re-fitted potential)."""
    steps, refinement = refine_learner_demos(learner, q_values, settings or ProgressRefine())
    potential = copy.deepcopy(learner.fit.potential).cpu()
    to_go = refined_to_go(steps["episode"], steps["to_go"], refinement.decisions)
    fit_potential(potential, steps["observation"], to_go, learner.config.gamma, seed=learner.config.seed)
    return refinement, potential
