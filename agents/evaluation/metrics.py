"""Navigation metrics as pure functions over per-episode arrays.

The figures are the ones the navigation literature reports (DESIGN.md,
"Evaluation"):

* outcome rates - success, collision with a static obstacle, collision with a
  moving obstacle, timeout - which add up to 1, each with a 95% Wilson score
  interval (Wilson 1927; it stays inside [0, 1] and behaves at 0 and n);
* SPL, success weighted by path length (Anderson et al., "On Evaluation of
  Embodied Navigation Agents", 2018): ``mean_i S_i * L_i / max(P_i, L_i)`` with
  ``L_i`` the shortest path length (grid A*, metres between the start and goal
  cell centres) and ``P_i`` the length the robot travelled;
* path-length ratio ``P_i / L_i`` and time to goal (steps), on successes only;
* minimum clearance: the smallest distance, over an episode, from the robot's
  centre to the surface of a blocked cell or the map border.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

from agents.planning.lattice import nearest_blocked_distance
from worlds.maps import GridMap, clearance
from worlds.outcomes import Outcome

Z_95 = 1.959963984540054

OUTCOME_KEYS: dict[str, Outcome] = {
    "success": Outcome.GOAL,
    "collision_static": Outcome.COLLISION_STATIC,
    "collision_dynamic": Outcome.COLLISION_DYNAMIC,
    "timeout": Outcome.TIMEOUT,
}


@dataclass(frozen=True)
class Rate:
    """A proportion ``count / n`` with its 95% Wilson score interval ``[low, high]``."""

    value: float
    low: float
    high: float
    count: int
    n: int

    def to_dict(self) -> dict[str, float | int]:
        return asdict(self)


def wilson_interval(count: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval for ``count`` successes out of ``n`` trials ((0, 1) when n = 0)."""
    if not 0 <= count <= n:
        raise ValueError(f"need 0 <= count <= n, got count={count}, n={n}")
    if n == 0:
        return 0.0, 1.0
    p = count / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = 0.0 if count == 0 else max(0.0, centre - half)  # exact bounds at the ends, no rounding
    high = 1.0 if count == n else min(1.0, centre + half)
    return low, high


def rate(count: int, n: int) -> Rate:
    low, high = wilson_interval(count, n)
    return Rate(count / n if n else 0.0, low, high, int(count), int(n))


def outcome_rates(outcomes: np.ndarray) -> dict[str, Rate]:
    """Rates of each final outcome (``worlds.outcomes.Outcome`` codes). Every episode
    must have ended, so the four rates add up to exactly 1."""
    outcomes = np.asarray(outcomes, dtype=np.int64)
    known = np.isin(outcomes, [int(o) for o in OUTCOME_KEYS.values()])
    if not known.all():
        raise ValueError(f"episodes without a final outcome: {sorted(set(outcomes[~known].tolist()))}")
    n = len(outcomes)
    return {key: rate(int((outcomes == code).sum()), n) for key, code in OUTCOME_KEYS.items()}


def _validated(success: np.ndarray, shortest: np.ndarray, taken: np.ndarray):
    success = np.asarray(success, dtype=bool)
    shortest = np.asarray(shortest, dtype=np.float64)
    taken = np.asarray(taken, dtype=np.float64)
    if not (success.shape == shortest.shape == taken.shape) or success.ndim != 1:
        raise ValueError("success, shortest and taken must be 1-D arrays of the same length")
    if not (np.isfinite(shortest).all() and (shortest > 0).all()):
        raise ValueError("shortest path lengths must be finite and positive (solvable tasks only)")
    if (taken < 0).any() or not np.isfinite(taken).all():
        raise ValueError("travelled path lengths must be finite and non-negative")
    return success, shortest, taken


def spl(success: np.ndarray, shortest: np.ndarray, taken: np.ndarray) -> float:
    """Success weighted by (normalised inverse) path length, in [0, 1]; 0 for no episodes."""
    success, shortest, taken = _validated(success, shortest, taken)
    if len(success) == 0:
        return 0.0
    return float(np.mean(success * shortest / np.maximum(taken, shortest)))


