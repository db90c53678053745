"""The env options of the services that run one (actor, learner, evaluator): EnvConfig's flags, and
``--env-config FILE``, the EnvConfig itself as a JSON object of its fields. `navlearn up` writes its
run's EnvConfig to a file and gives its processes that file, so each reads the config the user gave,
not flags rebuilt from it and parsed again. Flags win over the file, the file over NAVLEARN_ENV*
variables (as ``--nnql-config`` does for NNQLConfig)."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from services.common.options import add_options, config_file, options_from_args
from worlds.own_env import ENV_TITLE, EnvConfig

ENV_PREFIX = "NAVLEARN_ENV"
ENV_CONFIG_FLAG = "--env-config"


def add_env_options(parser: argparse.ArgumentParser) -> None:
    """EnvConfig's flags and ``--env-config FILE`` in their --help group."""
    add_options(parser, EnvConfig, ENV_PREFIX, ENV_TITLE)
    parser.add_argument(
        ENV_CONFIG_FLAG,
        metavar="FILE",
        help="JSON object of the env's settings (worlds.own_env.EnvConfig fields: env, env_kwargs, "
        "env_module, env_vector; `navlearn up` writes its run's there): the flags above win over it, it "
        "wins over NAVLEARN_ENV* variables",
    )


def env_from_args(args: argparse.Namespace) -> EnvConfig:
    """The EnvConfig of parsed flags, ``--env-config``'s file and NAVLEARN_ENV* variables (ValueError,
    or its OptionError, naming a bad file or value)."""
    base = config_file(getattr(args, "env_config", None), EnvConfig)
    return options_from_args(EnvConfig, args, ENV_PREFIX, base=base)


def write_env_config(env: EnvConfig, path: str | Path) -> list[str]:
    """Write ``env`` to ``path`` as JSON; returns the flags that give a service that file."""
    Path(path).write_text(json.dumps(dataclasses.asdict(env), indent=1) + "\n")
    return [ENV_CONFIG_FLAG, str(path)]
