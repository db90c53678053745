"""Dynamic programming checked against pymdptoolbox (random and grid MDPs), against each
other, against A* (no slip), and the stopping-rule bound."""

from __future__ import annotations

import warnings

import mdptoolbox.mdp as toolbox
import numpy as np
import pytest
import scipy.sparse as sp

from agents.mdp import (
    SOLVERS,
    FiniteMDP,
    gauss_seidel_value_iteration,
    grid_mdp,
    grid_value_iteration,
    modified_policy_iteration,
    policy_evaluation,
    policy_iteration,
    q_value_iteration,
    value_iteration,
)
from agents.planning import astar
from tests.mdp_helpers import random_mdp_arrays
from worlds.gridworld import GridDynamics, GridWorldConfig
from worlds.maps import load_movingai, parse_ascii

SMALL_MAP = """\
##########
#........#
#..##....#
#..#..#..#
#.....#..#
####..#..#
#........#
##########
"""


def optimal_up_to_ties(mdp: FiniteMDP, v_star: np.ndarray, policy, tol: float = 1e-6) -> np.ndarray:
    """Per state: is the policy's action optimal (its Q* within tol of V*)?"""
    q_star = mdp.q_values(v_star)
    policy = np.asarray(policy)
    return q_star[np.arange(len(policy)), policy] >= v_star - tol


