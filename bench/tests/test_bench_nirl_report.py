"""bench/nirl.py --report: NIRL paired with every learner from the same demonstrations (behaviour
cloning, SQIL, DQfD) on the same episodes, and the targets read from the comparison with BC."""

from __future__ import annotations

import json

from bench._nirl_report import report


def _row(method: str, set_name: str, seed: int, unseen: list[int], dynamic: list[int]) -> dict:
    test = {family: {"success": sum(s) / len(s), "success_ci": [0.0, 1.0], "solved": s,
                     "collision_static": 0.0}
            for family, s in (("unseen", unseen), ("dynamic", dynamic))}  # fmt: skip
    return {"method": method, "set": set_name, "seed": seed, "episodes": len(unseen), "env_steps": 1,
            "nav": "learning_plan", "test": test}  # fmt: skip


def test_nirl_is_paired_with_bc_and_dqfd_and_the_target_reads_bc(tmp_path, capsys):
    nirl = [1] * 8 + [0, 0]
    rows = [
        _row("nirl", "20noisy", 0, nirl, nirl),
        _row("bc", "20noisy", 0, [0] * 6 + [1] * 2 + [0, 0], [0] * 10),  # NIRL alone solves 6
        _row("dqfd", "20noisy", 0, [1] * 7 + [0, 0, 1], [1] * 10),  # 1 / 1, then 0 / 2 with discs
    ]
    runs = tmp_path / "runs.jsonl"
    runs.write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert report(runs) == 0
    out = capsys.readouterr().out
    summary = json.loads(out.splitlines()[-1])
    bc, dqfd = summary["nirl_vs_bc"]["20noisy/unseen"], summary["nirl_vs_dqfd"]["20noisy/unseen"]
    assert (bc["only_nirl"], bc["only_bc"], bc["n"]) == (6, 0, 10)
    assert (dqfd["only_nirl"], dqfd["only_dqfd"]) == (1, 1) and dqfd["p"] == 1.0
    assert summary["nirl_vs_dqfd"]["20noisy/dynamic"]["only_dqfd"] == 2
    assert summary["nirl_vs_sqil"] == {}
    assert summary["targets"]["nirl_minus_bc_noisy_unseen_ge_0.10"] == 0.8 - 0.2  # BC's, not the last paired
    assert "McNemar NIRL vs DQFD, 20noisy demos, unseen: 80.0% vs 80.0%" in out
