"""Finite discounted MDP ``(S, A, T, r, gamma)`` of thesis ch. 2.2, with
pymdptoolbox's conventions for the inputs.

``P`` is ``(A, S, S)``: a dense array, or a sequence of ``A`` matrices
(dense or scipy.sparse), ``P[a][s, s']`` the probability of moving from ``s``
to ``s'`` under action ``a``. ``R`` is the reward, either ``(S, A)`` (per state
and action), ``(S,)`` (per state, whatever the action) or ``(A, S, S)`` (per
transition; also a sequence of ``A`` sparse matrices). It is stored as the
expected immediate reward ``R[s, a]``.

Internally the ``A`` transition matrices are stacked into one CSR matrix of
shape ``(A * S, S)``, row ``a * S + s``, so a Bellman backup is one sparse
matrix-vector product.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from functools import cached_property

import numpy as np
import scipy.sparse as sp


class InvalidMDPError(ValueError):
    """The arrays given do not describe a finite discounted MDP."""


def _as_sparse_matrices(P: object) -> list[sp.csr_array]:
    if sp.issparse(P):
        raise InvalidMDPError(
            "P must be an (A, S, S) array or a sequence of A (S, S) matrices, got one sparse matrix"
        )
    if isinstance(P, np.ndarray) and P.dtype != object:
        if P.ndim != 3:
            raise InvalidMDPError(f"P must have shape (A, S, S), got an array of shape {P.shape}")
        matrices = list(P)
    elif isinstance(P, Sequence | np.ndarray):
        matrices = list(P)
    else:
        raise InvalidMDPError(f"P must be an array or a sequence of matrices, got {type(P).__name__}")
    if not matrices:
        raise InvalidMDPError("P has no actions (A = 0)")
    out = []
    for a, m in enumerate(matrices):
        try:
            csr = sp.csr_array(m, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InvalidMDPError(f"P[{a}] is not a numeric matrix: {exc}") from None
        if csr.ndim != 2:
            raise InvalidMDPError(f"P[{a}] must be 2-D (S, S), got shape {csr.shape}")
        out.append(csr)
    return out


def _check_transitions(matrices: list[sp.csr_array], atol: float) -> None:
    n_states = matrices[0].shape[0]
    if n_states == 0:
        raise InvalidMDPError("P has no states (S = 0)")
    for a, m in enumerate(matrices):
        if m.shape != (n_states, n_states):
            raise InvalidMDPError(
                f"P[{a}] has shape {m.shape}, expected ({n_states}, {n_states}) "
                "(square, the same S for every action)"
            )
        if not np.isfinite(m.data).all():
            raise InvalidMDPError(f"P[{a}] contains NaN or infinite values")
        if (m.data < 0).any():
            s = int(np.searchsorted(m.indptr, int(np.argmax(m.data < 0)), side="right") - 1)
            raise InvalidMDPError(f"P[{a}] has a negative probability in row {s}")
        sums = np.asarray(m.sum(axis=1)).ravel()
        bad = np.abs(sums - 1.0) > atol
        if bad.any():
            s = int(np.argmax(bad))
            raise InvalidMDPError(
                f"P[{a}] row {s} sums to {sums[s]:.10g}, not 1 (tolerance {atol:g}); "
                f"{int(bad.sum())} row(s) of P[{a}] are not probability distributions"
            )


def _expected_reward(R: object, matrices: list[sp.csr_array]) -> np.ndarray:
    n_actions, n_states = len(matrices), matrices[0].shape[0]
    if sp.issparse(R):
        raise InvalidMDPError("R must be an array or a sequence of A matrices, got one sparse matrix")
    per_transition: list | None = None
    if isinstance(R, np.ndarray) and R.dtype != object:
        if R.ndim == 1:
            if R.shape != (n_states,):
                raise InvalidMDPError(f"R of shape {R.shape} does not match S = {n_states} (expected (S,))")
            expected = np.repeat(R.astype(np.float64)[:, None], n_actions, axis=1)
        elif R.ndim == 2:
            if R.shape != (n_states, n_actions):
                hint = " (transposed? R is (S, A))" if R.shape == (n_actions, n_states) else ""
                raise InvalidMDPError(
                    f"R has shape {R.shape}, expected (S, A) = {(n_states, n_actions)}{hint}"
                )
            expected = R.astype(np.float64)
        elif R.ndim == 3:
            if R.shape != (n_actions, n_states, n_states):
                raise InvalidMDPError(
                    f"R has shape {R.shape}, expected (A, S, S) = {(n_actions, n_states, n_states)}"
                )
            per_transition = list(R)
        else:
            raise InvalidMDPError(f"R must be (S,), (S, A) or (A, S, S), got shape {R.shape}")
    elif isinstance(R, Sequence | np.ndarray) and len(R) == n_actions:
        per_transition = list(R)
    else:
        raise InvalidMDPError(
            f"R must be (S,), (S, A) or (A, S, S) (or a sequence of A matrices), got {R!r:.80}"
        )
    if per_transition is not None:
        expected = np.empty((n_states, n_actions))
        for a, (r, p) in enumerate(zip(per_transition, matrices, strict=True)):
            r = sp.csr_array(r, dtype=np.float64)
            if r.shape != (n_states, n_states):
                raise InvalidMDPError(f"R[{a}] has shape {r.shape}, expected ({n_states}, {n_states})")
            if not np.isfinite(r.data).all():
                raise InvalidMDPError(f"R[{a}] contains NaN or infinite values")
            expected[:, a] = np.asarray(p.multiply(r).sum(axis=1)).ravel()
    if not np.isfinite(expected).all():
        raise InvalidMDPError("R contains NaN or infinite values")
    return np.ascontiguousarray(expected)


class FiniteMDP:
    """A validated finite discounted MDP.

    Attributes: ``transitions`` (tuple of ``A`` CSR ``(S, S)`` matrices),
    ``rewards`` (``(S, A)`` expected immediate reward), ``gamma``,
    ``stacked`` (CSR ``(A * S, S)``, row ``a * S + s``).
    Row sums of ``P`` must equal 1 within ``atol``.
    """

    def __init__(self, P: object, R: object, gamma: float, atol: float = 1e-8) -> None:
        if isinstance(gamma, bool) or not isinstance(gamma, numbers.Real) or not 0.0 <= float(gamma) < 1.0:
            raise InvalidMDPError(f"gamma must be a number in [0, 1), got {gamma!r}")
        matrices = _as_sparse_matrices(P)
        _check_transitions(matrices, atol)
        self.rewards = _expected_reward(R, matrices)
        self.gamma = float(gamma)
        self.transitions = tuple(matrices)
        self.stacked = sp.csr_array(sp.vstack(matrices, format="csr"))
        self._rewards_as = np.ascontiguousarray(self.rewards.T).ravel()  # row a * S + s

    @property
    def n_states(self) -> int:
        return int(self.rewards.shape[0])

    @property
    def n_actions(self) -> int:
        return int(self.rewards.shape[1])

    @cached_property
    def stacked_by_state(self) -> sp.csr_array:
        """The transitions as CSR ``(S * A, S)`` with row ``s * A + a`` (state-major,
        what an in-place Gauss-Seidel sweep walks through)."""
        s, a = np.meshgrid(np.arange(self.n_states), np.arange(self.n_actions), indexing="ij")
        return sp.csr_array(self.stacked[(a * self.n_states + s).ravel()])

    def q_values(self, values: np.ndarray) -> np.ndarray:
        """One Bellman backup: ``Q[s, a] = R[s, a] + gamma * sum_s' P[a][s, s'] V[s']``, shape (S, A)."""
        q = self._rewards_as + self.gamma * (self.stacked @ values)
        return q.reshape(self.n_actions, self.n_states).T

    def bellman(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The optimality operator: returns ``(T V, greedy policy)``."""
        q = self.q_values(values)
        policy = np.argmax(q, axis=1)
        return q[np.arange(self.n_states), policy], policy

    def policy_model(self, policy: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
        """``(P_pi, r_pi)`` of a deterministic policy ``(S,)`` of actions or a
        stochastic one ``(S, A)`` of probabilities."""
        policy = np.asarray(policy)
        n_states, n_actions = self.n_states, self.n_actions
        if policy.shape == (n_states,) and np.issubdtype(policy.dtype, np.integer):
            if policy.min() < 0 or policy.max() >= n_actions:
                raise ValueError(f"policy actions must be in 0..{n_actions - 1}")
            rows = policy * n_states + np.arange(n_states)
            return sp.csr_array(self.stacked[rows]), self.rewards[np.arange(n_states), policy]
        if policy.shape == (n_states, n_actions):
            if (policy < 0).any() or not np.allclose(policy.sum(axis=1), 1.0, atol=1e-8):
                raise ValueError("a stochastic policy's rows must be probability distributions")
            p_pi = sum(sp.diags_array(policy[:, a]) @ self.transitions[a] for a in range(n_actions))
            return sp.csr_array(p_pi), (policy * self.rewards).sum(axis=1)
        raise ValueError(
            f"policy must be (S,) integer actions or (S, A) probabilities with S={n_states}, A={n_actions}; "
            f"got shape {policy.shape} dtype {policy.dtype}"
        )

    def __repr__(self) -> str:
        return f"FiniteMDP(S={self.n_states}, A={self.n_actions}, gamma={self.gamma})"
