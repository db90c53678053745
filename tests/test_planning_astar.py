"""Grid A*: exact on the MovingAI arena scenarios, no-path cases, 4-connectivity, corner rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.planning import astar, distance_field, path_length
from worlds.maps import GridMap, load_movingai, load_scenarios, parse_ascii


def test_arena_scenarios_give_their_optimal_length(arena_paths):
    map_path, scen_path = arena_paths
    grid = load_movingai(map_path)
    scenarios = load_scenarios(scen_path, grid)
    assert len(scenarios) == 130
    for scen in scenarios:
        result = astar(grid, scen.start, scen.goal)
        assert result.found
        assert result.length == pytest.approx(scen.optimal_length, abs=1e-6), scen
        assert result.path[0] == scen.start and result.path[-1] == scen.goal
        assert path_length(result.path) == pytest.approx(result.length, abs=1e-9)
        steps = np.abs(np.diff(np.asarray(result.path), axis=0))
        assert steps.max() <= 1 and steps.sum(axis=1).min() >= 1
        assert not any(grid.blocked[cell] for cell in result.path)


def test_distance_field_matches_astar(arena_paths):
    grid = load_movingai(arena_paths[0])
    scen = load_scenarios(arena_paths[1], grid)[-1]
    field = distance_field(grid, scen.goal)
    assert field[scen.start] == pytest.approx(scen.optimal_length, abs=1e-6)
    assert np.isinf(field[grid.blocked]).all()


def test_no_path_is_a_result_not_an_exception():
    grid, _ = parse_ascii("#####\n#.#.#\n#####\n")
    result = astar(grid, (1, 1), (1, 3))
    assert not result.found and result.path is None and math.isinf(result.length)
    assert result.expanded == 1
    blocked_goal = astar(grid, (1, 1), (0, 0))
    assert not blocked_goal.found and blocked_goal.expanded == 0
    outside = astar(grid, (1, 1), (9, 9))
    assert not outside.found


def test_diagonals_never_cut_corners():
    # The only way from S to G diagonally passes a blocked corner, so the path must go around.
    grid, m = parse_ascii("S#\n..\n.G\n")
    result = astar(grid, m["S"], m["G"])
    assert result.found
    assert result.path == [(0, 0), (1, 0), (2, 1)]
    assert result.length == pytest.approx(1 + math.sqrt(2))
    squeezed, m = parse_ascii("S#\n#G\n")
    assert not astar(squeezed, m["S"], m["G"]).found


def test_four_connected_uses_manhattan_moves():
    grid = GridMap(np.zeros((6, 7), dtype=bool), cell_size=0.5)
    result = astar(grid, (0, 0), (5, 6), connectivity=4)
    assert result.length == pytest.approx((5 + 6) * 0.5)
    steps = np.abs(np.diff(np.asarray(result.path), axis=0)).sum(axis=1)
    assert (steps == 1).all()
    eight = astar(grid, (0, 0), (5, 6))
    assert eight.length == pytest.approx((5 * math.sqrt(2) + 1) * 0.5)
    with pytest.raises(ValueError, match="connectivity"):
        astar(grid, (0, 0), (1, 1), connectivity=6)


def test_matches_networkx_on_random_maps():
    nx = pytest.importorskip("networkx")
    rng = np.random.default_rng(3)
    for _ in range(20):
        blocked = rng.random((20, 25)) < 0.3
        free = np.argwhere(~blocked)
        s, t = (tuple(int(v) for v in free[i]) for i in rng.choice(len(free), 2, replace=False))
        graph = nx.Graph()
        for r, c in free:
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                nr, nc = r + dr, c + dc
                if not (0 <= nr < 20 and 0 <= nc < 25) or blocked[nr, nc]:
                    continue
                if dr and dc and (blocked[r, nc] or blocked[nr, c]):
                    continue
                graph.add_edge((r, c), (nr, nc), weight=math.hypot(dr, dc))
        ours = astar(blocked, s, t)
        if s in graph and t in graph and nx.has_path(graph, s, t):
            assert ours.length == pytest.approx(nx.shortest_path_length(graph, s, t, weight="weight"))
        else:
            assert not ours.found
