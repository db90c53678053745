"""Map loaders, bad map files and task sampling (worlds.maps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from worlds.maps import (
    GridMap,
    MapFormatError,
    Task,
    clearance,
    connected,
    load_ascii,
    load_ascii_task,
    load_map,
    load_movingai,
    load_scenarios,
    parse_ascii,
    sample_task,
    to_ascii,
)

MOVINGAI_OK = "type octile\nheight 3\nwidth 4\nmap\n@@@@\n@.G@\n@@T@\n"


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_arena_map_and_all_scenarios_load(arena_paths):
    map_path, scen_path = arena_paths
    grid = load_movingai(map_path)
    assert grid.shape == (49, 49)
    assert grid.name == "arena"
    scenarios = load_scenarios(scen_path)
    assert len(scenarios) == 130
    for scen in scenarios:
        assert grid.is_free(scen.start) and grid.is_free(scen.goal)
        assert connected(grid, scen.start, scen.goal)
    first = scenarios[0]
    # first line: "0 arena.map 49 49 19 26 19 29 3.0" - x is the column, y the row
    assert (first.start, first.goal, first.optimal_length) == ((26, 19), (29, 19), 3.0)


def test_movingai_characters(tmp_path):
    grid = load_movingai(write(tmp_path, "tiny.map", MOVINGAI_OK))
    expected = np.array([[1, 1, 1, 1], [1, 0, 0, 1], [1, 1, 1, 1]], dtype=bool)
    np.testing.assert_array_equal(grid.blocked, expected)
    assert load_map(tmp_path / "tiny.map") == grid


@pytest.mark.parametrize(
    ("text", "line", "fragment"),
    [
        ("height 3\nwidth 4\nmap\n", 1, "type octile"),
        ("type octile\nwidth 4\nheight 3\nmap\n", 2, "height"),
        ("type octile\nheight 3\nwidth 4\nmapp\n@@@@\n", 4, "'map'"),
        ("type octile\nheight 3\nwidth 4\nmap\n@@@@\n@.@\n@@@@\n", 6, "3 characters"),
        ("type octile\nheight 3\nwidth 4\nmap\n@@@@\n@.x@\n@@@@\n", 6, "unknown map character 'x'"),
        ("type octile\nheight 3\nwidth 4\nmap\n@@@@\n@..@\n", 6, "height 3, found 2 rows"),
    ],
)
def test_bad_movingai_files_name_file_and_line(tmp_path, text, line, fragment):
    path = write(tmp_path, "bad.map", text)
    with pytest.raises(MapFormatError) as info:
        load_movingai(path)
    assert info.value.line == line
    assert str(path) in str(info.value)
    assert fragment in str(info.value)


def test_scenario_with_blocked_start_is_rejected(tmp_path):
    write(tmp_path, "tiny.map", MOVINGAI_OK)
    scen = write(
        tmp_path,
        "tiny.map.scen",
        "version 1\n0\ttiny.map\t4\t3\t1\t1\t2\t1\t1.0\n0\ttiny.map\t4\t3\t0\t0\t2\t1\t2.0\n",
    )
    with pytest.raises(MapFormatError) as info:
        load_scenarios(scen)
    assert info.value.line == 3 and "start" in str(info.value)


def test_scenario_size_mismatch_and_bad_header(tmp_path):
    write(tmp_path, "tiny.map", MOVINGAI_OK)
    wrong = write(tmp_path, "a.scen", "version 1\n0\ttiny.map\t5\t3\t1\t1\t2\t1\t1.0\n")
    with pytest.raises(MapFormatError, match="does not match"):
        load_scenarios(wrong)
    with pytest.raises(MapFormatError, match="version 1"):
        load_scenarios(write(tmp_path, "b.scen", "0\ttiny.map\t4\t3\t1\t1\t2\t1\t1.0\n"))
    with pytest.raises(MapFormatError, match="9 fields"):
        load_scenarios(write(tmp_path, "c.scen", "version 1\n0\ttiny.map\t4\t3\n"))


def test_missing_file_is_a_map_format_error(tmp_path):
    with pytest.raises(MapFormatError, match="file not found"):
        load_movingai(tmp_path / "nope.map")


def test_ascii_round_trip_and_markers(tmp_path):
    text = "#####\n#S..#\n#.#G#\n#####\n"
    grid, markers = parse_ascii(text)
    assert markers == {"S": (1, 1), "G": (2, 3)}
    assert to_ascii(grid, markers["S"], markers["G"]) == text
    path = write(tmp_path, "room.txt", text)
    assert load_ascii(path) == grid
    task = load_ascii_task(path)
    assert (task.start, task.goal) == ((1, 1), (2, 3))


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("####\n#S.\n####\n", "3 characters"),
        ("####\n#S?#\n####\n", "unknown map character '?'"),
        ("####\n#S##\n####\n", "no 'G' marker"),
        ("#####\n#S#G#\n#####\n", "not connected"),
    ],
)
def test_bad_ascii_task_files(tmp_path, text, fragment):
    with pytest.raises(MapFormatError, match=fragment):
        load_ascii_task(write(tmp_path, "bad.txt", text))


def test_task_rejects_blocked_start():
    grid, _ = parse_ascii("###\n#.#\n###\n")
    with pytest.raises(ValueError, match="blocked"):
        Task(grid, (0, 0), (1, 1))


def test_clearance_counts_border_and_obstacles():
    grid = GridMap(np.zeros((5, 5), dtype=bool), cell_size=0.5)
    dist = clearance(grid)
    assert dist[2, 2] == pytest.approx(1.5)  # three cells to the border, 0.5 m each
    assert dist[0, 0] == pytest.approx(0.5)


def test_sample_task_is_seeded_free_connected_and_far():
    blocked = np.zeros((20, 20), dtype=bool)
    blocked[:, 10] = True  # two disconnected halves
    grid = GridMap(blocked)
    a = sample_task(grid, np.random.default_rng(3), min_distance=5.0)
    b = sample_task(grid, np.random.default_rng(3), min_distance=5.0)
    assert (a.start, a.goal) == (b.start, b.goal)
    for seed in range(20):
        task = sample_task(grid, np.random.default_rng(seed), min_distance=5.0)
        assert connected(grid, task.start, task.goal)
        assert np.hypot(task.start[0] - task.goal[0], task.start[1] - task.goal[1]) >= 5.0
    with pytest.raises(ValueError, match="could not place"):
        sample_task(grid, np.random.default_rng(0), min_distance=100.0, max_tries=5)


def test_gridmap_is_read_only():
    grid = GridMap(np.zeros((3, 3), dtype=bool))
    with pytest.raises(ValueError):
        grid.blocked[0, 0] = True
