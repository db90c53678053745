"""`navlearn nirl reward`: the learned reward over a map beside the geodesic cost."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner
from agents.nirl.reward_map import load_potential, observe_at
from services.cli import main
from worlds.config import NavConfig
from worlds.env import NavigationEnv
from worlds.maps import load_ascii_task

MAP = """\
##########
#S.......#
#........#
#...##...#
#...##...#
#........#
#.......G#
##########
"""


def test_reward_map_observations_are_the_worlds(tmp_path):
    path = tmp_path / "tiny.txt"
    path.write_text(MAP)
    base = NavConfig(pool_size=1)
    nav = replace(base, sensors=replace(base.sensors, noise_std=0.0))
    env = NavigationEnv(nav, maps=str(path))
    task = load_ascii_task(path)
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        x, y, theta = info["pose"]
        ours = observe_at(task, nav, np.array([x]), np.array([y]), np.array([theta]))[0]
        assert np.allclose(ours, obs, atol=1e-5), (ours, obs)


def test_nirl_reward_draws_a_runs_reward_beside_the_geodesic_cost(tmp_path, capsys):
    path = tmp_path / "tiny.txt"
    path.write_text(MAP)
    run = tmp_path / "run"
    learner = NIRLLearner(NIRLConfig(hidden_sizes=(16,), reward_hidden_sizes=(16,)))
    learner.save_policy(run)
    out = tmp_path / "reward.png"
    assert main(["nirl", "reward", "--run", str(run), "--map", str(path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert out.stat().st_size > 10_000 and "Spearman" in printed and "progress potential" in printed
    # the potential drawn is the learner's own: same values at the same observations
    obs = torch.as_tensor(np.random.default_rng(0).random((7, 11), dtype=np.float32))
    torch.testing.assert_close(load_potential(run)(obs), learner.fit.potential(obs))
    plain = tmp_path / "plain"
    config = NIRLConfig(hidden_sizes=(16,), reward_hidden_sizes=(16,), fixed_reward="network")
    NIRLLearner(config).save_policy(plain)
    assert load_potential(plain) is None  # no potential: the two-panel map, as before
    assert main(["nirl", "reward", "--run", str(plain), "--map", str(path), "--out", str(out)]) == 0
    assert "progress potential" not in capsys.readouterr().out
    assert main(["nirl", "reward", "--run", str(tmp_path), "--map", str(path)]) == 2
    assert main(["nirl", "reward", "--run", str(run), "--map", "nowhere:12"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and "reward.safetensors" in err
