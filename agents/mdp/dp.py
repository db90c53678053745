"""Dynamic programming on a :class:`~agents.mdp.model.FiniteMDP` (thesis ch. 2.3).

Stopping rule (Puterman, *Markov Decision Processes*, 1994, thm. 6.3.1): the
value-iteration family stops when the sup-norm change of one sweep,
``residual = max_s |V_{k+1}(s) - V_k(s)|``, falls below
``eps * (1 - gamma) / (2 * gamma)``. Every sweep used here (Jacobi, Gauss-Seidel,
Q-value) is a gamma-contraction with fixed point ``V*``, so then
``max_s |V_{k+1}(s) - V*(s)| <= bound = gamma * residual / (1 - gamma) < eps / 2``
and the greedy policy of ``V_{k+1}`` is eps-optimal (its loss is at most
``2 * bound``). Policy iteration reports the a-posteriori bound
``||T V - V|| / (1 - gamma)`` instead, which holds for any ``V``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from agents.mdp.model import FiniteMDP


@dataclass(frozen=True)
class SolveResult:
    """What every solver returns."""

    values: np.ndarray
    """``(S,)`` value estimate."""
    policy: np.ndarray
    """``(S,)`` greedy action of ``values`` (int64)."""
    iterations: int
    """Sweeps (value-iteration family) or policy improvements (policy iteration)."""
    residual: float
    """Sup-norm change of the last sweep, or Bellman residual ``||T V - V||`` for policy iteration."""
    bound: float
    """Guaranteed upper bound on ``max_s |values(s) - V*(s)|``."""
    converged: bool
    """False when ``max_iter`` stopped the solver before its stopping rule."""
    method: str
    q: np.ndarray | None = None
    """``(S, A)`` action values (Q-value iteration only)."""


def stopping_threshold(eps: float, gamma: float) -> float:
    """Sweep change below which the greedy policy is eps-optimal."""
    if not eps > 0:
        raise ValueError(f"eps must be positive, got {eps}")
    return math.inf if gamma == 0 else eps * (1.0 - gamma) / (2.0 * gamma)


def contraction_bound(residual: float, gamma: float) -> float:
    """``max |V_{k+1} - V*|`` bound after a gamma-contraction sweep that changed V by ``residual``."""
    return gamma * residual / (1.0 - gamma)


def _initial_values(mdp: FiniteMDP, values0: np.ndarray | None) -> np.ndarray:
    if values0 is None:
        return np.zeros(mdp.n_states)
    values = np.array(values0, dtype=np.float64)
    if values.shape != (mdp.n_states,):
        raise ValueError(f"values0 must have shape ({mdp.n_states},), got {values.shape}")
    return values


def _finish(mdp: FiniteMDP, values, iterations, residual, converged, method) -> SolveResult:
    _, policy = mdp.bellman(values)
    bound = contraction_bound(residual, mdp.gamma)
    return SolveResult(values, policy, iterations, float(residual), bound, converged, method)


def policy_evaluation(
    mdp: FiniteMDP,
    policy: np.ndarray,
    method: str = "exact",
    tol: float = 1e-8,
    max_iter: int = 100_000,
    values0: np.ndarray | None = None,
) -> np.ndarray:
    """Value of a deterministic ``(S,)`` or stochastic ``(S, A)`` policy.

    ``method="exact"`` solves ``(I - gamma P_pi) V = r_pi`` with a sparse LU;
    ``"iterative"`` applies ``V <- r_pi + gamma P_pi V`` until ``max |V - V_pi| <= tol``
    is guaranteed (or ``max_iter``)."""
    p_pi, r_pi = mdp.policy_model(policy)
    if method == "exact":
        system = sp.identity(mdp.n_states, format="csc") - mdp.gamma * sp.csc_array(p_pi)
        return np.asarray(spla.spsolve(system, r_pi), dtype=np.float64).reshape(mdp.n_states)
    if method != "iterative":
        raise ValueError(f"method must be 'exact' or 'iterative', got {method!r}")
    values = _initial_values(mdp, values0)
    threshold = math.inf if mdp.gamma == 0 else tol * (1.0 - mdp.gamma) / mdp.gamma
    for _ in range(max_iter):
        new = r_pi + mdp.gamma * (p_pi @ values)
        change = float(np.max(np.abs(new - values)))
        values = new
        if change <= threshold:
            break
    return values


def value_iteration(
    mdp: FiniteMDP, eps: float = 0.01, max_iter: int = 100_000, values0: np.ndarray | None = None
) -> SolveResult:
    """Jacobi value iteration ``V <- max_a Q(V)``, one stacked sparse product per sweep."""
    threshold = stopping_threshold(eps, mdp.gamma)
    values = _initial_values(mdp, values0)
    residual, iterations = math.inf, 0
    while iterations < max_iter and not residual < threshold:
        new = mdp.q_values(values).max(axis=1)
        residual = float(np.max(np.abs(new - values)))
        values = new
        iterations += 1
    return _finish(mdp, values, iterations, residual, residual < threshold, "vi")


@njit(cache=True)
def _gauss_seidel(indptr, indices, data, rewards, n_actions, gamma, values, threshold, max_iter):
    """In-place sweeps over states in index order; rows are ``s * A + a``."""
    n_states = values.shape[0]
    delta = np.inf
    sweeps = 0
    while sweeps < max_iter and not delta < threshold:
        delta = 0.0
        for s in range(n_states):
            best = -np.inf
            for a in range(n_actions):
                row = s * n_actions + a
                acc = 0.0
                for k in range(indptr[row], indptr[row + 1]):
                    acc += data[k] * values[indices[k]]
                q = rewards[row] + gamma * acc
                if q > best:
                    best = q
            change = abs(best - values[s])
            if change > delta:
                delta = change
            values[s] = best
        sweeps += 1
    return sweeps, delta


def gauss_seidel_value_iteration(
    mdp: FiniteMDP, eps: float = 0.01, max_iter: int = 100_000, values0: np.ndarray | None = None
) -> SolveResult:
    """Gauss-Seidel value iteration: each state's backup uses the values already
    updated in the same sweep (compiled, in state order)."""
    threshold = stopping_threshold(eps, mdp.gamma)
    values = _initial_values(mdp, values0)
    by_state = mdp.stacked_by_state
    sweeps, residual = _gauss_seidel(
        by_state.indptr,
        by_state.indices,
        by_state.data,
        np.ascontiguousarray(mdp.rewards).ravel(),
        mdp.n_actions,
        mdp.gamma,
        values,
        threshold,
        max_iter,
    )
    return _finish(mdp, values, int(sweeps), float(residual), residual < threshold, "gs")


def _improve(q: np.ndarray, policy: np.ndarray) -> np.ndarray:
    """Greedy policy of ``q``, keeping the current action where it is already
    (numerically) greedy, so ties cannot make policy iteration cycle."""
    best = q.max(axis=1)
    current = q[np.arange(len(policy)), policy]
    keep = current >= best - 1e-12 * np.maximum(1.0, np.abs(best))
    return np.where(keep, policy, np.argmax(q, axis=1))


def policy_iteration(
    mdp: FiniteMDP,
    policy0: np.ndarray | None = None,
    evaluation: str = "exact",
    max_iter: int = 1000,
    eval_tol: float = 1e-10,
) -> SolveResult:
    """Howard's policy iteration: evaluate (``"exact"`` sparse solve or
    ``"iterative"``), improve greedily, stop when the policy is stable. Starts
    from the policy maximising the immediate reward unless ``policy0`` is given."""
    if policy0 is None:
        policy = np.argmax(mdp.rewards, axis=1)
    else:
        policy = np.asarray(policy0, dtype=np.int64)
        if policy.shape != (mdp.n_states,):
            raise ValueError(f"policy0 must have shape ({mdp.n_states},), got {policy.shape}")
    values = np.zeros(mdp.n_states)
    converged, iterations = False, 0
    while iterations < max_iter:
        values = policy_evaluation(mdp, policy, evaluation, tol=eval_tol, values0=values)
        iterations += 1
        improved = _improve(mdp.q_values(values), policy)
        if np.array_equal(improved, policy):
            converged = True
            break
        policy = improved
    residual = float(np.max(np.abs(mdp.q_values(values).max(axis=1) - values)))
    bound = residual / (1.0 - mdp.gamma)
    return SolveResult(values, policy, iterations, residual, bound, converged, "pi")


def modified_policy_iteration(
    mdp: FiniteMDP,
    eps: float = 0.01,
    partial_steps: int = 10,
    max_iter: int = 100_000,
    values0: np.ndarray | None = None,
) -> SolveResult:
    """Modified policy iteration (Puterman ch. 6.5): a greedy backup, then
    ``partial_steps`` backups with that policy fixed (0 gives value iteration).
    Starts below ``V*`` (``min R / (1 - gamma)``) unless ``values0`` is given."""
    if partial_steps < 0:
        raise ValueError(f"partial_steps must be >= 0, got {partial_steps}")
    threshold = stopping_threshold(eps, mdp.gamma)
    if values0 is None:
        values = np.full(mdp.n_states, mdp.rewards.min() / (1.0 - mdp.gamma))
    else:
        values = _initial_values(mdp, values0)
    residual, iterations = math.inf, 0
    while iterations < max_iter:
        new, policy = mdp.bellman(values)
        residual = float(np.max(np.abs(new - values)))
        values = new
        iterations += 1
        if residual < threshold:
            break
        p_pi, r_pi = mdp.policy_model(policy)
        for _ in range(partial_steps):
            values = r_pi + mdp.gamma * (p_pi @ values)
    return _finish(mdp, values, iterations, residual, residual < threshold, "mpi")


def q_value_iteration(
    mdp: FiniteMDP, eps: float = 0.01, max_iter: int = 100_000, q0: np.ndarray | None = None
) -> SolveResult:
    """Value iteration on action values: ``Q <- R + gamma P max_a' Q``."""
    threshold = stopping_threshold(eps, mdp.gamma)
    q = np.zeros((mdp.n_states, mdp.n_actions)) if q0 is None else np.array(q0, dtype=np.float64)
    if q.shape != (mdp.n_states, mdp.n_actions):
        raise ValueError(f"q0 must have shape {(mdp.n_states, mdp.n_actions)}, got {q.shape}")
    residual, iterations = math.inf, 0
    while iterations < max_iter and not residual < threshold:
        new = mdp.q_values(q.max(axis=1))
        residual = float(np.max(np.abs(new - q)))
        q = new
        iterations += 1
    bound = contraction_bound(residual, mdp.gamma)
    return SolveResult(
        q.max(axis=1), np.argmax(q, axis=1), iterations, residual, bound, residual < threshold, "qvi", q
    )


SOLVERS: dict[str, Callable[..., SolveResult]] = {
    "vi": value_iteration,
    "gs": gauss_seidel_value_iteration,
    "pi": policy_iteration,
    "mpi": modified_policy_iteration,
    "qvi": q_value_iteration,
}
