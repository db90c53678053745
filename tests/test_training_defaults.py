"""The shipped policy's recipe is the default of every trainer: a dueling head, 0..6 moving discs
per training episode and maps of every side from 16 to 64 cells (`navlearn train --local`, the actors
and learner of `navlearn up`)."""

from __future__ import annotations

import json

from agents.nnql.config import NNQLConfig
from agents.nnql.networks import DuelingQNetwork
from agents.nnql.patch_network import PatchQNetwork
from agents.nnql.q_networks import build_q_network
from agents.nnql.train_local import LocalTrainConfig
from services.actor.config import ActorConfig
from services.cli import main
from services.ops.up_config import UpConfig
from worlds.config import TRAINING_DISCS, NavConfig, ObservationConfig, SensorConfig, observation_settings
from worlds.perception import observation_dim
from worlds.tasks import TRAINING_MAPS


def test_every_trainer_defaults_to_the_disc_mix_and_the_dueling_head():
    assert TRAINING_DISCS == 6  # the dynamic test set's crowd of 4, and denser ones
    assert LocalTrainConfig().moving_discs == ActorConfig().moving_discs == UpConfig().moving_discs == 6
    assert NNQLConfig().dueling
    assert TRAINING_MAPS == "mixed:16-64"
    assert LocalTrainConfig().maps == ActorConfig().maps == UpConfig().maps == TRAINING_MAPS
    assert LocalTrainConfig().eval_sizes == (16, 32, 48, 64)
    assert isinstance(build_q_network(NNQLConfig(), 30, 5), DuelingQNetwork)


def test_networks_without_a_dueling_head_take_the_default_config():
    """The patch-CNN Q-network keeps a plain head; the default config must not refuse it."""
    nav = NavConfig(sensors=SensorConfig(n_beams=8, n_rays=16), observation=ObservationConfig(patch_size=16))
    net = build_q_network(NNQLConfig(), observation_dim(nav), 5, observation_settings(nav))
    assert isinstance(net, PatchQNetwork)


def train(tmp_path, *flags: str) -> tuple[dict, dict]:
    out = tmp_path / "run"
    argv = ["train", "--local", "--steps", "300", "--envs", "4", "--eval-every", "0"]
    assert main([*argv, "--final-eval-episodes", "0", "--no-progress", "--out", str(out), *flags]) == 0
    return json.loads((out / "summary.json").read_text()), json.loads((out / "config.json").read_text())


def test_train_local_uses_the_recipe_by_default_and_the_flags_turn_it_off(tmp_path):
    summary, policy = train(tmp_path)
    assert summary["run"]["moving_discs"] == TRAINING_DISCS and summary["nnql"]["dueling"] is True
    assert summary["run"]["maps"] == TRAINING_MAPS and summary["run"]["eval_sizes"] == [16, 32, 48, 64]
    assert summary["nnql"]["action_local"] == 3 and policy["architecture"]["local"]["window"] == 3
    assert policy["architecture"]["dueling"] is True
    summary, policy = train(tmp_path, "--no-dueling", "--moving-discs", "0")
    assert summary["run"]["moving_discs"] == 0 and summary["nnql"]["dueling"] is False
    assert "dueling" not in policy["architecture"]
