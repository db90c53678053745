"""Paired comparison of two policies: exact McNemar, per-family split, path ratio on jointly
solved episodes, `navlearn evaluate --compare`, and the evaluation staying what it was."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from math import comb
from pathlib import Path

import numpy as np
import pytest

from agents.evaluation import HEADLINE_EPISODES, compare, evaluate, make_eval_set, mcnemar_exact
from agents.evaluation.compare import paired_row
from agents.evaluation.policies import load_policy, save_policy
from agents.evaluation.runner import EvalResult
from services.cli import main
from worlds.outcomes import Outcome

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


@pytest.mark.parametrize(
    ("a_only", "b_only", "expected"),
    [
        (0, 0, 1.0),  # no discordant pair: no evidence either way
        (3, 3, 1.0),
        (0, 5, 2 / 2**5),  # 2 * P(X = 0), X ~ Bin(5, 1/2)
        (5, 0, 2 / 2**5),
        (1, 9, 22 / 1024),  # 2 * (C(10,0) + C(10,1)) / 2^10
        (2, 8, 112 / 1024),  # 2 * (1 + 10 + 45) / 1024
        (4, 12, 5034 / 65536),  # 2 * (1 + 16 + 120 + 560 + 1820) / 2^16
        (29, 58, 2 * sum(comb(87, k) for k in range(30)) / 2**87),
    ],
)
def test_mcnemar_exact_matches_hand_computed_values(a_only, b_only, expected):
    assert mcnemar_exact(a_only, b_only) == pytest.approx(expected, rel=1e-9)


def test_mcnemar_exact_rejects_negative_counts():
    with pytest.raises(ValueError, match="a_only=-1"):
        mcnemar_exact(-1, 3)


def test_paired_row_counts_and_jointly_solved_path_ratio():
    a = np.array([1, 1, 0, 0, 1], bool)
    b = np.array([1, 0, 1, 0, 1], bool)
    shortest = np.array([2.0, 4.0, 5.0, 5.0, 10.0])
    taken_a = np.array([3.0, 4.0, 9.0, 9.0, 10.0])
    taken_b = np.array([2.0, 8.0, 5.0, 9.0, 12.0])
    row = paired_row(a, b, shortest, taken_a, taken_b)
    assert (row.episodes, row.both, row.a_only, row.b_only, row.neither) == (5, 2, 1, 1, 1)
    assert (row.success_a.count, row.success_b.count) == (3, 3) and row.p_value == 1.0
    # episodes 0 and 4 are jointly solved; A's perfect path on episode 1 (B failed) does not count
    assert row.path_ratio_a == pytest.approx((3 / 2 + 10 / 10) / 2)
    assert row.path_ratio_b == pytest.approx((2 / 2 + 12 / 10) / 2)
    assert row.spl_a == pytest.approx((2 / 3 + 1 + 1) / 5)  # SPL over every episode
    assert row.spl_b == pytest.approx((1 + 1 + 10 / 12) / 5)
    none = paired_row(a, ~a, shortest, taken_a, taken_b)
    assert np.isnan(none.path_ratio_a) and none.to_dict()["path_ratio_a"] is None
    with pytest.raises(ValueError, match="pair up"):
        paired_row(a, b[:4], shortest, taken_a, taken_b)


def _forward(obs: np.ndarray) -> np.ndarray:
    return np.full(len(obs), 2, dtype=np.int64)


def _with_outcomes(result: EvalResult, set_name: str, solved: list[bool]) -> EvalResult:
    """``result`` with the episodes of ``set_name`` marked solved or timed out."""
    episodes = [
        replace(e, outcome=int(Outcome.GOAL if s else Outcome.TIMEOUT))
        for e, s in zip(result.episodes[set_name], solved, strict=True)
    ]
    return EvalResult(metrics=dict(result.metrics), episodes={set_name: episodes})


def test_compare_splits_by_map_family():
    es = make_eval_set("unseen", 9, seed=5)  # families round robin: rects, discs, rooms, rects, ...
    assert es.map_families == ("rects", "discs", "rooms") * 3
    base = evaluate(_forward, es)
    assert [e.map_family for e in base.episodes["unseen"]] == list(es.map_families)
    assert all(e.task.map_id.startswith(e.map_family + "-") for e in base.episodes["unseen"])
    a = _with_outcomes(base, "unseen", [True, True, True, True, False, True, False, False, True])
    b = _with_outcomes(base, "unseen", [True, False, False, True, True, False, False, False, False])
    c = compare(a, b, names=("a", "b"))
    rows = c.rows["unseen"]
    assert list(rows) == ["all", "rects", "discs", "rooms"]
    # rects: episodes 0, 3, 6; discs: 1, 4, 7; rooms: 2, 5, 8
    cells = {f: (r.episodes, r.both, r.a_only, r.b_only, r.neither) for f, r in rows.items()}
    assert cells == {
        "all": (9, 2, 4, 1, 2),
        "rects": (3, 2, 0, 0, 1),
        "discs": (3, 0, 1, 1, 1),
        "rooms": (3, 0, 3, 0, 0),
    }
    assert rows["all"].p_value == pytest.approx(mcnemar_exact(4, 1))
    assert rows["rooms"].p_value == pytest.approx(0.25)
    report = c.to_dict()
    json.dumps(report)
    assert report["a"] == "a" and report["sets"]["unseen"]["rooms"]["a_only"] == 3
    table = c.table()
    assert "rooms" in table and "McNemar" in table
    same = compare(base, base)
    assert same.rows["unseen"]["all"].p_value == 1.0 and same.rows["unseen"]["all"].a_only == 0


def test_compare_refuses_unpaired_episodes():
    a = evaluate(_forward, make_eval_set("unseen", 3, seed=1))
    other_seed = evaluate(_forward, make_eval_set("unseen", 3, seed=2))
    with pytest.raises(ValueError, match="episode 0"):
        compare(a, other_seed)
    with pytest.raises(ValueError, match="3 episodes, B 2"):
        compare(a, evaluate(_forward, make_eval_set("unseen", 2, seed=1)))
    with pytest.raises(ValueError, match="not for B"):
        compare(a, evaluate(_forward, make_eval_set("dynamic", 3, seed=1)))


def test_waves_do_not_change_results():
    es = make_eval_set("dynamic", 7, seed=4)
    one, many = evaluate(_forward, es, max_batch=512), evaluate(_forward, es, max_batch=2)
    assert one.to_dict(with_trajectories=True) == many.to_dict(with_trajectories=True)


def test_shipped_evaluation_is_reproduced():
    """The shipped policy's recorded episodes come out the same (same seeds, same episode definition).
    If the episode definition changed on purpose, re-run
    ``navlearn evaluate --policy pretrained/nnql --out pretrained/nnql/eval``."""
    recorded = json.loads((PRETRAINED / "eval" / "eval.json").read_text())
    assert recorded["shield"] is True  # recorded as `navlearn evaluate` runs it by default
    recorded = recorded["episodes"]["unseen"][:30]
    policy = load_policy(PRETRAINED)
    policy.use_shield(policy.nav_config())
    result = evaluate(policy, make_eval_set("unseen", len(recorded), seed=0))
    keys = ("map_id", "start", "goal", "seed", "outcome", "path_length", "steps", "shortest")
    for old, new in zip(recorded, result.to_dict()["episodes"]["unseen"], strict=True):
        assert {k: old[k] for k in keys} == {k: new[k] for k in keys}


def _random_policy(path: Path) -> Path:
    rng = np.random.default_rng(3)
    sizes = [11, 8, 5]
    weights = {}
    for k, (i, o) in enumerate(itertools.pairwise(sizes)):
        weights[f"{2 * k}.weight"] = rng.normal(size=(o, i)).astype(np.float32)
        weights[f"{2 * k}.bias"] = rng.normal(size=o).astype(np.float32)
    arch = {"obs_dim": 11, "n_actions": 5, "hidden_sizes": [8], "activation": "relu"}
    return save_policy(path, weights, arch, model="random", kind="q_network", version=1)


def test_cli_compares_two_saved_policies(tmp_path, capsys):
    other = _random_policy(tmp_path / "random")
    argv = ["evaluate", "--compare", str(PRETRAINED), str(other), "--maps", "unseen", "--episodes", "6"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "McNemar" in printed and "rooms" in printed and "model='random'" in printed
    report = json.loads((tmp_path / "out" / "compare.json").read_text())
    rows = report["sets"]["unseen"]
    assert list(rows) == ["all", "rects", "discs", "rooms"] and rows["all"]["episodes"] == 6
    assert report["metrics"]["a"]["unseen"]["success"]["count"] == rows["all"]["success_a"]["count"]
    argv = ["evaluate", "--compare", str(other), "heuristic", "--maps", "dynamic", "--episodes", "3"]
    assert main(argv) == 0
    assert "B = heuristic" in capsys.readouterr().out


def test_cli_names_a_bad_policy_directory(tmp_path, capsys):
    missing = tmp_path / "no-such-policy"
    assert main(["evaluate", "--compare", str(PRETRAINED), str(missing), "--episodes", "2"]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "no such policy directory" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["evaluate", "--compare", str(empty), str(PRETRAINED), "--episodes", "2"]) == 2
    assert str(empty) in capsys.readouterr().err


def test_cli_help_shows_the_headline_default(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"default: {HEADLINE_EPISODES}," in text and "--compare DIR DIR" in text
