"""Keep-best's rule (agents.evaluation.selection.score) and the evaluator's keeper
(services.evaluator.keep_best): the best-scoring version's weights are saved, a worse later one is
not, a tie goes to the later one, and a restarted keeper competes with what it saved."""

from __future__ import annotations

import numpy as np
import pytest

from agents.evaluation.policies import load_policy
from agents.evaluation.selection import score
from protocols.messages import WeightsUpdate
from services.evaluator.keep_best import KeepBest, kept_record

ARCHITECTURE = {"obs_dim": 2, "n_actions": 2, "hidden_sizes": [], "activation": "relu"}


def env_metrics(mean: float, success: float | None = None, episodes: int = 10) -> dict:
    m = {"episodes": episodes, "return": {"mean": mean, "low": mean, "high": mean, "std": 0.0}, "length": 5.0}
    if success is not None:
        m["success"] = {"value": success, "low": 0.0, "high": 1.0}
    return {"Corridor": m}


def world_family(success: float, spl: float, episodes: int) -> dict:
    return {"episodes": episodes, "success": {"value": success, "low": 0.0, "high": 1.0}, "spl": spl}


def test_score_pools_families_by_episodes_and_uses_success_before_return() -> None:
    world = {"unseen": world_family(0.9, 0.8, 30), "dynamic": world_family(0.5, 0.4, 10)}
    assert score(world) == pytest.approx((0.8, 0.7))
    assert score({"unseen": world_family(0.0, float("nan"), 10)}) == (0.0, 0.0)  # no success: no SPL
    assert score(env_metrics(120.0)) == (120.0, 120.0)
    assert score(env_metrics(-3.0, success=0.7)) == (0.7, -3.0)
    assert score(env_metrics(-3.0, success=0.7)) > score(env_metrics(50.0, success=0.6))
    with pytest.raises(ValueError, match="no episodes"):
        score({})


def weights(version: int, bias: float) -> WeightsUpdate:
    tensors = {
        "0.weight": np.zeros((2, 2), np.float32),
        "0.bias": np.array([0.0, bias], np.float32),
    }
    return WeightsUpdate(sender="learner#1", seq=version, model="nnql", version=version, tensors=tensors,
                         architecture=ARCHITECTURE)  # fmt: skip


def test_the_keeper_saves_better_versions_only_ties_to_the_later_and_reloads_its_score(tmp_path) -> None:
    path = tmp_path / "best"
    env = {"id": "Corridor", "kwargs": {}, "module": ""}
    keeper = KeepBest(path, eval_seed=1, env=env)
    assert keeper.offer(weights(10, 1.0), env_metrics(5.0))
    assert keeper.offer(weights(20, -2.0), env_metrics(8.0))  # its greedy action: 0
    assert not keeper.offer(weights(30, 3.0), env_metrics(7.9))  # the last is worse: 20 stays
    record = kept_record(path)
    assert record["version"] == 20 and record["score"] == [8.0, 8.0] and record["eval_seed"] == 1
    saved = load_policy(path)
    assert saved.version == 20 and saved.env == env
    np.testing.assert_array_equal(saved(np.zeros((3, 2), np.float32)), [0, 0, 0])  # version 20's weights
    again = KeepBest(path, eval_seed=1, env=env)  # a restarted evaluator of the same run
    assert again.best == (8.0, 8.0) and again.version == 20
    assert not again.offer(weights(40, 4.0), env_metrics(6.0))
    assert again.offer(weights(50, 5.0), env_metrics(8.0))  # a tie: the later version
    assert kept_record(path)["version"] == 50
    np.testing.assert_array_equal(load_policy(path)(np.zeros((3, 2), np.float32)), [1, 1, 1])
    assert kept_record(tmp_path / "none") is None
