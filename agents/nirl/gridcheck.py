"""Is the learned reward a reward? A check where the true one is known: the MDP toolkit's grid world.

The expert acts optimally on ``worlds.gridworld``'s MDP (``agents.mdp.grid_mdp``: 8 moves, slip,
step and collision costs); its demonstrated transitions, sampled from the true dynamics, train a
tabular soft Q-function with the same IQ-Learn objective the navigation learner uses
(``losses.iq_loss``, offline form). The reward it holds is read with the model,
``r(s, a) = Q(s, a) - gamma * sum_s' P(s' | s, a) V(s')`` (the inverse soft Bellman operator,
the goal absorbing with value 0), and the MDP is solved again under ``r`` alone by Q-value
iteration. The figure is the share of states whose optimal action under the learned reward is
an optimal action under the true one (``policy_agreement``); the issue's bar is 95%.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from agents.mdp import FiniteMDP, grid_mdp, q_value_iteration
from agents.nirl.losses import iq_loss, soft_value
from worlds.gridworld import DEFAULT_MAP, GridWorldConfig
from worlds.maps import parse_ascii


@dataclass
class RecoveryResult:
    """What the check measured."""

    agreement: float
    """share of non-goal states whose greedy action under the learned reward is truly optimal"""
    demo_agreement: float
    """the same for the soft Q-function's own greedy policy (imitation, before re-planning)"""
    states: int
    demo_transitions: int
    reward_correlation: float
    """Pearson correlation of learned and true reward over the expert's (state, action) pairs"""


def expert_transitions(
    mdp: FiniteMDP,
    policy: np.ndarray,
    goal_state: int,
    episodes: int,
    rng: np.random.Generator,
    max_steps: int = 200,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(states, actions, next_states, terminated) of ``episodes`` runs of ``policy`` from uniformly
    drawn non-goal starts, next states drawn from the MDP's own transition rows."""
    starts = [s for s in range(mdp.n_states) if s != goal_state]
    rows: list[tuple[int, int, int, bool]] = []
    for _ in range(episodes):
        s = int(rng.choice(starts))
        for _ in range(max_steps):
            a = int(policy[s])
            row = mdp.transitions[a][[s]]
            s_next = int(rng.choice(row.indices, p=row.data / row.data.sum()))
            rows.append((s, a, s_next, s_next == goal_state))
            s = s_next
            if s == goal_state:
                break
    s, a, n, d = (np.asarray(col) for col in zip(*rows, strict=True))
    return s.astype(np.int64), a.astype(np.int64), n.astype(np.int64), d.astype(bool)


def iq_learn_tabular(
    n_states: int,
    n_actions: int,
    transitions: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    gamma: float,
    alpha: float = 0.05,
    chi2_alpha: float = 0.5,
    steps: int = 3000,
    lr: float = 0.05,
    seed: int = 0,
) -> np.ndarray:
    """A tabular soft Q-function ``(S, A)`` fitted by offline IQ-Learn (full-batch Adam)."""
    gen = torch.Generator().manual_seed(seed)
    q = torch.nn.Parameter(0.01 * torch.randn(n_states, n_actions, generator=gen, dtype=torch.float64))
    optimiser = torch.optim.Adam([q], lr=lr)
    s, a, n, d = (torch.as_tensor(x) for x in transitions)
    expert = torch.ones(len(s), dtype=torch.bool)
    for _ in range(steps):
        values = soft_value(q, alpha)
        terms = iq_loss(q[s, a], values[s], values[n], d, expert, gamma, chi2_alpha)
        optimiser.zero_grad()
        terms.loss.backward()
        optimiser.step()
    return q.detach().numpy()


def recovered_reward(mdp: FiniteMDP, q: np.ndarray, goal_state: int, alpha: float) -> np.ndarray:
    """``r(s, a) = Q(s, a) - gamma * E[V(s')]`` with the model's transitions; the goal (absorbing,
    value 0 after it is entered) earns 0."""
    values = soft_value(torch.as_tensor(q), alpha).numpy()
    values[goal_state] = 0.0
    expected_next = np.stack([mdp.transitions[a] @ values for a in range(mdp.n_actions)], axis=1)
    reward = q - mdp.gamma * expected_next
    reward[goal_state] = 0.0
    return reward


def optimal_sets(q: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """(S, A) bool: actions within ``tol`` (relative to the value scale) of each state's best."""
    scale = max(1.0, float(np.abs(q).max()))
    return q >= q.max(axis=1, keepdims=True) - tol * scale


def policy_agreement(policy: np.ndarray, optimal: np.ndarray, exclude: int) -> float:
    """Share of states other than ``exclude`` whose action in ``policy`` is in ``optimal``."""
    states = np.array([s for s in range(len(policy)) if s != exclude])
    return float(optimal[states, policy[states]].mean())


def check_reward_recovery(
    grid_text: str = DEFAULT_MAP,
    episodes: int = 200,
    gamma: float = 0.95,
    alpha: float = 0.05,
    slip: float = 0.1,
    seed: int = 0,
) -> RecoveryResult:
    """Demonstrate, learn, re-plan under the learned reward and compare (see the module docstring)."""
    grid, markers = parse_ascii(grid_text)
    goal = markers["G"]
    dynamics, mdp = grid_mdp(grid, goal, GridWorldConfig(slip=slip), gamma=gamma)
    truth = q_value_iteration(mdp, eps=1e-8)
    optimal = optimal_sets(truth.q)
    rng = np.random.default_rng(seed)
    data = expert_transitions(mdp, truth.policy, dynamics.goal_state, episodes, rng)
    q = iq_learn_tabular(mdp.n_states, mdp.n_actions, data, gamma, alpha=alpha, seed=seed)
    reward = recovered_reward(mdp, q, dynamics.goal_state, alpha)
    replanned = q_value_iteration(FiniteMDP(list(mdp.transitions), reward, gamma), eps=1e-8)
    s, a = data[0], data[1]
    return RecoveryResult(
        agreement=policy_agreement(replanned.policy, optimal, dynamics.goal_state),
        demo_agreement=policy_agreement(q.argmax(axis=1), optimal, dynamics.goal_state),
        states=mdp.n_states,
        demo_transitions=len(s),
        reward_correlation=float(np.corrcoef(reward[s, a], mdp.rewards[s, a])[0, 1]),
    )
