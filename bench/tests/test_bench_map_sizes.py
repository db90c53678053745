"""bench/map_sizes.py: the disc rule, and one tiny sweep whose last line is the JSON report; the policy
runs through its reading shield with the same network alone and the subgoal follower beside it,
paired (--no-shield: alone, and no follower)."""

from __future__ import annotations

import json

from bench.map_sizes import discs_for, eval_sets, main, named_set
from tests.conftest import ARENA_MAP


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
            assert set(rows) == {"policy", "network", "one_frame", "follower", "heuristic", "expert"}
            assert {rows[m]["episodes"] for m in ("policy", "network", "one_frame", "follower")} == {6}
            assert rows["expert"]["episodes"] == 3 and rows["network"]["paired"]["episodes"] == 6
            for row in rows.values():
                total = row["success"] + row["collision_static"] + row["collision_dynamic"] + row["timeout"]
                assert abs(total - 1) < 1e-9
            assert rows["expert"]["paired"]["episodes"] == 3
        assert report["throughput"][size]["robot_steps_per_cpu_s"] > 0
    assert (tmp_path / "map_sizes.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "map_sizes.json").read_text())["seed"] == 1
    assert report["shield"] is True


def test_no_shield_runs_the_network_alone(capsys):
    main(["--sizes", "16", "--episodes", "4", "--expert-episodes", "0", "--throughput-seconds", "0",
          "--no-shield"])  # fmt: skip
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report["shield"] is False
    assert set(report["results"]["16"]["static"]) == {"policy", "heuristic"}


def test_the_sweep_runs_in_the_worlds_default_step_rule(capsys):
    from worlds.config import NavConfig

    main(["--sizes", "16", "--episodes", "2", "--expert-episodes", "0", "--throughput-seconds", "0"])
    out = capsys.readouterr().out.strip().splitlines()
    report = json.loads(out[-1])
    assert (
        report["step_factor"] == NavConfig().step_factor > 0 and report["max_steps"] == NavConfig().max_steps
    )
    assert f"ceil({NavConfig().step_factor:g} x the A* path's steps)" in out[0]


def test_map_mode_gives_one_row_per_file_and_method_and_ends_with_its_json(tmp_path, capsys):
    """--map on a hand-drawn ASCII room and a map_server map: the policy, the heuristic and the expert on
    each file's own episodes; an unreadable file is one error naming it."""
    import numpy as np
    from PIL import Image

    room = ["#" * 14] + ["#" + "." * 12 + "#"] * 10 + ["#" * 14]
    (tmp_path / "room.txt").write_text("\n".join(room) + "\n")
    pixels = [[0 if c == "#" else 254 for c in row for _ in range(4)] for row in room for _ in range(4)]
    Image.fromarray(np.array(pixels, "uint8")).save(tmp_path / "lab.pgm")
    (tmp_path / "lab.yaml").write_text(
        "image: lab.pgm\nresolution: 0.25\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    files = [str(tmp_path / "room.txt"), str(tmp_path / "lab.yaml")]
    assert main(["--map", *files, "--episodes", "4", "--expert-episodes", "4", "--out", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    report = json.loads(lines[-1])
    assert list(report["maps"]) == files and "ceil(4 x" in report["step_rule"]
    for rows in report["maps"].values():
        assert {"policy", "network", "follower", "heuristic", "expert"} <= set(rows) and rows["note"]
        assert rows["policy"]["episodes"] == rows["expert"]["episodes"] == 4
        assert rows["expert"]["paired"]["episodes"] == 4
        solved = rows["policy"]["where_expert_succeeds"]
        assert solved["episodes"] == round(4 * rows["expert"]["success"])
    assert sum(line.startswith(("room ", "lab ")) for line in lines) >= 6
    assert json.loads((tmp_path / "maps.json").read_text())["maps"].keys() == report["maps"].keys()
    assert main(["--map", str(tmp_path / "missing.yaml"), "--episodes", "2"]) == 2
    assert "missing.yaml" in capsys.readouterr().err


def test_a_named_set_is_a_generated_size_or_a_map_file():
    static, dynamic = named_set("static:16", 3, seed=1), named_set("dynamic:48", 3, seed=1)
    assert (static.family, static.obstacles.count) == ("unseen", 0)
    assert (dynamic.family, dynamic.obstacles.count) == ("dynamic", discs_for(48))
    assert static.tasks[0].grid.shape == (16, 16) and dynamic.tasks[0].grid.shape == (48, 48)
    arena = named_set(str(ARENA_MAP), 2, seed=1)
    assert len(arena) == 2 and arena.tasks[0].grid.shape == (49, 49)
