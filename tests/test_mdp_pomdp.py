"""POMDP belief filter and QMDP: exact Bayes updates, localisation in a corridor with doors."""

from __future__ import annotations

import numpy as np
import pytest

from agents.mdp import BeliefFilter, grid_mdp, qmdp_action, value_iteration, wall_readings, wall_sensor_model
from worlds.gridworld import MOVE_NAMES, GridWorldConfig
from worlds.maps import parse_ascii

# A corridor whose only landmarks are the doors (free cells) along its north wall.
CORRIDOR = """\
########################
##.###.#.###..##.#.#####
#......................#
########################
"""
GOAL = (2, 22)
EAST = MOVE_NAMES.index("E")


def corridor(slip: float = 0.05, flip: float = 0.05, directions: int = 8):
    grid, _ = parse_ascii(CORRIDOR)
    dyn, mdp = grid_mdp(grid, GOAL, GridWorldConfig(connectivity=4, slip=slip), gamma=0.95)
    return dyn, mdp, BeliefFilter(mdp, wall_sensor_model(dyn, flip, directions))


def test_sensor_model_rows_are_distributions_and_readings_are_walls():
    dyn, _, belief_filter = corridor(flip=0.1, directions=4)
    assert belief_filter.observation.shape == (dyn.n_states, 16)
    np.testing.assert_allclose(belief_filter.observation.sum(axis=1), 1.0)
    west_end = dyn.state((2, 1))
    # bits N, S, W, E: blocked north, south and west, free east
    assert wall_readings(dyn, 4)[west_end] == 0b0111
    assert belief_filter.observation[west_end, 0b0111] == pytest.approx(0.9**4)
    assert belief_filter.observation[west_end, 0b1111] == pytest.approx(0.9**3 * 0.1)


def test_update_is_bayes_rule():
    dyn, mdp, belief_filter = corridor(slip=0.2, flip=0.2, directions=4)
    rng = np.random.default_rng(0)
    prior = rng.dirichlet(np.ones(dyn.n_states))
    P = mdp.transitions[EAST].toarray()
    obs = 0b0011
    expected = belief_filter.observation[:, obs] * (prior @ P)
    np.testing.assert_allclose(belief_filter.update(prior, EAST, obs), expected / expected.sum())
    impossible = np.zeros(dyn.n_states)
    impossible[dyn.state((2, 5))] = 1.0
    certain = BeliefFilter(mdp, wall_sensor_model(dyn, 0.0, 4))
    with pytest.raises(ValueError, match="probability 0"):
        certain.correct(impossible, 0b1111)
    with pytest.raises(ValueError, match="observation must be"):
        BeliefFilter(mdp, np.ones((3, 2)) / 2)


def test_belief_concentrates_on_the_true_cell_in_the_corridor():
    dyn, _, belief_filter = corridor()
    cumulative = np.cumsum(dyn.outcome_prob, axis=1)
    on_truth = []
    map_correct = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        state = dyn.state((2, 3))
        belief = belief_filter.correct(belief_filter.uniform(), belief_filter.sample_observation(rng, state))
        trace = [belief[state]]
        for _ in range(15):
            outcome = int(np.searchsorted(cumulative[EAST], rng.random(), side="right"))
            state = int(dyn.successor[state, outcome])
            belief = belief_filter.update(belief, EAST, belief_filter.sample_observation(rng, state))
            trace.append(belief[state])
        on_truth.append(trace)
        map_correct.append(int(np.argmax(belief)) == state)
    mean = np.mean(on_truth, axis=0)
    assert mean[0] < 0.3  # one look is ambiguous: many cells look alike
    assert mean[-1] > 0.9  # after passing a few doors the robot knows where it is
    assert np.mean(map_correct) >= 0.9


def test_qmdp_reaches_the_goal_from_an_unknown_start():
    dyn, mdp, belief_filter = corridor(slip=0.1, flip=0.1)
    q = mdp.q_values(value_iteration(mdp, eps=1e-6).values)
    cumulative = np.cumsum(dyn.outcome_prob, axis=1)
    for seed in range(5):
        rng = np.random.default_rng(seed)
        state = dyn.state((2, 1 + 3 * seed))
        belief = belief_filter.correct(belief_filter.uniform(), belief_filter.sample_observation(rng, state))
        for _ in range(60):
            if state == dyn.goal_state:
                break
            action = qmdp_action(belief, q)
            outcome = int(np.searchsorted(cumulative[action], rng.random(), side="right"))
            state = int(dyn.successor[state, outcome])
            belief = belief_filter.update(belief, action, belief_filter.sample_observation(rng, state))
        assert state == dyn.goal_state
    certain = np.eye(dyn.n_states)[dyn.state((1, 2))]
    assert qmdp_action(certain, q) == int(np.argmax(q[dyn.state((1, 2))]))
