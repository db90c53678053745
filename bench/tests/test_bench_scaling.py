"""bench/scaling.py's reading of a learning curve: thresholds crossed by the success pooled over a
few evaluations, and the highest threshold every run reached."""

from __future__ import annotations

from bench.scaling import crossings, curve, highest_common, rejudge


def line(t: float, version: int, count: int, n: int = 100, model: str = "nnql") -> dict:
    success = {"value": count / n, "low": 0.0, "high": 1.0, "count": count, "n": n}
    return {"time": t, "policy_version": version, "model": model, "metrics": {"unseen": {"success": success}}}


def test_a_threshold_is_reached_when_the_pooled_success_reaches_it():
    counts = [
        (110, 1000, 42),
        (120, 1500, 65),
        (130, 2000, 71),
        (140, 3000, 69),
        (150, 3500, 81),
        (160, 4000, 70),
    ]
    lines = [line(t, v, c) for t, v, c in reversed(counts)]
    points = curve([*lines, line(105, 0, 99, model="reference")], "unseen")
    assert [p["version"] for p in points] == [
        1000,
        1500,
        2000,
        3000,
        3500,
        4000,
    ]  # report order, no reference
    single = crossings(points, start=100.0, thresholds=[0.6, 0.7, 0.8], window=1)
    assert (
        single["0.6"]["s"] == 20.0 and single["0.7"]["version"] == 2000 and single["0.8"]["version"] == 3500
    )
    hits = crossings(points, start=100.0, thresholds=[0.6, 0.7, 0.8], window=3)
    assert hits["0.6"]["s"] == 40.0 and hits["0.6"]["version"] == 3000  # 59% pooled at version 2000
    assert hits["0.7"]["version"] == 3500 and hits["0.7"]["success"] == round(221 / 300, 4)
    assert hits["0.7"]["low"] < 221 / 300 < hits["0.7"]["high"]
    assert hits["0.8"] is None  # one evaluation at 81% among 69-71% is not a policy at 80%


def test_highest_common_threshold_is_the_one_every_run_reached():
    reached = [{"0.6": {"s": 1}, "0.7": {"s": 2}, "0.8": None}, {"0.6": {"s": 3}, "0.7": None, "0.8": None}]
    runs = [{"reached": r} for r in reached]
    assert highest_common(runs, [0.6, 0.7, 0.8]) == 0.6
    assert highest_common(runs[1:], [0.7, 0.8]) is None


def test_a_curve_without_the_family_is_empty():
    assert curve([line(1, 10, 50)], "dynamic") == []


def test_a_recorded_output_is_judged_again_at_other_thresholds():
    curve_1 = [
        {"s": 10.0 * i, "version": 1000 * i, "success": x} for i, x in enumerate([0.0, 0.7, 0.74, 0.76, 0.75])
    ]
    curve_2 = [
        {"s": 5.0 * i, "version": 1000 * i, "success": x} for i, x in enumerate([0.0, 0.72, 0.78, 0.76, 0.74])
    ]
    recorded = {
        "settings": {"episodes": 500},
        "runs": [{"actors": 1, "curve": curve_1}, {"actors": 2, "curve": curve_2}],
    }
    again = rejudge(recorded, [0.7, 0.75], window=2)
    assert again["highest_common_threshold"] == 0.75
    # pooled (370 + 380) / 1000 and (360 + 390) / 1000
    assert again["to_common"] == [
        {"actors": 1, "s": 30.0, "updates": 3000},
        {"actors": 2, "s": 10.0, "updates": 2000},
    ]
    assert again["runs"][0]["reached"]["0.7"]["version"] == 2000  # 0.0 and 0.7 pool to 35%
