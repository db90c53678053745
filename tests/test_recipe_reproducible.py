"""Recorded figures stay reproducible: a short fixed-seed run of the default `train --local` recipe
gives the numbers it gave before the option system, the configs and the Q-network variants were
reorganised (issue 42).

PINNED was first recorded by ``python -m tests.recipe_figures`` on commit a731e15 (main before issue
42's refactor) and held through it; it was re-recorded on 2026-12-06 (main 8bb1a09) when the default
recipe changed on purpose (issue 39: maps of every side 16-64, the action-local branch, the own-map
subgoal's clearance), and again on 2026-12-06 (b383bdc) when the own map stopped clearing the wall
cell a ray hit (a bug fix that changes what the robot maps at 1 m cells too, in rare cases: the run
before it, 269dc86, still gives the previous figures), and again on 2026-12-07 (3cb1791) when the own
map's plan started preferring cells the robot has seen (``subgoal_prefers_seen`` in LEARNING_NAV,
docs/navigation-by-size.md section 12). CPU, torch's one intra-op thread, twice with identical output.
A change that moves code without changing what the default recipe computes leaves every figure as it
is; one that changes the recipe on purpose re-records them here with its commit.
"""

from __future__ import annotations

import pytest

from tests.recipe_figures import recipe_figures

PINNED = {
    "updates": 63,
    "selected_version": 63,
    "train_success": [0.0, 0.0, 0.058824],
    "episode_return": [0.0, -1.0915, -0.9174],
    "td_loss": [0.0, 0.017157, 0.006422],
    "eval_success": [0.34375, 0.59375],
    "final_success": 0.375,
    "final_spl": 0.3194,
    "q_values": [
        [0.19065, 0.28409, 0.51712, 0.43728, 0.43105],
        [0.22359, 0.2863, 0.36887, 0.32191, 0.44989],
        [0.20295, 0.30561, 0.39731, 0.35294, 0.55325],
        [0.44708, 0.46578, 0.38933, 0.5887, 0.36693],
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
