"""Fast value iteration for grid MDPs: compiled Gauss-Seidel sweeps over the
grid's neighbour table instead of sparse matrix products.

Three things make it fast, each exact (the fixed point is still ``V*``):

* **stencil**: a state's backup reads its B successor values straight from
  ``GridDynamics.successor`` (no CSR indices), and with the grid's uniform slip
  ``Q(s, a) = alpha * W_a + beta * sum_b W_b`` with ``W_b = r(s, b) + gamma V(succ(s, b))``,
  so all A actions cost O(B), not O(A * B);
* **goal-outward Gauss-Seidel order**: states are swept by increasing
  shortest-path distance to the goal, in place, so one sweep carries the goal's
  information across the whole map instead of one cell per sweep; the states
  are renumbered in that order first, so a sweep walks memory sequentially and
  neighbours (at nearby distances) sit close by;
* **self-loop elimination**: a blocked move keeps the robot in place, so
  ``V(s)`` appears on both sides of its own backup; each action's equation
  ``q = c + gamma * stay * q`` is solved exactly (``q = c / (1 - gamma * stay)``).

Each such sweep is still a gamma-contraction in the sup norm, so the stopping
rule and bound of :mod:`agents.mdp.dp` hold unchanged. ``dtype=np.float32`` runs
the sweeps in single precision and then polishes in double precision until the
same stopping rule holds, so the result carries the same guarantee.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from agents.mdp.dp import SolveResult, contraction_bound, stopping_threshold
from agents.planning import distance_field
from worlds.gridworld import GridDynamics


@njit(cache=True)
def _sweeps(successor, reward, alpha, beta, gamma, values, threshold, max_sweeps):
    """In-place Gauss-Seidel sweeps over states ``0..S-1`` (already renumbered in
    sweep order) with the uniform-slip backup ``alpha * W_a + beta * sum_b W_b``."""
    n_states, n_outcomes = successor.shape
    w = np.empty(n_outcomes, dtype=values.dtype)
    stay = np.zeros(n_outcomes, dtype=values.dtype)
    g = values.dtype.type(gamma)
    delta = np.inf
    sweeps = 0
    while sweeps < max_sweeps and not delta < threshold:
        delta = 0.0
        for s in range(n_states):
            w_sum = 0.0
            w_max = -np.inf
            stay_sum = 0.0
            for b in range(n_outcomes):
                nxt = successor[s, b]
                if nxt == s:
                    w[b] = reward[s, b]
                    stay[b] = 1.0
                    stay_sum += 1.0
                else:
                    w[b] = reward[s, b] + g * values[nxt]
                    stay[b] = 0.0
                w_sum += w[b]
                w_max = max(w_max, w[b])
            if stay_sum == 0.0:  # no blocked move: the best action is the best move
                best = alpha * w_max + beta * w_sum
            else:  # solve each action's self-loop: q = c + gamma * p_stay * q
                best = -np.inf
                for a in range(n_outcomes):
                    q = (alpha * w[a] + beta * w_sum) / (1.0 - g * (alpha * stay[a] + beta * stay_sum))
                    best = max(best, q)
            delta = max(delta, abs(best - values[s]))
            values[s] = best
        sweeps += 1
    return sweeps, delta


@njit(cache=True)
def _greedy_policy(successor, reward, prob, gamma, values):
    """``argmax_a Q(s, a)`` of ``values`` for every state (a Jacobi backup)."""
    n_states, n_outcomes = successor.shape
    n_actions = prob.shape[0]
    policy = np.empty(n_states, dtype=np.int64)
    for s in range(n_states):
        best = -np.inf
        for a in range(n_actions):
            q = 0.0
            for b in range(n_outcomes):
                q += prob[a, b] * (reward[s, b] + gamma * values[successor[s, b]])
            if q > best:
                best = q
                policy[s] = a
    return policy


def goal_outward_order(dynamics: GridDynamics) -> np.ndarray:
    """States sorted by shortest-path distance to the goal (goal first)."""
    dist = distance_field(dynamics.grid, dynamics.goal, dynamics.config.connectivity)
    cells = dynamics.cells
    return np.argsort(dist[cells[:, 0], cells[:, 1]], kind="stable")


def grid_value_iteration(
    dynamics: GridDynamics,
    gamma: float = 0.99,
    eps: float = 0.01,
    max_sweeps: int = 100_000,
    order: str = "goal-outward",
    dtype: type = np.float64,
) -> SolveResult:
    """eps-optimal values and greedy policy of the grid MDP (see the module docstring).

    Starts from the lower bound ``min reward / (1 - gamma)``, so values rise
    monotonically (a start above ``V*`` makes the max chase optimistic
    neighbours and needs several times more sweeps). ``order`` is
    ``"goal-outward"`` or ``"index"`` (row-major, for comparison).
    """
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma must be in [0, 1), got {gamma}")
    if np.dtype(dtype) not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    threshold = stopping_threshold(eps, gamma)
    if order == "goal-outward":
        sweep_order = goal_outward_order(dynamics)
    elif order == "index":
        sweep_order = np.arange(dynamics.n_states)
    else:
        raise ValueError(f"order must be 'goal-outward' or 'index', got {order!r}")
    rank = np.empty_like(sweep_order)
    rank[sweep_order] = np.arange(len(sweep_order))
    successor = rank[dynamics.successor[sweep_order]].astype(np.int32)  # states renumbered in sweep order
    reward = dynamics.reward[sweep_order]
    n_moves = dynamics.n_actions
    beta = dynamics.config.slip / (n_moves - 1)
    alpha = 1.0 - dynamics.config.slip - beta
    values = np.full(dynamics.n_states, reward.min() / (1.0 - gamma), dtype=np.float64)
    sweeps = 0
    if np.dtype(dtype) == np.float32:
        # single precision cannot resolve changes much below an ulp of |V|: stop there, polish in double
        ulp = float(np.spacing(np.float32(np.abs(values).max())))
        values32 = values.astype(np.float32)
        sweeps, _ = _sweeps(
            successor,
            reward.astype(np.float32),
            alpha,
            beta,
            gamma,
            values32,
            max(threshold, 8 * ulp),
            max_sweeps,
        )
        values = values32.astype(np.float64)
    more, residual = _sweeps(
        successor, reward, alpha, beta, gamma, values, threshold, max(max_sweeps - sweeps, 1)
    )
    sweeps += int(more)
    values = values[rank]  # back to state numbering
    policy = _greedy_policy(dynamics.successor, dynamics.reward, dynamics.outcome_prob, gamma, values)
    residual = float(residual)
    bound = contraction_bound(residual, gamma) if math.isfinite(residual) else math.inf
    return SolveResult(values, policy, sweeps, residual, bound, residual < threshold, f"grid-gs/{order}")
