"""Map files through the real CLI: evaluate --map on a map_server map, a MovingAI map with its
scenarios and an ASCII map; world show --map; train --local --maps; demos generate --maps."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from services.cli import main
from tests.test_worlds_mapfiles import write_pgm, write_yaml

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


def office(tmp_path: Path) -> Path:
    """A 6 m x 4 m map_server office at 0.05 m: outer walls, a wall with a 1 m door, a pillar."""
    pixels = np.full((80, 120), 254, dtype=np.uint8)
    pixels[:2, :] = pixels[-2:, :] = pixels[:, :2] = pixels[:, -2:] = 0
    pixels[:, 60:62] = 0
    pixels[30:50, 60:62] = 254  # the door
    pixels[20:26, 90:96] = 0  # a pillar
    write_pgm(tmp_path / "office.pgm", pixels.tolist())
    return write_yaml(tmp_path, image="office.pgm", name="office.yaml", origin=[-3.0, -2.0, 0.0])


def movingai(tmp_path: Path) -> Path:
    rows = ["@" * 20] + ["@" + "." * 18 + "@"] * 18 + ["@" * 20]
    rows[9] = "@" + "." * 8 + "TT" + "S" * 8 + "@"  # trees block, swamp passes
    path = tmp_path / "hall.map"
    path.write_text("type octile\nheight 20\nwidth 20\nmap\n" + "\n".join(rows) + "\n")
    scen = "version 1\n" + "".join(f"0\thall.map\t20\t20\t2\t{y}\t17\t{y}\t15\n" for y in (2, 5, 14))
    (tmp_path / "hall.map.scen").write_text(scen)
    return path


def test_evaluate_on_three_map_formats(tmp_path, capsys):
    ascii_map = tmp_path / "lab.txt"
    ascii_map.write_text("\n".join(["#" * 14] + ["#" + "." * 12 + "#"] * 8 + ["#" * 14]) + "\n")
    argv = ["evaluate", "--policy", str(PRETRAINED), "--episodes", "3", "--out", str(tmp_path / "eval")]
    for path in (office(tmp_path), movingai(tmp_path), ascii_map):
        argv += ["--map", str(path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "office.yaml: 120x80 pixels of 0.05 m -> 60x40 cells of 0.1 m" in out
    assert "hall.map: 20x20 cells of 1 m (MovingAI, not resampled), 3 scenarios" in out
    report = json.loads((tmp_path / "eval" / "eval.json").read_text())
    assert set(report["metrics"]) == {"office", "hall", "lab"}
    hall = report["episodes"]["hall"]
    assert sorted((e["start"], e["goal"]) for e in hall) == [([y, 2], [y, 17]) for y in (2, 5, 14)]
    # pairs are at least 2 m apart through cells the robot fits on; the grid A* may hug walls closer
    assert all(1.0 < e["shortest"] < 8.0 for e in report["episodes"]["office"])


def test_pairs_drawn_replaces_a_files_own_scenarios(tmp_path, capsys):
    hall = movingai(tmp_path)
    argv = ["evaluate", "--policy", "heuristic", "--map", str(hall), "--episodes", "12"]
    assert main([*argv, "--out", str(tmp_path / "own")]) == 0
    said = "".join(capsys.readouterr())
    assert "3 scenarios from hall.map.scen" in said and "pairs=drawn" not in said
    own = json.loads((tmp_path / "own" / "eval.json").read_text())["episodes"]["hall"]
    scen = {((y, 2), (y, 17)) for y in (2, 5, 14)}
    assert len(own) == 12 and {(tuple(e["start"]), tuple(e["goal"])) for e in own} == scen  # repeated
    assert main([*argv, "--pairs", "drawn", "--out", str(tmp_path / "drawn")]) == 0
    assert "3 scenarios from hall.map.scen; not used: pairs=drawn" in "".join(capsys.readouterr())
    drawn = json.loads((tmp_path / "drawn" / "eval.json").read_text())["episodes"]["hall"]
    pairs = {(tuple(e["start"]), tuple(e["goal"])) for e in drawn}
    assert len(drawn) == 12 and len(pairs) >= 10 and not pairs <= scen
    assert all(e["shortest"] >= 2.0 for e in drawn)
    capsys.readouterr()
    assert main([*argv, "--pairs", "some", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "pairs='some'" in err and "own, drawn" in err and "Traceback" not in err


def test_evaluate_for_a_smaller_robot(tmp_path, capsys):
    """--robot-radius reads the map scaled for the world's robot, says so, and runs on it."""
    out_dir = tmp_path / "eval"
    argv = ["evaluate", "--policy", str(PRETRAINED), "--map", str(office(tmp_path)), "--episodes", "4"]
    assert main([*argv, "--robot-radius", "0.1", "--out", str(out_dir)]) == 0
    out = capsys.readouterr().out
    assert "office.yaml: 120x80 pixels of 0.05 m -> 120x80 cells of 0.125 m" in out
    assert "scaled x2.5 for a robot of radius 0.1 m" in out
    report = json.loads((out_dir / "eval.json").read_text())
    assert len(report["episodes"]["office"]) == 4
    assert main([*argv, "--robot-radius", "0"]) == 2
    assert "radius=0.0 must be > 0" in capsys.readouterr().err


