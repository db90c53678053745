"""worlds.heuristics.subgoal_scores, the classical mapless planner of bench/map_sizes.py's
``follower`` row: turn towards the own map's subgoal (through the reading shield in the bench)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.shield import for_nav
from worlds.config import LEARNING_NAV, NavConfig
from worlds.heuristics import misalignment, subgoal_scores
from worlds.outcomes import Outcome
from worlds.perception import frame_layout

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


def test_the_best_score_turns_towards_the_subgoal():
    nav = LEARNING_NAV
    at = frame_layout(nav)["subgoal"][0]
    scores = subgoal_scores(nav)
    obs = np.zeros((3, 30), np.float32)
    for row, bearing in enumerate((0.0, math.pi / 2, -math.pi / 3)):
        obs[row, at : at + 3] = 0.5, math.sin(bearing), math.cos(bearing)
    best = scores(obs).argmax(axis=1)
    wanted = [int(np.argmin(np.abs(nav.robot.turns - b))) for b in (0.0, math.pi / 2, -math.pi / 3)]
    assert best.tolist() == wanted and wanted[1] == nav.robot.n_actions - 1


def test_an_observation_without_a_subgoal_is_refused():
    assert "subgoal" not in frame_layout(NavConfig())
    with pytest.raises(ValueError, match="no subgoal"):
        subgoal_scores(NavConfig())


def test_through_the_shield_it_reaches_goals_the_goal_bearing_alone_does_not():
    """On 40 validation episodes of 32-cell maps: following the own map's subgoal through the shield
    reaches the goal far more often than following the goal's bearing through the same shield
    (walls between the robot and its goal need a plan)."""
    nav = load_policy(PRETRAINED).nav_config(LEARNING_NAV)
    shield, scores = for_nav(nav), subgoal_scores(nav)
    goal_at = frame_layout(nav)["goal"][0]
    es = make_eval_set("unseen", 40, seed=1, size=32)

    def towards_goal(obs):
        bearing = np.arctan2(obs[:, goal_at + 1], obs[:, goal_at + 2])
        return shield.choose(-misalignment(bearing, nav.robot.turns), obs)

    goals = {}
    for name, policy in (("subgoal", lambda o: shield.choose(scores(o), o)), ("goal", towards_goal)):
        outcomes = np.array([e.outcome for e in evaluate(policy, es, nav).episodes["unseen"]])
        goals[name] = int((outcomes == int(Outcome.GOAL)).sum())
    assert goals["subgoal"] >= 36 and goals["subgoal"] >= goals["goal"] + 8, goals
