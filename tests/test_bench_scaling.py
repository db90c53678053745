"""bench/scaling.py's reading of a learning curve: thresholds crossed, and the highest every run reached."""

from __future__ import annotations

from bench.scaling import crossings, curve, highest_common


def line(t: float, version: int, success: float, model: str = "nnql") -> dict:
    metrics = {"unseen": {"success": {"value": success, "low": success - 0.04, "high": success + 0.04}}}
    return {"time": t, "policy_version": version, "model": model, "metrics": metrics}


def test_first_evaluation_at_or_above_each_threshold_counts_from_the_start():
    lines = [line(110, 1000, 0.42), line(130, 2000, 0.71), line(120, 1500, 0.65), line(140, 3000, 0.69)]
    points = curve([*lines, line(105, 0, 0.99, model="reference")], "unseen")
    assert [p["version"] for p in points] == [1000, 1500, 2000, 3000]  # report order; reference dropped
    hits = crossings(points, start=100.0, thresholds=[0.6, 0.7, 0.8])
    assert hits["0.6"]["s"] == 20.0 and hits["0.6"]["version"] == 1500
    assert hits["0.7"]["s"] == 30.0 and hits["0.7"]["success"] == 0.71
    assert hits["0.8"] is None


def test_highest_common_threshold_is_the_one_every_run_reached():
    reached = [{"0.6": {"s": 1}, "0.7": {"s": 2}, "0.8": None}, {"0.6": {"s": 3}, "0.7": None, "0.8": None}]
    runs = [{"reached": r} for r in reached]
    assert highest_common(runs, [0.6, 0.7, 0.8]) == 0.6
    assert highest_common(runs[1:], [0.7, 0.8]) is None


def test_a_curve_without_the_family_is_empty():
    assert curve([line(1, 10, 0.5)], "dynamic") == []
