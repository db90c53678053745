"""Per-robot random streams for the compiled kernel (splitmix64, Steele et al. 2014).

Each robot owns one 64-bit state, so a robot's draws never depend on how many other
robots share the batch: robot ``i`` of a vector env seeded ``s`` sees exactly the
stream of a single env seeded ``s + i``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0


def seed_state(np_random: np.random.Generator) -> np.uint64:
    """A stream state drawn from a gymnasium ``np_random`` generator."""
    return np.uint64(np_random.integers(0, 2**63, dtype=np.int64))


@njit(cache=True, inline="always")
def next_u64(state, i):
    z = state[i] + _GOLDEN
    state[i] = z
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@njit(cache=True, inline="always")
def uniform(state, i) -> float:
    """Uniform in [0, 1)."""
    return float(next_u64(state, i) >> _S11) * _INV53


@njit(cache=True, inline="always")
def randint(state, i, n) -> int:
    """Uniform integer in [0, n)."""
    return min(int(uniform(state, i) * n), n - 1)


@njit(cache=True, inline="always")
def gauss(state, i) -> float:
    """Standard normal (Box-Muller, one value per two uniforms)."""
    u1 = 1.0 - uniform(state, i)
    u2 = uniform(state, i)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
