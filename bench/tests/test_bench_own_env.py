"""bench/own_env.py's same-robot-step budget: SB3 gets the robot-steps navlearn's run of the seed took."""

import json

import pytest

from bench.own_env import navlearn_budget


def write(folder, seed, row):
    path = folder / f"navlearn-s{seed}" / "result.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(row))


def test_the_budget_is_navlearns_steps_to_its_target_or_all_it_stepped(tmp_path):
    write(tmp_path, 0, {"to_target": {"steps": 249_000}, "robot_steps": 260_000})
    write(tmp_path, 1, {"to_target": None, "robot_steps": 1_014_144})
    assert navlearn_budget(tmp_path, 0) == 249_000
    assert navlearn_budget(tmp_path, 1) == 1_014_144


def test_a_missing_navlearn_run_is_one_line_naming_the_file_and_what_to_run(tmp_path):
    said = r"navlearn-s2/result.json is missing; run --systems navlearn for seed 2"
    with pytest.raises(SystemExit, match=said):
        navlearn_budget(tmp_path, 2)
