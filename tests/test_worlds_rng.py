"""Per-robot random streams of the kernel (worlds.rng)."""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import stats

from worlds.rng import gauss, randint, seed_state, uniform


@njit(cache=True)
def _draw(seed, n, kind):
    state = np.array([seed], dtype=np.uint64)
    out = np.empty(n)
    for k in range(n):
        out[k] = gauss(state, 0) if kind == 0 else (uniform(state, 0) if kind == 1 else randint(state, 0, 7))
    return out


def test_gaussian_draws_are_standard_normal():
    x = _draw(np.uint64(12345), 400_000, 0)
    assert abs(x.mean()) < 0.01 and abs(x.std() - 1) < 0.01
    assert abs(stats.skew(x)) < 0.02 and abs(stats.kurtosis(x)) < 0.05
    assert stats.kstest(x, "norm").pvalue > 1e-3
    tail = np.mean(np.abs(x) > 3.5)  # the ziggurat's tail branch
    assert abs(tail - 2 * stats.norm.sf(3.5)) < 1.5e-4


def test_uniform_and_integer_draws():
    u = _draw(np.uint64(7), 200_000, 1)
    assert u.min() >= 0 and u.max() < 1 and stats.kstest(u, "uniform").pvalue > 1e-3
    k = _draw(np.uint64(7), 70_000, 2)
    assert set(np.unique(k)) == set(range(7))
    assert stats.chisquare(np.bincount(k.astype(int))).pvalue > 1e-3


def test_streams_are_seeded():
    a = _draw(seed_state(np.random.default_rng(1)), 10, 0)
    b = _draw(seed_state(np.random.default_rng(1)), 10, 0)
    c = _draw(seed_state(np.random.default_rng(2)), 10, 0)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
