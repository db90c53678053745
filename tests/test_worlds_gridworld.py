"""GridWorldEnv and GridDynamics: gymnasium checks, determinism, corner rule, and the env's
sampled transitions against the sparse MDP built from the same dynamics."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from agents.mdp import grid_mdp
from worlds.gridworld import ENV_ID, MOVE_NAMES, GridDynamics, GridWorldConfig, GridWorldEnv
from worlds.maps import load_movingai, parse_ascii


def test_registered_env_passes_check_env():
    env = gym.make(ENV_ID, render_mode="ansi")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and info["cell"] == (1, 1)
    assert env.action_space.n == 8
    assert "R" in env.render()
    env.close()


def test_same_seed_same_episode():
    def rollout(seed: int) -> list:
        env = GridWorldEnv(start=None, max_steps=30)
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        out = [obs]
        for _ in range(30):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            out.append((obs, reward))
            if terminated or truncated:
                break
        return out

    assert rollout(3) == rollout(3)
    assert rollout(3) != rollout(4)


def test_blocked_moves_and_corner_rule():
    grid, markers = parse_ascii("S#.\n...\n..G\n")
    dyn = GridDynamics.build(grid, markers["G"], GridWorldConfig(collision_cost=3.0, step_cost=2.0))
    s = dyn.state((0, 0))
    east, south, south_east = MOVE_NAMES.index("E"), MOVE_NAMES.index("S"), MOVE_NAMES.index("SE")
    assert dyn.successor[s, east] == s and dyn.collision[s, east] and dyn.reward[s, east] == -3.0
    assert dyn.cell(int(dyn.successor[s, south])) == (1, 0) and dyn.reward[s, south] == -2.0
    assert dyn.successor[s, south_east] == s  # would cut the blocked corner at (0, 1)
    middle = dyn.state((1, 1))
    assert dyn.cell(int(dyn.successor[middle, south_east])) == (2, 2)
    assert dyn.reward[middle, south_east] == pytest.approx(-2.0 * math.sqrt(2))
    goal = dyn.goal_state
    assert (dyn.successor[goal] == goal).all() and (dyn.reward[goal] == 0).all()
    np.testing.assert_allclose(dyn.outcome_prob.sum(axis=1), 1.0)
    assert dyn.outcome_prob[0, 0] == pytest.approx(0.9) and dyn.outcome_prob[0, 1] == pytest.approx(0.1 / 7)


def test_states_are_the_cells_that_reach_the_goal():
    grid, markers = parse_ascii("S.#.\n..#.\n.G#.\n")
    dyn = GridDynamics.build(grid, markers["G"])
    assert dyn.n_states == 6
    with pytest.raises(ValueError, match="cannot reach the goal"):
        dyn.state((0, 3))
    with pytest.raises(ValueError, match="blocked"):
        GridDynamics.build(grid, (0, 2))


def test_env_transitions_match_the_sparse_mdp():
    env = GridWorldEnv(config=GridWorldConfig(slip=0.3))
    _, mdp = grid_mdp(env.dynamics.grid, env.dynamics.goal, env.dynamics.config)
    cell = (3, 4)
    s = env.dynamics.state(cell)
    n = 20000
    for action in (MOVE_NAMES.index("E"), MOVE_NAMES.index("NW")):
        counts = np.zeros(env.dynamics.n_states)
        total_reward = 0.0
        env.reset(seed=1)
        for _ in range(n):
            env.reset(options={"start": cell})
            obs, reward, *_ = env.step(action)
            counts[obs] += 1
            total_reward += reward
        expected = mdp.transitions[action][[s]].toarray().ravel()
        assert np.abs(counts / n - expected).max() < 0.015
        assert total_reward / n == pytest.approx(mdp.rewards[s, action], abs=0.06)


def test_episode_ends_at_goal_or_max_steps():
    grid, markers = parse_ascii("S.G\n")
    env = GridWorldEnv(
        grid, markers["G"], markers["S"], GridWorldConfig(connectivity=4, slip=0.0), max_steps=5
    )
    env.reset(seed=0)
    east = MOVE_NAMES.index("E")
    assert env.step(east)[2:4] == (False, False)
    _, reward, terminated, truncated, info = env.step(east)
    assert terminated and not truncated and info["cell"] == (0, 2) and reward == -1.0
    env.reset()
    west = MOVE_NAMES.index("W")
    results = [env.step(west) for _ in range(5)]
    assert all(r[4]["collision"] for r in results)
    assert results[-1][3] and not results[-1][2]
    with pytest.raises(ValueError, match=r"action must be in 0\.\.3"):
        env.step(4)


def test_arena_dynamics_build(arena_paths):
    grid = load_movingai(arena_paths[0])
    dyn = GridDynamics.build(grid, (46, 47))
    assert dyn.n_states == 2054 and dyn.successor.shape == (2054, 8)
    assert (dyn.successor >= 0).all() and (dyn.successor < dyn.n_states).all()


def test_importing_worlds_registers_both_envs():
    import subprocess
    import sys

    code = (
        "import gymnasium as gym, sys, worlds\n"
        "assert 'worlds.gridworld' not in sys.modules\n"
        "assert {'navlearn/Navigation-v0', 'navlearn/GridWorld-v0'} <= set(gym.registry)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
