"""Shared parts of the tabular learners (thesis ch. 2.4): config, schedules,
exploration, sampling from the grid world's dynamics, results.

The learners run whole episodes in compiled code against the arrays of
``worlds.gridworld.GridDynamics`` (the same arrays ``GridWorldEnv.step`` uses),
so a learner given a ``GridWorldEnv`` learns exactly that env's MDP, at
millions of steps per second. Episodes start at the env's start cell, or at a
uniformly random non-goal state when the env has none (exploring starts), and
are cut after the env's ``max_steps``. Randomness comes from numba's generator,
seeded from ``config.seed``, so a run is reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from agents.tabular.config import StepSizeConfig, TabularConfig
from worlds.gridworld import GridDynamics, GridWorldEnv

Progress = Callable[[int], None]
"""Called with the number of episodes finished so far."""


@dataclass(frozen=True)
class TabularResult:
    """Learned action values and the learning curve."""

    q: np.ndarray
    """``(S, A)`` action values."""
    returns: np.ndarray
    """Undiscounted return of each episode."""
    lengths: np.ndarray
    """Steps of each episode."""

    @property
    def policy(self) -> np.ndarray:
        return np.argmax(self.q, axis=1)

    @property
    def values(self) -> np.ndarray:
        return self.q.max(axis=1)


def exploration_schedule(config: TabularConfig) -> np.ndarray:
    """Epsilon or temperature of every episode: geometric decay, then constant."""
    n = config.episodes
    decay = max(1, round(config.explore_decay * n))
    t = np.minimum(np.arange(n) / decay, 1.0)
    return config.explore_start * (config.explore_end / config.explore_start) ** t


def grid_dynamics(env: GridWorldEnv) -> tuple[GridDynamics, int, int]:
    """``(dynamics, start state or -1 for exploring starts, max_steps)`` of a (wrapped) GridWorldEnv."""
    base = getattr(env, "unwrapped", env)
    if not isinstance(base, GridWorldEnv):
        raise TypeError(
            f"the tabular learners need a worlds.gridworld.GridWorldEnv, got {type(base).__name__}"
        )
    start = -1 if base.start_state is None else base.start_state
    return base.dynamics, start, base.max_steps


def run_in_chunks(run: Callable[[int, int], None], episodes: int, progress: Progress | None) -> None:
    """Call ``run(first, last)`` over consecutive episode ranges, reporting progress between them."""
    chunk = episodes if progress is None else max(1, math.ceil(episodes / 100))
    for first in range(0, episodes, chunk):
        last = min(episodes, first + chunk)
        run(first, last)
        if progress is not None:
            progress(last)


def run_episodes(
    episodes_kernel: Callable[..., None],
    grid: tuple[GridDynamics, int, int],
    table: np.ndarray,
    config: StepSizeConfig,
    progress: Progress | None,
    chunk_args: Callable[[int, int], tuple],
) -> tuple[np.ndarray, np.ndarray]:
    """Drive a compiled episode kernel over ``config.episodes`` episodes in chunks, with progress, and
    return each episode's (undiscounted return, steps). Every tabular kernel (TD(0) prediction,
    Q-learning, SARSA, Monte Carlo) takes ``(table, visits, successor, reward, cum_prob, goal, start,
    max_steps, gamma, alpha, by_visits, power, *chunk_args(first, last), returns, lengths, first)``:
    ``table`` is what it learns (V or Q, updated in place), ``visits`` counts its entries' updates,
    ``grid`` is :func:`grid_dynamics`'s, and numba's generator is seeded from ``config.seed``."""
    dyn, start, max_steps = grid
    visits = np.zeros(table.shape, dtype=np.int64)
    cum_prob = np.cumsum(dyn.outcome_prob, axis=1)
    returns = np.zeros(config.episodes)
    lengths = np.zeros(config.episodes, dtype=np.int64)
    seed_numba(config.seed)

    def run(first: int, last: int) -> None:
        episodes_kernel(
            table,
            visits,
            dyn.successor,
            dyn.reward,
            cum_prob,
            dyn.goal_state,
            start,
            max_steps,
            config.gamma,
            config.alpha,
            config.alpha_schedule == "visits",
            config.alpha_power,
            *chunk_args(first, last),
            returns,
            lengths,
            first,
        )

    run_in_chunks(run, config.episodes, progress)
    return returns, lengths


def run_control(
    episodes_kernel: Callable[..., None],
    env: GridWorldEnv,
    config: TabularConfig,
    progress: Progress | None,
    *extra: object,
) -> TabularResult:
    """Learn Q with a compiled control episode kernel (Q-learning, SARSA, Monte Carlo) by
    :func:`run_episodes`: its chunk arguments are the exploration (Boltzmann or not, each episode's
    epsilon or temperature), then ``extra`` (Monte Carlo's first-visit flag, SARSA's on-policy one)."""
    grid = grid_dynamics(env)
    q = np.zeros((grid[0].n_states, grid[0].n_actions))
    params = exploration_schedule(config)
    boltzmann = config.exploration == "boltzmann"
    returns, lengths = run_episodes(
        episodes_kernel,
        grid,
        q,
        config,
        progress,
        lambda first, last: (boltzmann, params[first:last], *extra),
    )
    return TabularResult(q, returns, lengths)


@njit(cache=True)
def seed_numba(seed: int) -> None:
    """Seed numba's generator (separate from numpy's)."""
    np.random.seed(seed)


@njit(cache=True)
def start_state(start: int, n_states: int, goal: int) -> int:
    if start >= 0:
        return start
    draw = np.random.randint(n_states - 1)
    return draw + 1 if draw >= goal else draw


@njit(cache=True)
def greedy(q_row) -> int:
    """Argmax with ties broken uniformly at random."""
    best = q_row.max()
    count = 0
    for a in range(q_row.shape[0]):
        if q_row[a] == best:
            count += 1
    pick = np.random.randint(count)
    for a in range(q_row.shape[0]):
        if q_row[a] == best:
            if pick == 0:
                return a
            pick -= 1
    return 0


@njit(cache=True)
def explore(q_row, boltzmann: bool, param: float) -> int:
    """Epsilon-greedy (``param`` = epsilon) or Boltzmann (``param`` = temperature) action."""
    n = q_row.shape[0]
    if not boltzmann:
        if np.random.random() < param:
            return np.random.randint(n)
        return greedy(q_row)
    weights = np.exp((q_row - q_row.max()) / param)
    u = np.random.random() * weights.sum()
    acc = 0.0
    for a in range(n):
        acc += weights[a]
        if u < acc:
            return a
    return n - 1


@njit(cache=True)
def sample_index(cum_row) -> int:
    """Draw an index from a cumulative distribution."""
    u = np.random.random() * cum_row[-1]
    for a in range(cum_row.shape[0]):
        if u < cum_row[a]:
            return a
    return cum_row.shape[0] - 1


@njit(cache=True)
def step_size(alpha: float, by_visits: bool, power: float, visits: int) -> float:
    return alpha / visits**power if by_visits else alpha