def test_map_errors_are_one_line(tmp_path, capsys):
    bad = write_yaml(tmp_path, image="missing.pgm")
    assert main(["evaluate", "--policy", str(PRETRAINED), "--map", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "m.yaml" in err and "field 'image'" in err
    unknown = ["evaluate", "--policy", "heuristic", "--map", str(office(tmp_path)), "--unknown", "maybe"]
    assert main(unknown) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown='maybe'" in err and "blocked, free" in err


def test_world_show_draws_a_map_file(tmp_path, capsys):
    out = tmp_path / "office.png"
    argv = [
        "world",
        "show",
        "--map",
        f"{office(tmp_path)},unknown=free",
        "--out",
        str(out),
        "--obstacles",
        "0",
    ]
    assert main([*argv, "--policy", str(PRETRAINED)]) == 0
    printed = capsys.readouterr().out
    assert "cells of 0.1 m" in printed and "policy" in printed and out.stat().st_size > 10_000


def test_train_on_a_map_file(tmp_path, capsys):
    spec = str(office(tmp_path))
    run = tmp_path / "run"
    argv = ["train", "--local", "--steps", "400", "--envs", "4", "--maps", spec, "--out", str(run)]
    argv += ["--eval-every", "0", "--final-eval-episodes", "0", "--hidden", "16", "--no-progress"]
    assert main(argv) == 0
    assert "cells of 0.1 m" in capsys.readouterr().out
    assert json.loads((run / "summary.json").read_text())["env_steps"] == 400


def test_demos_on_a_map_file(tmp_path, capsys):
    spec = str(office(tmp_path))
    demos = tmp_path / "office-v0"
    assert main(["demos", "generate", "--maps", spec, "--episodes", "2", "--out", str(demos)]) == 0
    out = capsys.readouterr().out
    assert "cells of 0.1 m" in out and "2 episodes" in out


def test_evaluate_flags_set_distances_and_the_step_limit(tmp_path, capsys):
    lab = tmp_path / "lab.txt"
    lab.write_text("\n".join(["#" * 14] + ["#" + "." * 12 + "#"] * 8 + ["#" * 14]) + "\n")
    argv = ["evaluate", "--compare", "heuristic", "heuristic", "--map", str(lab), "--episodes", "6"]
    argv += ["--min-distance", "6", "--step-factor", "0", "--max-steps", "2", "--out", str(tmp_path)]
    assert main(argv) == 0
    report = json.loads((tmp_path / "compare.json").read_text())["metrics"]["a"]["lab"]
    assert report["success"]["value"] == 0.0 and report["timeout"]["value"] > 0.5  # 2 steps reach nothing
    capsys.readouterr()
    argv = ["evaluate", "--policy", "heuristic", "--map", str(lab), "--episodes", "6", "--min-distance", "6"]
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
    episodes = json.loads((tmp_path / "b" / "eval.json").read_text())["episodes"]["lab"]
    assert all(e["shortest"] >= 6.0 for e in episodes)  # 1 m cells: every free cell holds the robot


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(420)
def test_up_trains_on_a_map_file_and_its_evaluator_measures_it(tmp_path):
    """`navlearn up --maps office.yaml` through the real processes: up says how the file was read,
    the actor trains on it (transitions reach the learner), the evaluator measures it as a set of
    its own beside the generated ones, and every process stops cleanly."""
    out, run = tmp_path / "run", f"upmap{os.getpid()}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    argv = [
        sys.executable, "-m", "services.cli", "up", "--run", run, "--out", str(out),
        "--maps", str(office(tmp_path)), "--actors", "1", "--envs", "4", "--eval-episodes", "2",
        "--hidden-sizes", "16", "--batch-size", "16", "--learning-starts", "64", "--duration", "5",
    ]  # fmt: skip
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=400)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "office.yaml: 120x80 pixels of 0.05 m -> 60x40 cells of 0.1 m" in done.stdout, done.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_codes"] == {"actor-1": 0, "learner": 0, "evaluator": 0}
    received = sum(a["transitions"] for a in summary["last_status"]["learner"]["actors"].values())
    assert received > 0
    assert "office" in summary["last_evaluation"]["metrics"]
    assert "office.yaml" in (out / "logs" / "actor-1.log").read_text()
