"""Evaluation metrics on hand-made cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.evaluation.metrics import (
    mean_on_success,
    outcome_rates,
    path_ratio,
    point_clearance,
    spl,
    summarize,
    wilson_interval,
)
from worlds.maps import GridMap
from worlds.outcomes import Outcome


def test_wilson_interval_known_values():
    assert wilson_interval(5, 10) == pytest.approx((0.236593, 0.763407), abs=1e-6)
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(3.8415 / 13.8415, abs=1e-4)
    low, high = wilson_interval(10, 10)
    assert high == 1.0 and low == pytest.approx(10 / 13.8415, abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError):
        wilson_interval(3, 2)


def test_outcome_rates_add_up_to_one():
    outcomes = (
        [Outcome.GOAL] * 6 + [Outcome.COLLISION_STATIC] * 2 + [Outcome.COLLISION_DYNAMIC, Outcome.TIMEOUT]
    )
    rates = outcome_rates(np.array(outcomes))
    assert rates["success"].value == 0.6 and rates["success"].count == 6
    assert rates["collision_static"].value == 0.2
    assert rates["collision_dynamic"].value == 0.1 and rates["timeout"].value == 0.1
    assert sum(r.value for r in rates.values()) == pytest.approx(1.0)
    assert rates["success"].low < 0.6 < rates["success"].high
    with pytest.raises(ValueError, match="final outcome"):
        outcome_rates(np.array([Outcome.GOAL, Outcome.RUNNING]))


def test_spl_and_path_ratio_by_hand():
    success = np.array([1, 1, 0, 1], dtype=bool)
    shortest = np.array([10.0, 10.0, 10.0, 5.0])
    taken = np.array([10.0, 20.0, 3.0, 4.0])
    # 1 + 10/20 + 0 + 5/max(4, 5) over 4 episodes
    assert spl(success, shortest, taken) == pytest.approx(2.5 / 4)
    assert path_ratio(success, shortest, taken) == pytest.approx((1.0 + 2.0 + 0.8) / 3)
    assert math.isnan(path_ratio(np.zeros(2, bool), np.ones(2), np.ones(2)))
    assert spl(np.zeros(0, bool), np.zeros(0), np.zeros(0)) == 0.0
    with pytest.raises(ValueError, match="shortest"):
        spl(success, np.array([10.0, 0.0, 1.0, 1.0]), taken)
    assert mean_on_success(np.array([7, 9, 100, 11]), success) == pytest.approx(9.0)


def test_point_clearance_by_hand_and_against_brute_force():
    blocked = np.zeros((5, 5), dtype=bool)
    blocked[2, 2] = True
    grid = GridMap(blocked)
    points = np.array([[0.5, 0.5], [1.5, 2.5], [1.5, 1.5], [2.5, 2.5]])
    assert point_clearance(grid, points) == pytest.approx([0.5, 0.5, math.sqrt(0.5), 0.0])

    rng = np.random.default_rng(0)
    grid = GridMap(rng.random((12, 15)) < 0.2, cell_size=0.5)
    pts = rng.uniform([0, 0], [15 * 0.5, 12 * 0.5], size=(200, 2))
    cells = np.argwhere(grid.blocked) * 0.5  # (row, col) corners in metres
    for (x, y), got in zip(pts, point_clearance(grid, pts), strict=True):
        dx = np.maximum.reduce([cells[:, 1] - x, np.zeros(len(cells)), x - cells[:, 1] - 0.5])
        dy = np.maximum.reduce([cells[:, 0] - y, np.zeros(len(cells)), y - cells[:, 0] - 0.5])
        border = min(x, y, 7.5 - x, 6.0 - y)
        assert got == pytest.approx(min(border, np.hypot(dx, dy).min()))


def test_summarize_is_json_ready():
    metrics = summarize(
        outcomes=np.array([Outcome.GOAL, Outcome.TIMEOUT]),
        shortest=np.array([4.0, 6.0]),
        taken=np.array([5.0, 9.0]),
        steps=np.array([20, 200]),
        min_clearance=np.array([0.4, 0.2]),
    )
    assert metrics.spl == pytest.approx(0.4)
    assert metrics.path_ratio == pytest.approx(1.25) and metrics.time_to_goal == 20
    assert metrics.min_clearance_min == pytest.approx(0.2)
    d = metrics.to_dict()
    assert d["success"]["value"] == 0.5 and d["episodes"] == 2
    none = summarize(np.array([Outcome.TIMEOUT]), np.ones(1), np.ones(1), np.ones(1), np.ones(1)).to_dict()
    assert none["path_ratio"] is None
