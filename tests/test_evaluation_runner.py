"""Evaluation sets and the batched runner."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.evaluation.plots import plot_learning_curves, plot_paths
from agents.evaluation.runner import EvalSet, evaluate, make_eval_set
from worlds.outcomes import Outcome
from worlds.tasks import TRAIN_SEEDS


def test_eval_sets_are_fixed_and_held_out():
    a = make_eval_set("unseen", 6, seed=1)
    b = make_eval_set("unseen", 6, seed=1)
    assert [t.grid for t in a.tasks] == [t.grid for t in b.tasks]
    assert [(t.start, t.goal) for t in a.tasks] == [(t.start, t.goal) for t in b.tasks]
    assert a.seeds == b.seeds and a.obstacles.count == 0
    for task in a.tasks:  # map names end in their generator seed, above every training seed
        assert int(task.map_id.rsplit("-", 1)[1]) >= TRAIN_SEEDS
    other = make_eval_set("unseen", 6, seed=2)
    assert not {t.map_id for t in a.tasks} & {t.map_id for t in other.tasks}
    dynamic = make_eval_set("dynamic", 6, seed=1)
    assert [t.map_id for t in dynamic.tasks] == [t.map_id for t in a.tasks] and dynamic.obstacles.count > 0
    movingai = make_eval_set("movingai", 10, seed=0)
    assert len({(t.start, t.goal) for t in movingai.tasks}) == 10
    assert (movingai.shortest > 0).all()
    with pytest.raises(ValueError, match="unknown evaluation family"):
        make_eval_set("outdoor", 3)


def _forward_policy(obs: np.ndarray) -> np.ndarray:
    return np.full(len(obs), 2, dtype=np.int64)  # always straight ahead


def test_evaluate_records_consistent_episodes(tmp_path):
    sets = [make_eval_set("unseen", 5, seed=3), make_eval_set("dynamic", 5, seed=3)]
    result = evaluate(_forward_policy, sets, max_batch=3)  # two waves per family
    again = evaluate(_forward_policy, sets, max_batch=5)
    for family in ("unseen", "dynamic"):
        m = result.metrics[family]
        assert m.episodes == 5
        total = m.success.value + m.collision_static.value + m.collision_dynamic.value + m.timeout.value
        assert total == pytest.approx(1.0)
        for ep, other in zip(result.episodes[family], again.episodes[family], strict=True):
            assert ep.outcome != Outcome.RUNNING and ep.outcome == other.outcome  # batch size does not matter
            np.testing.assert_allclose(ep.trajectory, other.trajectory)
            assert len(ep.trajectory) == ep.steps + 1
            steps = np.hypot(*np.diff(ep.trajectory[:, :2], axis=0).T)
            assert ep.path_length == pytest.approx(steps.sum(), abs=1e-6)
            assert (
                0 < ep.min_clearance < 10
            )  # poses never overlap an obstacle (a collision stops the robot before)
    # driving straight ahead on maps bordered by walls mostly ends in a wall
    assert result.metrics["unseen"].collision_static.value >= 0.6
    json.dumps(result.to_dict(with_trajectories=True))
    assert "success" in result.table()
    assert plot_paths(result, "unseen", tmp_path / "unseen.png").stat().st_size > 0
    points = [(0, result.to_dict()["metrics"]), (1, again.to_dict()["metrics"])]
    assert plot_learning_curves(points, tmp_path / "curve.png").stat().st_size > 0


def test_single_set_is_accepted():
    es = make_eval_set("movingai", 2)
    assert isinstance(es, EvalSet)
    result = evaluate(_forward_policy, es)
    assert list(result.metrics) == ["movingai"]
