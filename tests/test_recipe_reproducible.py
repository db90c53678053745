"""Recorded figures stay reproducible: a short fixed-seed run of the default `train --local` recipe
gives the numbers it gave before the option system, the configs and the Q-network variants were
reorganised (issue 42).

PINNED was first recorded by ``python -m tests.recipe_figures`` on commit a731e15 (main before issue
42's refactor) and held through it; it was re-recorded on 2026-12-06 (main 8bb1a09) when the default
recipe changed on purpose (issue 39: maps of every side 16-64, the action-local branch, the own-map
subgoal's clearance). CPU, torch's one intra-op thread, twice with identical output. A change that
moves code without changing what the default recipe computes leaves every figure as it is; one that
changes the recipe on purpose re-records them here with its commit.
"""

from __future__ import annotations

import pytest

from tests.recipe_figures import recipe_figures

PINNED = {
    "updates": 63,
    "selected_version": 63,
    "train_success": [0.0, 0.043478, 0.153846],
    "episode_return": [0.0, -1.1325, -0.7941],
    "td_loss": [0.0, 0.018575, 0.010524],
    "eval_success": [0.3125, 0.59375],
    "final_success": 0.75,
    "final_spl": 0.640852,
    "q_values": [
        [0.21299, 0.22024, 0.47355, 0.43641, 0.43616],
        [0.23308, 0.21374, 0.27311, 0.32517, 0.44937],
        [0.2143, 0.26354, 0.35735, 0.36752, 0.56795],
        [0.45593, 0.42991, 0.4023, 0.58041, 0.39057],
    ],
}


@pytest.mark.slow
def test_the_default_recipe_gives_the_recorded_figures(tmp_path):
    figures = recipe_figures(tmp_path / "run")
    q_values = figures.pop("q_values")
    pinned = dict(PINNED)
    flat = [q for row in pinned.pop("q_values") for q in row]
    assert [q for row in q_values for q in row] == pytest.approx(flat, abs=2e-5)
    assert figures == pinned
