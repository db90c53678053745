"""bench/map_sizes.py: the disc rule, and one tiny sweep whose last line is the JSON report."""

from __future__ import annotations

import json

from bench.map_sizes import discs_for, eval_sets, main


def test_discs_follow_the_area_past_32_cells():
    assert [discs_for(s) for s in (16, 24, 32, 48, 64)] == [4, 4, 4, 9, 16]


def test_static_and_dynamic_sets_share_their_episodes():
    sets = eval_sets(24, 6, seed=1)
    assert sets["static"].tasks == sets["dynamic"].tasks and sets["static"].seeds == sets["dynamic"].seeds
    assert sets["static"].obstacles.count == 0 and sets["dynamic"].obstacles.count == 4
    assert all(t.grid.shape == (24, 24) for t in sets["static"].tasks)


def test_a_tiny_sweep_prints_every_method_and_ends_with_its_json(tmp_path, capsys):
    main(["--sizes", "16", "20", "--episodes", "6", "--expert-episodes", "3", "--seed", "1",
          "--throughput-seconds", "0.2", "--out", str(tmp_path)])  # fmt: skip
    lines = capsys.readouterr().out.strip().splitlines()
    report = json.loads(lines[-1])
    assert report["sizes"] == [16, 20] and report["max_steps"] > 0
    for size in ("16", "20"):
        for kind in ("static", "dynamic"):
            rows = report["results"][size][kind]
            assert set(rows) == {"policy", "heuristic", "expert"}
            assert rows["policy"]["episodes"] == 6 and rows["expert"]["episodes"] == 3
            for row in rows.values():
                total = row["success"] + row["collision_static"] + row["collision_dynamic"] + row["timeout"]
                assert abs(total - 1) < 1e-9
            assert rows["expert"]["paired"]["episodes"] == 3
        assert report["throughput"][size]["robot_steps_per_cpu_s"] > 0
    assert (tmp_path / "map_sizes.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "map_sizes.json").read_text())["seed"] == 1
