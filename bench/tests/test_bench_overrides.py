"""The benches' ``KEY=VALUE`` overrides (bench/nirl.py --nirl, bench/perception.py --nnql / --rewards)."""

from __future__ import annotations

import argparse

import pytest

from agents.nirl.config import NIRLConfig
from agents.nnql.config import NNQLConfig
from bench._common import parse_overrides
from worlds.config import RewardConfig


def test_values_are_parsed_as_json_else_kept_as_strings():
    parser = argparse.ArgumentParser()
    got = parse_overrides(
        parser, ["n_step=3", "network=patch", "lr=5e-4", "activation=tanh"], NNQLConfig, "--nnql"
    )
    assert got == {"n_step": 3, "network": "patch", "lr": 5e-4, "activation": "tanh"}
    assert NNQLConfig(**got).n_step == 3
    assert parse_overrides(parser, ["collision=-3"], RewardConfig, "--rewards") == {"collision": -3}
    assert parse_overrides(parser, ["fix_reward_after=1"], NIRLConfig, "--nirl") == {"fix_reward_after": 1}


@pytest.mark.parametrize("item", ["nstep=3", "n_step", "=3"])
def test_an_unknown_or_malformed_key_is_a_usage_error_naming_the_option(item, capsys):
    with pytest.raises(SystemExit):
        parse_overrides(argparse.ArgumentParser(prog="perception.py"), [item], NNQLConfig, "--nnql")
    err = capsys.readouterr().err
    assert f"--nnql {item!r}" in err and "NNQLConfig field" in err
