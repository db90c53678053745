"""The robot given its map (`navlearn evaluate --known-map`, ``GreedyMLPPolicy.use_known_map``): the
shipped policy's subgoal planned on the true map instead of its own, through the real CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from agents.evaluation.policies import load_policy, save_policy
from services.cli import main
from tests.test_evaluation_policies import ARCH, _weights
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


def test_a_known_map_changes_the_subgoals_map_and_nothing_else(tmp_path):
    policy = load_policy(PRETRAINED)
    own = policy.nav_config(LEARNING_NAV)
    known = policy.use_known_map().nav_config(LEARNING_NAV)
    assert (own.observation.subgoal, known.observation.subgoal) == ("own_map", "known_map")
    assert replace(known.observation, subgoal="own_map") == own.observation
    assert observation_dim(known) == policy.obs_dim and "known map" in repr(policy)
    policy.use_shield(known)  # the shield takes the policy in its new observation
    # a policy that plans no subgoal (saved before observation records: 8 beams and the goal)
    save_policy(tmp_path / "old", _weights(np.random.default_rng(0)), ARCH, model="nnql", kind="q_network")
    with pytest.raises(ValueError, match=r"subgoal='none'.*observation\.subgoal='own_map'"):
        load_policy(tmp_path / "old").use_known_map()
    assert main(["evaluate", "--policy", str(tmp_path / "old"), "--known-map", "--episodes", "2"]) == 2
    assert main(["evaluate", "--policy", "heuristic", "--known-map", "--episodes", "2"]) == 2


def test_evaluate_with_the_known_map_drives_shorter_paths_on_the_same_episodes(tmp_path, capsys):
    """32-cell validation maps: given the map, the robot stops exploring rooms that turn out closed,
    so on the same episodes it drives a shorter way (SPL up) and reaches the goal as often."""
    argv = ["evaluate", "--policy", str(PRETRAINED), "--maps", "unseen", "--size", "32", "--seed", "1"]
    argv += ["--episodes", "40"]
    assert main([*argv, "--out", str(tmp_path / "own")]) == 0
    assert "known map" not in capsys.readouterr().out
    assert main([*argv, "--known-map", "--out", str(tmp_path / "known")]) == 0
    assert "known map" in capsys.readouterr().out
    own, known = (json.loads((tmp_path / d / "eval.json").read_text()) for d in ("own", "known"))
    assert (own["known_map"], known["known_map"]) == (False, True)
    pairs = [(e["start"], e["goal"]) for e in own["episodes"]["unseen"]]
    assert pairs == [(e["start"], e["goal"]) for e in known["episodes"]["unseen"]]
    m_own, m_known = own["metrics"]["unseen"], known["metrics"]["unseen"]
    assert m_known["success"]["count"] >= m_own["success"]["count"] - 1
    assert m_known["spl"] > m_own["spl"] + 0.02, (m_own["spl"], m_known["spl"])


def test_world_show_draws_a_run_given_the_map(tmp_path, capsys):
    png = tmp_path / "known.png"
    argv = ["world", "show", "--policy", str(PRETRAINED), "--map", "rooms:24", "--known-map"]
    assert main([*argv, "--out", str(png)]) == 0 and png.stat().st_size > 10_000
    assert "policy" in capsys.readouterr().out
    assert main(["world", "show", "--known-map", "--out", str(tmp_path / "none.png")]) == 2
    assert "--known-map needs a subgoal to plan" in capsys.readouterr().err
    heuristic = ["world", "show", "--policy", "heuristic", "--known-map"]
    assert main([*heuristic, "--out", str(tmp_path / "h.png")]) == 2
    assert "the heuristic plans none" in capsys.readouterr().err
