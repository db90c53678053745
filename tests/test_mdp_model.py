"""FiniteMDP: pymdptoolbox's input conventions, expected rewards, and clear errors on bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from agents.mdp import FiniteMDP, InvalidMDPError
from tests.mdp_helpers import random_mdp_arrays


def test_dense_and_sparse_inputs_describe_the_same_mdp():
    P, R = random_mdp_arrays(np.random.default_rng(0), 6, 3)
    dense = FiniteMDP(P, R, 0.9)
    sparse = FiniteMDP([sp.csr_matrix(p) for p in P], R, 0.9)
    listed = FiniteMDP(list(P), R, 0.9)
    values = np.arange(6.0)
    for other in (sparse, listed):
        np.testing.assert_allclose(other.q_values(values), dense.q_values(values))
    assert dense.n_states == 6 and dense.n_actions == 3 and dense.stacked.shape == (18, 6)


def test_q_values_is_the_bellman_backup():
    P, R = random_mdp_arrays(np.random.default_rng(1), 5, 4)
    mdp = FiniteMDP(P, R, 0.8)
    values = np.random.default_rng(2).normal(size=5)
    expected = R + 0.8 * np.einsum("ast,t->sa", P, values)
    np.testing.assert_allclose(mdp.q_values(values), expected)
    new, policy = mdp.bellman(values)
    np.testing.assert_allclose(new, expected.max(axis=1))
    np.testing.assert_array_equal(policy, expected.argmax(axis=1))
    by_state = mdp.stacked_by_state.toarray()
    np.testing.assert_allclose(by_state[2 * 4 + 3], P[3, 2])


def test_reward_shapes_follow_pymdptoolbox():
    rng = np.random.default_rng(3)
    P, _ = random_mdp_arrays(rng, 4, 2)
    per_state = rng.normal(size=4)
    np.testing.assert_allclose(FiniteMDP(P, per_state, 0.5).rewards, np.repeat(per_state[:, None], 2, axis=1))
    per_transition = rng.normal(size=(2, 4, 4))
    expected = np.einsum("ast,ast->sa", P, per_transition)
    np.testing.assert_allclose(FiniteMDP(P, per_transition, 0.5).rewards, expected)
    sparse_rewards = [sp.csr_matrix(r * (p > 0)) for r, p in zip(per_transition, P, strict=True)]
    np.testing.assert_allclose(FiniteMDP(P, sparse_rewards, 0.5).rewards, expected)


def test_policy_model_for_deterministic_and_stochastic_policies():
    P, R = random_mdp_arrays(np.random.default_rng(4), 5, 3)
    mdp = FiniteMDP(P, R, 0.9)
    policy = np.array([0, 2, 1, 1, 0])
    p_pi, r_pi = mdp.policy_model(policy)
    np.testing.assert_allclose(p_pi.toarray(), P[policy, np.arange(5)])
    np.testing.assert_allclose(r_pi, R[np.arange(5), policy])
    mixed = np.full((5, 3), 1 / 3)
    p_mix, r_mix = mdp.policy_model(mixed)
    np.testing.assert_allclose(p_mix.toarray(), P.mean(axis=0))
    np.testing.assert_allclose(r_mix, R.mean(axis=1))
    with pytest.raises(ValueError, match=r"actions must be in 0\.\.2"):
        mdp.policy_model(np.array([0, 3, 0, 0, 0]))
    with pytest.raises(ValueError, match="probability distributions"):
        mdp.policy_model(np.full((5, 3), 0.5))


def with_row(P: np.ndarray, action: int, state: int, row: list[float]) -> np.ndarray:
    out = P.copy()
    out[action, state] = row
    return out


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda P, R: (P * 1.01, R), r"row 0 sums to 1\.01"),
        (
            lambda P, R: (with_row(P, 1, 0, [1.2, -0.2, 0, 0]), R),
            r"P\[1\] has a negative probability in row 0",
        ),
        (lambda P, R: (np.where(np.arange(4) == 2, np.nan, P), R), "NaN or infinite"),
        (lambda P, R: (P, np.where(R > 0, np.inf, R)), "NaN or infinite"),
        (lambda P, R: (P[:, :3, :], R), r"shape \(3, 4\), expected \(3, 3\)"),
        (lambda P, R: ([P[0], P[1][:3, :3]], R), r"P\[1\] has shape \(3, 3\), expected \(4, 4\)"),
        (lambda P, R: (P, R.T), r"transposed\? R is \(S, A\)"),
        (lambda P, R: (P, R[:3]), r"R has shape \(3, 2\), expected \(S, A\)"),
        (lambda P, R: (P, np.ones(5)), r"does not match S = 4"),
        (lambda P, R: (P[0], R), r"shape \(A, S, S\)"),
        (lambda P, R: (sp.csr_matrix(P[0]), R), "one sparse matrix"),
        (lambda P, R: ([], R), r"no actions"),
    ],
)
def test_invalid_inputs_raise_clear_errors(mutate, message):
    P, R = random_mdp_arrays(np.random.default_rng(5), 4, 2, density=1.0)
    bad_P, bad_R = mutate(P, R)
    with pytest.raises(InvalidMDPError, match=message):
        FiniteMDP(bad_P, bad_R, 0.9)


@pytest.mark.parametrize("gamma", [1.0, -0.1, 1.5, float("nan"), "0.9", True])
def test_gamma_must_be_in_zero_one(gamma):
    P, R = random_mdp_arrays(np.random.default_rng(6), 3, 2)
    with pytest.raises(InvalidMDPError, match=r"gamma must be a number in \[0, 1\)"):
        FiniteMDP(P, R, gamma)


def test_row_sum_tolerance_is_configurable():
    P, R = random_mdp_arrays(np.random.default_rng(7), 3, 2)
    nudged = P * (1 + 1e-6)
    with pytest.raises(InvalidMDPError, match="tolerance 1e-08"):
        FiniteMDP(nudged, R, 0.9)
    assert FiniteMDP(nudged, R, 0.9, atol=1e-5).n_states == 3
