"""Demonstrations on a user's Gymnasium env (issue 40 part 4): `navlearn demos record` writes a Minari
dataset with the env recorded (Minari's spec and navlearn's id + kwargs), loading it for another env is
refused naming both, `navlearn imitate train --env` clones it into a policy that plays the env, a
trained policy demonstrates in turn, and NIRL refuses it with the reason."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from agents.demos import DemoFormatError, dataset_location, datasets_root
from agents.env_demos import load_env_demos
from agents.evaluation.env_returns import evaluate_env
from agents.evaluation.policies import load_policy
from agents.nirl.buffers import load_demonstrations
from worlds.own_env import EnvConfig

REPO = Path(__file__).resolve().parents[1]
POLE = EnvConfig(env="CartPole-v1")
EXPERT = textwrap.dedent(
    '''
    def act(observation):
        """CartPole's textbook controller: push the way the pole leans and turns."""
        return int(observation[2] + 0.5 * observation[3] > 0)
    '''
)


def navlearn(tmp_path: Path, *argv: str) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *argv],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
        env=env,
    )


def test_demos_recorded_on_a_users_env_are_checked_cloned_and_refused_by_nirl(tmp_path: Path) -> None:
    import minari

    (tmp_path / "pole_expert.py").write_text(EXPERT)
    demos = tmp_path / "pole-v0"
    done = navlearn(tmp_path, "demos", "record", "--env", "CartPole-v1", "--expert", "pole_expert:act",
                    "--episodes", "6", "--out", str(demos))  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "6 episodes of CartPole-v1 by expert pole_expert:act" in done.stdout
    episodes = load_env_demos(demos, POLE)
    assert len(episodes) == 6 and all(len(e.observations) == len(e) + 1 for e in episodes)
    assert sum(len(e) for e in episodes) > 6 * 200  # the controller balances the pole
    root, dataset_id = dataset_location(demos)
    with datasets_root(root):
        assert minari.load_dataset(dataset_id).env_spec.id == "CartPole-v1"  # Minari's own record

    shorter = EnvConfig(env="CartPole-v1", env_kwargs='{"max_episode_steps": 50}')
    with pytest.raises(DemoFormatError, match=r"recorded on env CartPole-v1, but this learner runs env "
                                              r"CartPole-v1 \{\"max_episode_steps\": 50\}"):  # fmt: skip
        load_env_demos(demos, shorter)
    with pytest.raises(DemoFormatError, match="NIRL learns its reward from the world's features"):
        load_demonstrations(str(demos))

    policy = tmp_path / "cloned"
    done = navlearn(tmp_path, "imitate", "train", "--env", "CartPole-v1", "--demos", str(demos),
                    "--out", str(policy), "--hidden-sizes", "32", "--max-epochs", "60")  # fmt: skip
    assert done.returncode == 0, done.stderr
    cloned = load_policy(policy)
    assert cloned.env == POLE.record()
    played = evaluate_env(cloned, POLE, 10, seed=1)["CartPole-v1"]
    assert played["return"]["mean"] > 150, played  # a random policy averages about 22
    fifty = '{"max_episode_steps": 50}'
    wrong = navlearn(tmp_path, "imitate", "train", "--env", "CartPole-v1", "--env-kwargs", fifty,
                     "--demos", str(demos), "--out", str(tmp_path / "x"))  # fmt: skip
    assert wrong.returncode == 2 and "recorded on env CartPole-v1, but this learner runs env" in wrong.stderr

    again = tmp_path / "again-v0"
    done = navlearn(
        tmp_path, "demos", "record", "--policy", str(policy), "--episodes", "2", "--out", str(again)
    )
    assert done.returncode == 0, done.stderr
    assert len(load_env_demos(again, POLE)) == 2
    other = navlearn(tmp_path, "demos", "record", "--policy", str(policy), "--env", "CartPole-v1",
                     "--env-kwargs", fifty, "--out", str(tmp_path / "o-v0"))  # fmt: skip
    assert (
        other.returncode == 2 and "was trained on env CartPole-v1, not on --env CartPole-v1 {" in other.stderr
    )
    info = json.loads((policy / "config.json").read_text())
    assert info["env"] == POLE.record() and info["training"]["epochs"] <= 60
