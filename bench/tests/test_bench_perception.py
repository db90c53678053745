"""bench/perception.py's report: one clone per distinct observation, path ratios on jointly solved
episodes, pooled figures of a run without SPL (the expert)."""

from __future__ import annotations

import pytest

from bench.perception import bc_variants, joint_path_ratios, pooled


def test_one_clone_per_distinct_observation_the_reward_and_the_learner_play_no_part():
    # B+geo observes as B, D+geo as D (geodesic reward), Fgea+geo as F (network options)
    got = bc_variants(["B+geo", "B", "D+geo", "D", "Fgea+geo", "F", "A"])
    assert got == {"BC:A": "A", "BC:B": "B", "BC:D": "D", "BC:F": "F"}
    assert bc_variants(["B+geo"]) == {"BC:B+geo": "B+geo"}  # B's observation, named as asked


def record(seed, solved, ratios, spl=0.5):
    sets = {"test": {"success": sum(solved) / len(solved), "spl": spl,
                     "per_family": {"rects": 0.0, "discs": 0.0, "rooms": 0.0}}}  # fmt: skip
    return {"seed": seed, "episodes": {"test": solved}, "path_ratios": {"test": ratios}, "sets": sets}


def test_path_ratio_on_the_episodes_every_learned_variant_of_the_seed_solved():
    runs = {
        "A": [
            record(0, [True, True, False, True], [1.2, 1.4, None, 1.0]),
            record(1, [True, False], [2.0, None]),
        ],
        "D": [
            record(0, [True, False, True, True], [1.1, None, 1.0, 1.3]),
            record(1, [True, True], [1.5, 1.1]),
        ],
        # a clone and the expert are not learned variants: they do not narrow the joint set
        "BC:A": [record(0, [False, False, False, False], [None] * 4)],
        "expert": [record(None, [True, True, True, True], [1.0] * 4, spl=None)],
    }
    joint_path_ratios(runs, "test")
    a0, d0 = runs["A"][0]["sets"]["test"], runs["D"][0]["sets"]["test"]
    assert a0["jointly_solved"] == d0["jointly_solved"] == 2  # episodes 0 and 3
    assert a0["path_ratio_joint"] == pytest.approx((1.2 + 1.0) / 2)
    assert d0["path_ratio_joint"] == pytest.approx((1.1 + 1.3) / 2)
    assert runs["D"][1]["sets"]["test"]["path_ratio_joint"] == pytest.approx(1.5)  # seed 1's own joint set
    assert "path_ratio_joint" not in runs["BC:A"][0]["sets"]["test"]
    assert pooled(runs["A"], "test")["path_ratio_joint"] == pytest.approx(((1.2 + 1.0) / 2 + 2.0) / 2)


def test_pooled_figures_of_a_run_without_spl():
    expert = record(None, [True, True, False, True], [1.0, 1.0, None, 1.0], spl=None)
    got = pooled([expert], "test")
    assert got["success"] == 0.75 and got["spl"] is None and got["path_ratio_joint"] is None
