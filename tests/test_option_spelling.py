"""One option system: every training command's flags are config fields, spelled the same everywhere.

`up`, `learner`, `train` and `nirl train` (and the other services) build their flags from config
dataclasses with services.common.options; this lists each command's flags against the fields, so
a hand-written flag, or one option under two names (`--hidden` beside `--hidden-sizes`), fails here.
"""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from agents.imitation.config import ImitationConfig
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nnql.config import NNQLConfig
from agents.nnql.train_config import LocalTrainConfig, TrainObservation
from agents.tabular.config import TabularConfig
from services.actor.config import ActorConfig
from services.cli import build_parser
from services.common.transport import ZenohSettings
from services.learner.config import NNQL_REFUSED, LearnerConfig
from services.ops.up_config import UpConfig
from worlds.own_env import EnvConfig

COMMANDS = {
    "up": (UpConfig, NNQLConfig, EnvConfig),
    "learner": (LearnerConfig, NNQLConfig, EnvConfig, ZenohSettings),
    "train": (LocalTrainConfig, TrainObservation, NNQLConfig, EnvConfig),
    "nirl train": (NIRLRun, NIRLConfig),
    "actor": (ActorConfig, EnvConfig, ZenohSettings),
    "imitate train": (ImitationConfig, EnvConfig),
    "tabular": (TabularConfig,),
}
"""each command and the configs its flags come from"""

HAND_WRITTEN = {
    "up": set(),
    "learner": {"--nnql-config", "--nirl-config", "--env-config", "--verbose"},
    "train": {"--local"},
    "nirl train": {"--demos", "--observation"},
    "actor": {"--env-config", "--verbose"},
    "imitate train": {"--demos", "--out", "--observation"},
    "tabular": {
        "--algo",
        "--map",
        "--start",
        "--goal",
        "--slip",
        "--connectivity",
        "--step-cost",
        "--collision-cost",
        "--exploring-starts",
        "--max-steps",
        "--every-visit",
        "--out",
    },
}
"""the flags that are not a config field, and only these: a config file, logging, a dataset"""

SKIPPED = {"up": {"seed"}, "train": {"seed"}}
"""fields a command sets itself (its run's seed seeds NNQL too)"""


def command_parser(name: str) -> argparse.ArgumentParser:
    parser = build_parser()
    for word in name.split():
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[word]
    return parser


def flag_of(field: dataclasses.Field) -> str:
    return field.metadata.get("flag") or "--" + field.name.replace("_", "-")


def field_flags(name: str) -> dict[str, str]:
    """flag -> field name of every field of the command's configs."""
    return {flag_of(f): f.name for cls in COMMANDS[name] for f in dataclasses.fields(cls)}


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_flag_is_a_config_field_or_named_here(name):
    flags = {
        option
        for action in command_parser(name)._actions
        for option in action.option_strings
        if option.startswith("--") and option != "--help" and not option.startswith("--no-")
    }
    fields = field_flags(name)
    skipped = {flag for flag, field in fields.items() if field in SKIPPED.get(name, set())}
    assert flags - set(fields) == HAND_WRITTEN[name]
    assert set(fields) - skipped <= flags


def test_one_field_one_flag_and_one_flag_one_field_across_the_commands():
    by_field: dict[str, set[str]] = {}
    by_flag: dict[str, set[str]] = {}
    for name in COMMANDS:
        for flag, field in field_flags(name).items():
            by_field.setdefault(field, set()).add(flag)
            by_flag.setdefault(flag, set()).add(field)
    assert {f: s for f, s in by_field.items() if len(s) > 1} == {}
    assert {f: s for f, s in by_flag.items() if len(s) > 1} == {}


def test_a_field_of_several_configs_has_one_type():
    """hidden_sizes, gamma, lr, seed, maps, envs, ...: the same name takes the same kind of value."""
    types: dict[str, set[str]] = {}
    for cls in {c for classes in COMMANDS.values() for c in classes}:
        for field in dataclasses.fields(cls):
            types.setdefault(field.name, set()).add(str(field.type).removesuffix(" | None"))
    assert {name: kinds for name, kinds in types.items() if len(kinds) > 1} == {}


def test_the_training_commands_share_the_nnql_options_and_the_old_spellings_are_gone():
    flags = {name: set(field_flags(name)) for name in COMMANDS}
    nnql = {flag_of(f) for f in dataclasses.fields(NNQLConfig)} - {"--seed"}
    refused = {flag_of(f) for f in dataclasses.fields(NNQLConfig) if f.name in NNQL_REFUSED}
    for name in ("up", "learner", "train"):
        assert nnql <= flags[name]
    for option in ("--gamma", "--hidden-sizes", "--exploration", "--action-local", "--patch-size"):
        assert option in flags["train"]
    parsed = {
        option
        for name in ("up", "learner", "train", "nirl train", "imitate train")
        for action in command_parser(name)._actions
        for option in action.option_strings
    }
    assert not {"--hidden", "--epsilon-greedy", "--patch", "--no-subgoal", "--keep-last"} & parsed
    for name in ("up", "learner"):  # refused in one sentence, not offered in --help
        assert all(flag not in command_parser(name).format_help() for flag in refused)
