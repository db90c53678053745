"""NNQL actually learns: a tiny corridor map, trained in one process for a few seconds."""

from __future__ import annotations

import numpy as np
import pytest

from agents.nnql.config import NNQLConfig
from agents.nnql.rollout import VectorRollout
from agents.nnql.train_local import LocalTrainConfig, train_local
from worlds.config import NavConfig

CORRIDOR = """\
############
#..........#
#S........G#
#..........#
############
"""
GOAL = 1  # worlds.outcomes.Outcome.GOAL


def greedy_success(policy, maps: str, episodes: int = 64, seed: int = 123) -> float:
    from worlds.vector_env import NavigationVectorEnv

    env = NavigationVectorEnv(16, maps=maps, seed=seed)
    rollout = VectorRollout(env, policy.greedy())
    rollout.reset()
    ended = []
    for _ in range(10_000):
        ended += rollout.step()[1]
        if len(ended) >= episodes:
            break
    env.close()
    return float(np.mean([e.outcome == GOAL for e in ended[:episodes]]))


@pytest.mark.parametrize(
    "variant",
    [
        {},
        {"sarsa": True, "double_q": False, "prioritized": True},
        {"exploration": "epsilon", "epsilon_decay_updates": 300},
    ],
    ids=["double-dqn-boltzmann", "sarsa-prioritized", "epsilon-greedy"],
)
def test_nnql_learns_a_corridor(tmp_path, variant):
    corridor = tmp_path / "corridor.txt"
    corridor.write_text(CORRIDOR)
    nnql = NNQLConfig(
        hidden_sizes=(32, 32),
        batch_size=64,
        learning_starts=500,
        utd_ratio=0.125,
        temperature_start=0.2,
        temperature_end=0.01,
        temperature_decay_updates=400,
        network="mlp",  # the update rules under test, on the MLP alone
        **variant,
    )
    run = LocalTrainConfig(
        steps=4000,
        envs=8,
        maps=str(corridor),
        out=str(tmp_path / "out"),
        eval_every=0,
        final_eval_episodes=0,
        progress=False,
        moving_discs=0,
    )
    result = train_local(run, nnql, nav=NavConfig())  # the plain observation greedy_success steps
    assert result.updates == pytest.approx(0.125 * (4000 - 496), abs=20)
    assert greedy_success(result.learner.policy(), str(corridor)) >= 0.9
    # the outputs: a policy directory that loads back, the curve
    from agents.nnql.policy import NNQLPolicy

    loaded = NNQLPolicy.load(tmp_path / "out")
    assert loaded.version == result.updates
    assert (tmp_path / "out" / "curve.png").stat().st_size > 0
    assert len(result.curve) >= 2


def test_keep_best_saves_the_weights_that_validated_best(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import agents.nnql.train_local as train_local_module
    from agents.nnql.policy import NNQLPolicy

    corridor = tmp_path / "corridor.txt"
    corridor.write_text(CORRIDOR)
    scores = iter([0.2, 0.9, 0.5, 0.1])  # three periodic validations, then the final weights
    seen_versions = []

    def fake_evaluate(policy, episodes, seed, nav=None, dynamic=0, sizes=(16,)):
        seen_versions.append(policy.version)
        success = next(scores)
        rate = SimpleNamespace(value=success)
        return SimpleNamespace(metrics={"unseen": SimpleNamespace(success=rate, spl=success)})

    monkeypatch.setattr(train_local_module, "evaluate_policy", fake_evaluate)
    nnql = NNQLConfig(hidden_sizes=(8,), batch_size=32, learning_starts=200, utd_ratio=0.25)
    run = LocalTrainConfig(
        steps=1600,
        envs=8,
        maps=str(corridor),
        out=str(tmp_path / "out"),
        eval_every=400,
        final_eval_episodes=0,
        progress=False,
    )
    result = train_local(run, nnql)
    assert len(seen_versions) == 4 and len(set(seen_versions)) == 4
    assert result.selected_version == seen_versions[1]
    assert NNQLPolicy.load(tmp_path / "out").version == seen_versions[1]
    assert result.learner.version == seen_versions[3] != seen_versions[1]
