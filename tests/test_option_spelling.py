"""One option system: every training command's flags are config fields, spelled the same everywhere.

`up`, `learner`, `train` and `nirl train` (and the other services) build their flags from config
dataclasses with services.common.options; this lists each command's flags against the fields, so
a hand-written flag, or one option under two names (`--hidden` beside `--hidden-sizes`), fails here.
"""

from __future__ import annotations

import argparse

import pytest

from agents.imitation.config import ImitationConfig
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nnql.config import NNQLConfig
from agents.nnql.train_config import LocalTrainConfig, TrainObservation
from agents.tabular.config import TabularConfig
from services.actor.config import ActorConfig
from services.cli import build_parser
from services.common.options import option_fields
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


def flag_of(option) -> str:
    """An option's flag as written here: --<name with dashes>, unless its field renames it."""
    return (not option.parent and option.field.metadata.get("flag")) or "--" + option.name.replace("_", "-")


def field_flags(name: str) -> dict[str, str]:
    """flag -> option name of every option of the command's configs (a nested config's fields are
    options named <field>_<subfield>: NNQLConfig.local.window is --local-window)."""
    return {flag_of(o): o.name for cls in COMMANDS[name] for o in option_fields(cls)}


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
        for option in option_fields(cls):
            types.setdefault(option.name, set()).add(str(option.field.type).removesuffix(" | None"))
    assert {name: kinds for name, kinds in types.items() if len(kinds) > 1} == {}


def test_the_training_commands_share_the_nnql_options_and_the_old_spellings_are_gone():
    flags = {name: set(field_flags(name)) for name in COMMANDS}
    nnql = {flag_of(o) for o in option_fields(NNQLConfig)} - {"--seed"}
    refused = {flag_of(o) for o in option_fields(NNQLConfig) if (o.parent or o.name) in NNQL_REFUSED}
    assert {"--sarsa", "--patch-channels", "--patch-goal", "--patch-window"} <= refused
    for name in ("up", "learner", "train"):
        assert nnql <= flags[name]
    for option in (
        "--gamma",
        "--hidden-sizes",
        "--exploration",
        "--network",
        "--local-window",
        "--patch-size",
    ):
        assert option in flags["train"]
    # the Q-network variant and the action-local branch are spelled the same for NIRL
    assert {"--network", "--local-window", "--dueling", "--hidden-sizes"} <= flags["nirl train"]
    parsed = {
        option
        for name in ("up", "learner", "train", "nirl train", "imitate train")
        for action in command_parser(name)._actions
        for option in action.option_strings
    }
    old = {"--hidden", "--epsilon-greedy", "--patch", "--no-subgoal", "--keep-last", "--action-local"}
    # the patch CNN's flat --cnn-* flags are gone (--cnn-channels, -kernel-sizes, -strides now shape network
    # cnn, the image CNN: an old patch command is refused naming --network cnn, never silently re-read)
    assert not (old | {"--q-network", "--cnn-goal", "--cnn-embed"}) & parsed
    assert {"--cnn-channels", "--cnn-kernel-sizes", "--cnn-strides"} <= flags["up"] & flags["train"]
    for name in ("up", "learner"):  # refused in one sentence, not offered in --help
        assert all(flag not in command_parser(name).format_help() for flag in refused)