def path_ratio(success: np.ndarray, shortest: np.ndarray, taken: np.ndarray) -> float:
    """Mean of travelled / shortest over successful episodes (``nan`` when none succeeded)."""
    success, shortest, taken = _validated(success, shortest, taken)
    if not success.any():
        return math.nan
    return float(np.mean(taken[success] / shortest[success]))


def mean_on_success(values: np.ndarray, success: np.ndarray) -> float:
    """Mean of ``values`` over successful episodes (``nan`` when none succeeded); e.g. time to goal."""
    values = np.asarray(values, dtype=np.float64)
    success = np.asarray(success, dtype=bool)
    if values.shape != success.shape:
        raise ValueError("values and success must have the same shape")
    return float(values[success].mean()) if success.any() else math.nan


@njit(cache=True)
def _clearance_kernel(blocked, cell_size, xs, ys, bound):
    out = np.empty(xs.shape[0])
    for i in range(xs.shape[0]):
        out[i] = nearest_blocked_distance(blocked, cell_size, xs[i], ys[i], bound[i])
    return out


def point_clearance(grid: GridMap, xy: np.ndarray, cell_clearance: np.ndarray | None = None) -> np.ndarray:
    """Exact distance in metres from each point ``(x, y)`` (shape ``(n, 2)``) to the nearest
    blocked cell square or the map border; 0 inside a blocked cell.

    ``cell_clearance`` (``worlds.maps.clearance(grid)``) bounds the search window;
    pass it when calling many times on the same map."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if cell_clearance is None:
        cell_clearance = clearance(grid)
    rows = np.clip(np.floor(xy[:, 1] / grid.cell_size).astype(np.int64), 0, grid.height - 1)
    cols = np.clip(np.floor(xy[:, 0] / grid.cell_size).astype(np.int64), 0, grid.width - 1)
    bound = cell_clearance[rows, cols].astype(np.float64) + grid.cell_size
    return _clearance_kernel(grid.blocked, float(grid.cell_size), xy[:, 0].copy(), xy[:, 1].copy(), bound)


def json_fields(record: object) -> dict[str, object]:
    """A metrics dataclass's fields as JSON: each Rate as its dict, nan and infinity as None."""
    out: dict[str, object] = {}
    for key, value in record.__dict__.items():
        if isinstance(value, Rate):
            out[key] = value.to_dict()
        elif isinstance(value, float) and not math.isfinite(value):
            out[key] = None  # JSON has no nan
        else:
            out[key] = value
    return out


@dataclass(frozen=True)
class FamilyMetrics:
    """The evaluation figures for one map family (see the module docstring)."""

    episodes: int
    success: Rate
    collision_static: Rate
    collision_dynamic: Rate
    timeout: Rate
    spl: float
    path_ratio: float
    time_to_goal: float
    min_clearance_mean: float
    min_clearance_min: float

    def to_dict(self) -> dict[str, object]:
        return json_fields(self)


def summarize(
    outcomes: np.ndarray,
    shortest: np.ndarray,
    taken: np.ndarray,
    steps: np.ndarray,
    min_clearance: np.ndarray,
) -> FamilyMetrics:
    """All figures for one family from per-episode arrays: final outcome codes, A* length
    (m), travelled length (m), steps taken, and the episode's minimum clearance (m)."""
    rates = outcome_rates(outcomes)
    success = np.asarray(outcomes) == int(Outcome.GOAL)
    clear = np.asarray(min_clearance, dtype=np.float64)
    return FamilyMetrics(
        episodes=len(success),
        **rates,
        spl=spl(success, shortest, taken),
        path_ratio=path_ratio(success, shortest, taken),
        time_to_goal=mean_on_success(steps, success),
        min_clearance_mean=float(clear.mean()) if len(clear) else math.nan,
        min_clearance_min=float(clear.min()) if len(clear) else math.nan,
    )