def toolbox_run(cls, P, R, gamma, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its sparse input check warns about efficiency
        solver = cls(P, R, gamma, **kwargs)
        solver.run()
    return np.asarray(solver.V), np.asarray(solver.policy)


def small_grid_mdp(slip: float = 0.1, gamma: float = 0.95, connectivity: int = 8):
    grid, _ = parse_ascii(SMALL_MAP)
    dyn, mdp = grid_mdp(grid, (6, 8), GridWorldConfig(connectivity=connectivity, slip=slip), gamma)
    return dyn, mdp


@pytest.mark.parametrize(
    ("seed", "n_states", "n_actions", "gamma"), [(0, 10, 3, 0.9), (1, 30, 4, 0.95), (2, 50, 2, 0.5)]
)
def test_random_mdps_match_pymdptoolbox(seed, n_states, n_actions, gamma):
    P, R = random_mdp_arrays(np.random.default_rng(seed), n_states, n_actions)
    mdp = FiniteMDP(P, R, gamma)
    v_pi_theirs, policy_pi_theirs = toolbox_run(toolbox.PolicyIteration, P, R, gamma)
    ours = policy_iteration(mdp)
    np.testing.assert_allclose(ours.values, v_pi_theirs, atol=1e-8)
    assert optimal_up_to_ties(mdp, ours.values, policy_pi_theirs).all()
    assert optimal_up_to_ties(mdp, ours.values, ours.policy).all()
    _, policy_vi_theirs = toolbox_run(toolbox.ValueIteration, P, R, gamma, epsilon=1e-4)
    ours_vi = value_iteration(mdp, eps=1e-4)
    assert optimal_up_to_ties(mdp, ours.values, policy_vi_theirs, tol=1e-4).all()
    assert optimal_up_to_ties(mdp, ours.values, ours_vi.policy, tol=1e-4).all()
    for name, solver in SOLVERS.items():
        result = solver(mdp)
        assert result.converged, name
        assert np.max(np.abs(result.values - ours.values)) <= result.bound + 1e-9, name
        assert optimal_up_to_ties(mdp, ours.values, result.policy, tol=2 * result.bound + 1e-9).all(), name


def test_per_transition_rewards_match_pymdptoolbox():
    rng = np.random.default_rng(7)
    P, _ = random_mdp_arrays(rng, 12, 3)
    R3 = rng.normal(size=(3, 12, 12))
    v_theirs, _ = toolbox_run(toolbox.PolicyIteration, P, R3, 0.9)
    np.testing.assert_allclose(policy_iteration(FiniteMDP(P, R3, 0.9)).values, v_theirs, atol=1e-8)


@pytest.mark.parametrize("connectivity", [8, 4])
def test_grid_mdp_matches_pymdptoolbox(connectivity):
    dyn, mdp = small_grid_mdp(connectivity=connectivity)
    P = [sp.csr_matrix(p) for p in mdp.transitions]  # pymdptoolbox's own (strict) input check runs here
    v_theirs, policy_theirs = toolbox_run(toolbox.PolicyIteration, P, mdp.rewards, mdp.gamma)
    ours = policy_iteration(mdp)
    np.testing.assert_allclose(ours.values, v_theirs, atol=1e-8)
    assert optimal_up_to_ties(mdp, ours.values, policy_theirs).all()
    _, policy_vi_theirs = toolbox_run(toolbox.ValueIteration, P, mdp.rewards, mdp.gamma, epsilon=0.01)
    assert optimal_up_to_ties(mdp, ours.values, policy_vi_theirs, tol=0.01).all()
    fast = grid_value_iteration(dyn, mdp.gamma, eps=0.01)
    assert np.max(np.abs(fast.values - ours.values)) <= fast.bound
    assert optimal_up_to_ties(mdp, ours.values, fast.policy, tol=0.01).all()


def test_every_solver_meets_its_bound_on_a_grid():
    dyn, mdp = small_grid_mdp(gamma=0.99)
    exact = policy_iteration(mdp)
    assert exact.converged and exact.bound < 1e-9
    results = [
        value_iteration(mdp, eps=0.01),
        gauss_seidel_value_iteration(mdp, eps=0.01),
        modified_policy_iteration(mdp, eps=0.01, partial_steps=5),
        q_value_iteration(mdp, eps=0.01),
        policy_iteration(mdp, evaluation="iterative"),
        grid_value_iteration(dyn, 0.99, eps=0.01),
        grid_value_iteration(dyn, 0.99, eps=0.01, order="index"),
        grid_value_iteration(dyn, 0.99, eps=0.01, dtype=np.float32),
    ]
    for result in results:
        error = np.max(np.abs(result.values - exact.values))
        assert result.converged and error <= result.bound, result.method
        assert result.bound < 0.005 or result.method == "pi", result.method  # eps / 2
        assert optimal_up_to_ties(mdp, exact.values, result.policy, tol=0.01).all(), result.method
    assert results[0].iterations > results[5].iterations  # goal-outward Gauss-Seidel needs fewer sweeps


def test_stopping_rule_reports_unconverged_runs():
    _, mdp = small_grid_mdp(gamma=0.99)
    result = value_iteration(mdp, eps=1e-6, max_iter=3)
    assert not result.converged and result.iterations == 3
    assert result.bound == pytest.approx(0.99 * result.residual / 0.01)


def test_policy_evaluation_exact_equals_iterative():
    _, mdp = small_grid_mdp()
    policy = np.random.default_rng(0).integers(mdp.n_actions, size=mdp.n_states)
    exact = policy_evaluation(mdp, policy)
    iterative = policy_evaluation(mdp, policy, method="iterative", tol=1e-9)
    np.testing.assert_allclose(iterative, exact, atol=1e-9)
    p_pi, r_pi = mdp.policy_model(policy)
    np.testing.assert_allclose(exact, r_pi + mdp.gamma * (p_pi @ exact), atol=1e-9)
    with pytest.raises(ValueError, match="'exact' or 'iterative'"):
        policy_evaluation(mdp, policy, method="magic")


def test_without_slip_the_greedy_path_is_a_shortest_path(arena_paths):
    grid = load_movingai(arena_paths[0])
    start, goal = (2, 2), (46, 47)
    config = GridWorldConfig(slip=0.0, collision_cost=1.0)
    dyn = GridDynamics.build(grid, goal, config)
    result = grid_value_iteration(dyn, 0.9999, eps=1e-3)
    path = dyn.intended_path(result.policy, start)
    assert path[-1] == goal
    steps = np.abs(np.diff(np.asarray(path), axis=0)).sum(axis=1)
    length = float(np.sum(np.where(steps == 2, np.sqrt(2), 1.0)))
    assert length == pytest.approx(astar(grid, start, goal).length, abs=1e-9)
