"""The shipped policy's recipe is the default of every trainer: a dueling head, the action-local branch
(window 3), 0..6 moving discs per training episode and maps of every side from 16 to 64 cells
(`navlearn train --local`, the actors and learner of `navlearn up`)."""

from __future__ import annotations

import json

from agents.nnql.config import LocalConfig, NNQLConfig
from agents.nnql.networks import DuelingQNetwork
from agents.nnql.patch_network import PatchQNetwork
from agents.nnql.q_networks import build_q_network
from agents.nnql.train_local import LocalTrainConfig
from services.actor.config import ActorConfig
from services.cli import build_parser, main
from services.common.options import config_file, options_from_args
from services.learner.config import LearnerConfig, learner_network
from services.ops.up_config import UpConfig
from worlds.config import (
    TRAINING_DISCS,
    TRAINING_MAPS,
    NavConfig,
    ObservationConfig,
    SensorConfig,
    observation_settings,
)
from worlds.own_env import EnvConfig
from worlds.perception import observation_dim


def test_every_trainer_defaults_to_the_disc_mix_and_the_dueling_head():
    assert TRAINING_DISCS == 6  # the dynamic test set's crowd of 4, and denser ones
    assert LocalTrainConfig().moving_discs == ActorConfig().moving_discs == UpConfig().moving_discs == 6
    assert NNQLConfig().dueling
    assert TRAINING_MAPS == "mixed:16-64"
    assert LocalTrainConfig().maps == ActorConfig().maps == UpConfig().maps == TRAINING_MAPS
    assert LocalTrainConfig().eval_sizes == (16, 32, 48, 64)
    assert isinstance(build_q_network(NNQLConfig(), 30, 5), DuelingQNetwork)  # no navlearn observation
    assert NNQLConfig().network == "auto" and LocalConfig().window == 3


def up_learner_config(tmp_path, *flags: str) -> NNQLConfig:
    """The NNQLConfig the learner of `navlearn up <flags>` trains: up builds it from its flags, hands it
    over as a file (services.ops.up), and the learner reads it and builds its network on the actors'
    observation (as services.commands.learner and services.learner.run do)."""
    args = build_parser().parse_args(["up", *flags])
    up = options_from_args(UpConfig, args, "NAVLEARN_UP")
    nnql = options_from_args(NNQLConfig, args, "NAVLEARN_NNQL", seed=up.seed)
    path = tmp_path / "nnql.json"
    path.write_text(json.dumps(nnql.to_dict()))
    learner_args = build_parser().parse_args(
        ["learner", "--nnql-config", str(path), "--observation", up.observation]
    )
    learner = options_from_args(LearnerConfig, learner_args, "NAVLEARN_LEARNER")
    given = options_from_args(
        NNQLConfig, learner_args, "NAVLEARN_NNQL", base=config_file(str(path), NNQLConfig)
    )
    return learner_network(given, learner.observation, EnvConfig())


def test_up_with_no_flags_trains_the_recipe_train_local_trains(tmp_path):
    """One default: the learner under `navlearn up` builds the action-local branch (window 3) with the
    dueling head, as `navlearn train --local` does (below), and its actors' maps are 16-64 cells."""
    nnql = up_learner_config(tmp_path)
    assert nnql.network == "local" and nnql.local.window == 3 and nnql.dueling
    assert UpConfig().maps == TRAINING_MAPS == "mixed:16-64"
    summary, _ = train(tmp_path)
    assert {**summary["nnql"], "seed": nnql.seed} == nnql.to_dict()  # the same config, seed aside
    assert up_learner_config(tmp_path, "--network", "mlp").network == "mlp"
    assert up_learner_config(tmp_path, "--local-window", "2").local.window == 2


def test_networks_without_a_dueling_head_take_the_default_config():
    """The patch-CNN Q-network keeps a plain head; the default config must not refuse it."""
    nav = NavConfig(sensors=SensorConfig(n_beams=8, n_rays=16), observation=ObservationConfig(patch_size=16))
    net = build_q_network(NNQLConfig(), observation_dim(nav), 5, observation_settings(nav))
    assert isinstance(net, PatchQNetwork)  # network auto: the patch CNN on an observation with a patch


def train(tmp_path, *flags: str) -> tuple[dict, dict]:
    out = tmp_path / "run"
    argv = ["train", "--local", "--steps", "300", "--envs", "4", "--eval-every", "0"]
    assert main([*argv, "--final-eval-episodes", "0", "--no-progress", "--out", str(out), *flags]) == 0
    return json.loads((out / "summary.json").read_text()), json.loads((out / "config.json").read_text())


def test_train_local_uses_the_recipe_by_default_and_the_flags_turn_it_off(tmp_path):
    summary, policy = train(tmp_path)
    assert summary["run"]["moving_discs"] == TRAINING_DISCS and summary["nnql"]["dueling"] is True
    assert summary["run"]["maps"] == TRAINING_MAPS and summary["run"]["eval_sizes"] == [16, 32, 48, 64]
    assert summary["nnql"]["network"] == "local" and summary["nnql"]["local"]["window"] == 3
    assert policy["architecture"]["local"]["window"] == 3 and policy["nnql_config"]["network"] == "local"
    assert policy["architecture"]["dueling"] is True
    summary, policy = train(tmp_path, "--no-dueling", "--moving-discs", "0")
    assert summary["run"]["moving_discs"] == 0 and summary["nnql"]["dueling"] is False
    assert "dueling" not in policy["architecture"]
