"""Demonstrations carry their observation: recorded in the learner's (LEARNING_NAV by default) while
the expert drives, stored with the dataset, checked by `nirl train`, `imitate train` and `up --nirl`
with one error naming the file and the field; old 8-beam sets still load in their own observation."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from gymnasium import spaces

from agents.demo_observation import dataset_observation, load_demos_for
from agents.demos import DemoFormatError, write_demos
from agents.nirl.buffers import load_demonstrations
from agents.planning.demonstrate import generate_demos
from services.cli import main
from worlds.config import (
    LEARNING_NAV,
    LEARNING_PLAN_NAV,
    LEGACY_OBSERVATION,
    OBSERVATIONS,
    NavConfig,
    observation_settings,
)
from worlds.env import NavigationEnv, observation_space
from worlds.perception import observation_dim


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """A LEARNING_NAV set (recorded settings) and an old-style 8-beam set (no record)."""
    root = tmp_path_factory.mktemp("demos")
    learning, _ = generate_demos("rooms:10", 3, seed=3, config=LEARNING_NAV)
    new = write_demos(root / "learning-v0", learning, observation_space(LEARNING_NAV), spaces.Discrete(5),
                      observation=observation_settings(LEARNING_NAV))  # fmt: skip
    plain, _ = generate_demos("rooms:10", 3, seed=3, config=NavConfig())
    old = write_demos(root / "plain-v0", plain, observation_space(NavConfig()), spaces.Discrete(5))
    return {"learning": (new, learning), "plain": (old, plain)}


def test_recorded_observation_is_the_robots_own_along_the_expert_trajectory(datasets):
    path, demos = datasets["learning"]
    assert dataset_observation(path) == (observation_settings(LEARNING_NAV), observation_dim(LEARNING_NAV))
    loaded = load_demos_for(path, LEARNING_NAV)
    env = NavigationEnv(LEARNING_NAV, maps="rooms:10")
    for demo, back in zip(demos, loaded, strict=True):
        np.testing.assert_array_equal(back.observations, demo.observations)
        # the own-map subgoal depends on the path driven: replaying the recorded actions from the
        # same reset gives exactly the recorded observations, subgoal columns included
        obs, _ = env.reset(seed=demo.metadata["seed"])
        replayed = [obs]
        for action in demo.actions:
            obs, *_ = env.step(int(action))
            replayed.append(obs)
        np.testing.assert_allclose(np.asarray(replayed), demo.observations, atol=1e-6)
        assert demo.observations.shape[1] == observation_dim(LEARNING_NAV) != observation_dim(NavConfig())


def test_old_8_beam_sets_load_in_their_own_observation(datasets):
    path, demos = datasets["plain"]
    assert dataset_observation(path) == (LEGACY_OBSERVATION, 11)
    assert len(load_demos_for(path, OBSERVATIONS["plain"])) == len(demos)
    assert len(load_demonstrations(str(path), OBSERVATIONS["plain"])) == len(demos)


@pytest.mark.parametrize(
    "which, nav, field",
    [
        ("plain", LEARNING_NAV, re.escape("sensors.n_beams=8")),
        ("learning", OBSERVATIONS["plain"], re.escape("observation.subgoal='own_map'")),
    ],
)
def test_a_mismatch_is_one_error_naming_the_file_and_field(datasets, which, nav, field):
    path, _ = datasets[which]
    for load in (load_demos_for, load_demonstrations):
        with pytest.raises(DemoFormatError, match=field) as info:
            load(str(path), nav)
        assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_learners_default_to_learning_nav_and_refuse_other_observations(datasets, tmp_path, capsys):
    from services.ops.up_config import UpConfig, check_nirl

    old, _ = datasets["plain"]
    new, _ = datasets["learning"]
    for argv in (["nirl", "train", "--no-progress"], ["imitate", "train"]):
        assert main([*argv, "--demos", str(old), "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and old.name in err and "sensors.n_beams=8" in err, err
    with pytest.raises(ValueError, match=re.escape("sensors.n_beams=8")):
        check_nirl(UpConfig(nirl=True, demos=str(old)))
    check_nirl(UpConfig(nirl=True, demos=str(new)))
    # behaviour cloning in either observation, the saved policy records the one it was trained in
    for name, path, nav in (("learning", new, LEARNING_NAV), ("plain", old, OBSERVATIONS["plain"])):
        out = tmp_path / f"bc-{name}"
        argv = [
            "imitate",
            "train",
            "--demos",
            str(path),
            "--out",
            str(out),
            "--max-epochs",
            "2",
            "--hidden-sizes",
            "8",
        ]
        assert main([*argv, "--observation", name]) == 0
        saved = json.loads((out / "config.json").read_text())
        assert saved["observation"] == observation_settings(nav)
        assert saved["architecture"]["obs_dim"] == observation_dim(nav)


def test_a_learning_plan_set_loads_for_learning_learners_exactly_without_the_plan_length(datasets, tmp_path):
    """What `navlearn demos generate` records by default (learning_plan, NIRL's) loads for behaviour
    cloning's and NNQL's learning observation with the plan length dropped: step for step what a
    learning recording of the same episodes holds; the other way round is refused."""
    path, learning = datasets["learning"]
    planned, _ = generate_demos("rooms:10", 3, seed=3, config=LEARNING_PLAN_NAV)
    space, settings = observation_space(LEARNING_PLAN_NAV), observation_settings(LEARNING_PLAN_NAV)
    planned_path = write_demos(
        tmp_path / "planned-v0", planned, space, spaces.Discrete(5), observation=settings
    )
    loaded = load_demos_for(planned_path, LEARNING_NAV)
    for back, want, full in zip(loaded, learning, planned, strict=True):
        np.testing.assert_array_equal(back.actions, want.actions)
        np.testing.assert_allclose(back.observations, want.observations, atol=1e-6)
        assert full.observations.shape[1] == back.observations.shape[1] + 1
    assert len(load_demos_for(planned_path, LEARNING_PLAN_NAV)) == len(planned)
    with pytest.raises(DemoFormatError, match=re.escape("observation.plan_length=False")):
        load_demos_for(path, LEARNING_PLAN_NAV)
