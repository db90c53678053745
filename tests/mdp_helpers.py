"""Helpers shared by the MDP tests (not a test module)."""

from __future__ import annotations

import numpy as np


def random_mdp_arrays(rng: np.random.Generator, n_states: int, n_actions: int, density: float = 0.5):
    """Random sparse-ish stochastic P (A, S, S) and R (S, A)."""
    mask = rng.random((n_actions, n_states, n_states)) < density
    mask[:, np.arange(n_states), rng.integers(n_states, size=n_states)] = True  # every row has an entry
    P = np.where(mask, rng.random((n_actions, n_states, n_states)), 0.0)
    P /= P.sum(axis=2, keepdims=True)
    R = rng.normal(size=(n_states, n_actions))
    return P, R
