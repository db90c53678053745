"""`navlearn solve` and `navlearn tabular`: pictures written, figures printed, one-line errors."""

from __future__ import annotations

import re

import pytest

from services.cli import main


def png_written(path) -> bool:
    return path.exists() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("method", ["vi", "pi", "grid"])
def test_solve_arena(arena_paths, tmp_path, capsys, method):
    out = tmp_path / "values.png"
    assert main(["solve", "--map", str(arena_paths[0]), "--method", method, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "2054 states x 8 actions" in printed and "start (2, 2), goal (46, 47)" in printed
    assert re.search(
        r"\d+ (sweeps|policy improvements) in [\d.]+ s, residual [\d.e+-]+, max \|V - V\*\| <= ", printed
    )
    assert "reaches the goal in 49 moves" in printed
    assert png_written(out)


def test_solve_uses_ascii_markers_and_flags(tmp_path, capsys):
    map_path = tmp_path / "room.txt"
    map_path.write_text("#######\n#S....#\n#.###.#\n#....G#\n#######\n")
    out = tmp_path / "v.png"
    args = ["solve", "--map", str(map_path), "--connectivity", "4", "--slip", "0", "--method", "gs"]
    assert main([*args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "start (1, 1), goal (3, 5)" in printed and "x 4 actions" in printed
    assert "reaches the goal in 6 moves" in printed


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--map", "no/such.map"], "map file not found"),
        (["--goal", "0,0"], "blocked or outside"),
        (["--slip", "1.5"], "slip must be in"),
        (["--gamma", "1"], "--gamma must be in"),
    ],
)
def test_solve_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main(["solve", *args, "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.parametrize("algo", ["qlearning", "sarsa", "mc"])
def test_tabular_writes_a_learning_curve(tmp_path, capsys, algo):
    out = tmp_path / "curve.png"
    args = ["tabular", "--algo", algo, "--episodes", "3000", "--exploring-starts", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "3000 episodes" in printed and re.search(
        r"optimal action \(value iteration\) in \d+/33 states", printed
    )
    assert png_written(out)


def test_tabular_rejects_bad_config(tmp_path, capsys):
    assert main(["tabular", "--alpha", "2", "--out", str(tmp_path / "c.png")]) == 2
    assert "alpha must be in (0, 1]" in capsys.readouterr().err
