"""The own-map subgoal plans in the robot's configuration space (:mod:`worlds.own_map`): on cells
finer than the robot the plan grid is inflated by its radius, per changed cell, and on 1 m cells
nothing of it runs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agents.evaluation import make_eval_set
from agents.evaluation.runner import fixed_sampler
from worlds.config import LEARNING_NAV
from worlds.fields import BLOCKED
from worlds.gridsearch import SOFT, new_work
from worlds.heuristics import goal_seeking_policy
from worlds.maps import GridMap, Task
from worlds.own_map import (
    CHANGED,
    FREE,
    ON_PLAN,
    SEEN_BLOCKED,
    UNKNOWN,
    _set,
    inflate,
    inflation_cells,
    plan_clear,
    waypoint,
)
from worlds.perception import REUSE_PARAM
from worlds.vector_env import NavigationVectorEnv


def padded(blocked: np.ndarray) -> np.ndarray:
    """The padded plan grid of ``blocked`` (ring blocked)."""
    h, w = blocked.shape
    plan = np.full((h + 2, w + 2), BLOCKED, np.uint8)
    plan[1:-1, 1:-1] = np.where(blocked, BLOCKED, 0)
    return plan.ravel()


def inflated(blocked: np.ndarray, radius: float, cell: float) -> np.ndarray:
    """The map cells of ``blocked`` that the inflation blocks, as a (h, w) bool array."""
    h, w = blocked.shape
    plan = padded(blocked)
    wide, near = levels(plan, [radius / cell])
    inflate(plan, wide, near, h, w, np.array([radius / cell]))
    return wide.reshape(h + 2, w + 2)[1:-1, 1:-1] == BLOCKED


def levels(plan: np.ndarray, reaches) -> tuple[np.ndarray, np.ndarray]:
    """An empty inflated grid (none without ``reaches``) and the counts of ``len(reaches)`` levels for
    the padded grid ``plan``."""
    n = len(reaches)
    return np.zeros(plan.size if n else 0, np.uint8), np.zeros((n, plan.size), np.int32)


def test_inflation_cells_from_the_radius_and_the_cell():
    assert inflation_cells(0.25, 1.0) == 0  # the training maps: nothing inflated
    assert inflation_cells(0.25, 0.5) == 0
    assert inflation_cells(0.25, 0.25) == 1  # mixed:32 split 4x4
    assert inflation_cells(0.25, 0.1) == 2  # map_server maps at 0.1 m
    assert inflation_cells(0.25, 0.05) == 5


def test_which_cells_a_blocked_cell_blocks():
    blocked = np.zeros((11, 11), bool)
    blocked[5, 5] = True
    # 0.1 m cells, 0.25 m radius: every centre within 2 cells (the corner (2, 2) is 0.21 m from the
    # square); the ring blocks the two outer rows and columns the same way
    expect = np.zeros((11, 11), bool)
    expect[3:8, 3:8] = True
    expect[:2], expect[-2:], expect[:, :2], expect[:, -2:] = True, True, True, True
    assert np.array_equal(inflated(blocked, 0.25, 0.1), expect)
    # 0.125 m cells: the corners (2, 2) lie 0.265 m away, the rest of the 5x5 square nearer than 0.25
    got = inflated(blocked, 0.25, 0.125)
    square = got[3:8, 3:8]
    assert square.sum() == 21 and not square[0, 0] and not square[4, 4] and not square[0, 4]
    assert not got[2:9, 2:9].sum() - 21  # nothing else inside the ring's band


def test_no_inflation_at_1m_cells_is_the_plan_grid():
    rng = np.random.default_rng(0)
    blocked = rng.random((9, 13)) < 0.3
    assert np.array_equal(inflated(blocked, 0.25, 1.0), blocked)


@pytest.mark.parametrize("unseen", [0, SOFT], ids=["unseen-free", "prefers-seen"])
def test_incremental_inflation_equals_inflating_from_scratch(unseen):
    """The inflated grid followed cell by cell equals the one inflated from the plan grid, whose unseen
    cells stay ``unseen`` (SOFT: ``subgoal_prefers_seen``) until seen."""
    rng = np.random.default_rng(1)
    h, w, cell = 23, 17, 0.1
    reach = np.array([0.4 / cell, 0.25 / cell])  # the clearance's level, then the radius's
    occ = np.zeros((h, w), np.int8)
    plan = np.zeros((h + 2) * (w + 2), np.uint8)
    plan_clear(plan, h, w, unseen)
    wide, near = levels(plan, reach)
    inflate(plan, wide, near, h, w, reach)
    exam = np.zeros(plan.shape, np.int32)
    for step in range(3000):
        r, c = int(rng.integers(h)), int(rng.integers(w))
        state = SEEN_BLOCKED if rng.random() < 0.4 else FREE
        _set(occ, plan, exam, -1, w + 2, r, c, state, wide, near, h, reach)
        if step % 500 == 499:
            wide2, near2 = levels(plan, reach)
            inflate(plan, wide2, near2, h, w, reach)
            assert np.array_equal(near, near2) and np.array_equal(wide, wide2)
            inner = plan.reshape(h + 2, w + 2)[1:-1, 1:-1]
            expected = np.select([occ == SEEN_BLOCKED, occ == FREE], [BLOCKED, 0], unseen)
            assert np.array_equal(inner, expected)
            if step == 499:
                assert (occ == UNKNOWN).any()  # unseen cells were checked too
    assert 0 < (occ == SEEN_BLOCKED).sum() < h * w  # both kinds of change happened


@pytest.mark.parametrize(("band", "reads", "misses"), [(0, 1, 2), (2, 3, 4)])
def test_a_change_reaches_the_plan_where_the_inflation_moved(band, reads, misses):
    """A cell that becomes blocked changes the inflated grid within ``band`` of it, which a search read
    from every cell it expanded within ``band + 1``: such a change is on the plan, one further is not."""
    h = w = 15
    for away, flags in ((reads, CHANGED | ON_PLAN), (misses, CHANGED)):
        occ = np.zeros((h, w), np.int8)
        plan = np.zeros((h + 2) * (w + 2), np.uint8)
        plan_clear(plan, h, w)
        reach = np.array([2.5] if band else [])  # reach 2.5 cells: band 2; none: no level
        wide, near = levels(plan, reach)
        inflate(plan, wide, near, h, w, reach)
        exam = np.zeros(plan.shape, np.int32)
        exam[(7 + 1) * (w + 2) + 7 + away + 1] = 5  # the last search (5) expanded cell (7, 7 + away)
        assert _set(occ, plan, exam, 5, w + 2, 7, 7, SEEN_BLOCKED, wide, near, h, reach) == flags


def search(blocked: np.ndarray, cell: float, start: tuple[int, int], goal: tuple[int, int], wide: bool,
           radii=(0.25,), along: float = 0.3):  # fmt: skip
    """(waypoint cell as (row, col) or None for the goal, path length m) of the own-map search, on the
    plan grid inflated by ``radii`` (levels, widest first) when ``wide``."""
    h, w = blocked.shape
    plan = padded(blocked)
    reach = np.array(radii if wide else []) / cell
    grid, near = levels(plan, reach)
    inflate(plan, grid, near, h, w, reach)
    exam = np.zeros(plan.shape, np.int32)
    x, y = (start[1] + 0.5) * cell, (start[0] + 0.5) * cell
    work = new_work(plan.size)
    node, searched, length = waypoint(plan, grid, near, reach, h, w, cell, x, y, goal[0], goal[1], along,
                                      work, exam, 1)  # fmt: skip
    assert searched
    return (None if node < 0 else (node // (w + 2) - 1, node % (w + 2) - 1)), length


def test_a_gap_narrower_than_the_robot_is_planned_round():
    # 0.1 m cells; a wall across row 10 with a 0.3 m gap (3 cells) near the start and a 0.7 m door
    # far off: the plain search takes the gap, the inflated one the door
    blocked = np.zeros((21, 40), bool)
    blocked[10] = True
    blocked[10, 3:6] = False  # the gap
    blocked[10, 30:37] = False  # the door
    _, plain = search(blocked, 0.1, (5, 4), (15, 4), wide=False)
    _, wide = search(blocked, 0.1, (5, 4), (15, 4), wide=True)
    assert plain == pytest.approx(1.0)
    assert wide > 5.0  # through the door, 26 cells away and back


def test_the_path_keeps_the_clearance_where_it_can():
    # 0.1 m cells, a corridor 1.2 m wide (columns 1-12) along the rows; start and goal in column 3,
    # 0.25 m from the wall: on the radius's level the path runs down column 3, on the clearance's
    # level (0.4 m) it moves out to column 5, 0.45 m from the wall, as a path through 1 m cells does
    # (the waypoint 1 m along, past the cells around the start that count free)
    blocked = np.zeros((60, 14), bool)
    blocked[:, 0] = blocked[:, 13] = True
    radius_only, _ = search(blocked, 0.1, (3, 3), (56, 3), wide=True, radii=(0.25,), along=1.0)
    both, length = search(blocked, 0.1, (3, 3), (56, 3), wide=True, radii=(0.4, 0.25), along=1.0)
    assert radius_only[1] == 3
    assert both[1] == 5
    # its length in metres, not its cost (two diagonals out, 49 cells down, two back; the soft cells it
    # crossed on the way out and back cost more but are no longer)
    assert length == pytest.approx(4 * math.sqrt(2) * 0.1 + 4.9)


def test_a_door_narrower_than_the_clearance_is_taken_at_a_cost():
    # the gap and the door of the test above: the 0.7 m door lies in the clearance's band (its middle
    # cell 0.35 m from the jambs), passable at a cost, so the path goes through it, not through the
    # 0.3 m gap (blocked within the radius); with the 0.4 m as the only, blocking, level there is no
    # inflated path and the plain grid's goes through the gap
    blocked = np.zeros((21, 40), bool)
    blocked[10] = True
    blocked[10, 3:6] = False
    blocked[10, 30:37] = False
    _, blocking = search(blocked, 0.1, (5, 4), (15, 4), wide=True, radii=(0.4,))
    _, both = search(blocked, 0.1, (5, 4), (15, 4), wide=True, radii=(0.4, 0.25))
    assert blocking == pytest.approx(1.0)
    assert both > 5.0


def test_a_door_in_the_band_beats_a_long_detour():
    # 0.25 m cells: a 1 m door (4 cells: the middle two in the 0.4 m band, the outer two within the
    # radius) next to the start and goal, a wide opening 13 m away: through the door, not round
    blocked = np.zeros((41, 80), bool)
    blocked[20] = True
    blocked[20, 4:8] = False  # the door
    blocked[20, 60:76] = False  # the opening
    _, length = search(blocked, 0.25, (10, 5), (30, 5), wide=True, radii=(0.4, 0.25))
    assert length < 6.0  # 20 cells of 0.25 m and a step sideways; round by the opening: over 30 m


def test_a_start_next_to_a_wall_still_plans_away_from_it():
    blocked = np.zeros((20, 20), bool)
    blocked[:, 0] = True  # a wall along column 0; the robot in column 1 (its centre 0.15 m from it)
    node, length = search(blocked, 0.1, (2, 1), (17, 5), wide=True)
    assert length > 0  # a path, though the start cell lies in the inflated band
    assert node is not None and node[1] >= 3  # the waypoint leads out of the band (columns 1-2)


def test_hemmed_in_by_the_inflation_the_plain_search_is_used():
    # a corridor 0.3 m wide (3 cells) is the only way: inflated, nothing passes (the start's and goal's
    # own cells free, their neighbours not); the plain path is kept
    blocked = np.ones((30, 9), bool)
    blocked[:, 3:6] = False
    _, plain = search(blocked, 0.1, (2, 4), (27, 4), wide=False)
    _, wide = search(blocked, 0.1, (2, 4), (27, 4), wide=True)
    assert plain == wide == pytest.approx(2.5)


def fine_tasks(k: int) -> list[Task]:
    """Rooms and rects maps of 16 cells with every cell split in k x k (0.25 m cells for k = 4)."""
    tasks = []
    for t in make_eval_set("unseen", 8, seed=5, size=16, families=("rects", "rooms")).tasks:
        grid = GridMap(t.grid.blocked.repeat(k, 0).repeat(k, 1), cell_size=t.grid.cell_size / k)
        start = (t.start[0] * k + k // 2, t.start[1] * k + k // 2)
        goal = (t.goal[0] * k + k // 2, t.goal[1] * k + k // 2)
        tasks.append(Task(grid, start, goal, f"{t.map_id}/{k}"))
    return tasks


def rollout(config, maps, reuse: bool, steps: int = 300, n: int = 12):
    """Observations of ``n`` robots driving ``steps`` steps, half at random, half towards the goal."""
    env = NavigationVectorEnv(n, config, maps=maps, threads=1)
    env.batch.perception.params[REUSE_PARAM] = float(reuse)
    obs, _ = env.reset(seed=3)
    rng, seek = np.random.default_rng(3), goal_seeking_policy(config)
    width = config.sensors.n_beams + 3  # readings + goal, what the heuristic reads
    frames = [obs.copy()]
    for _ in range(steps):
        actions = seek(obs[:, :width])
        actions[::2] = rng.integers(config.robot.n_actions, size=len(actions[::2]))
        obs, *_ = env.step(actions)
        frames.append(obs.copy())
    inflates = env.batch.perception.wide.shape[1] > 0
    env.close()
    return np.stack(frames), inflates


@pytest.mark.parametrize("subgoal", ["own_map", "known_map"])
def test_reused_plans_on_fine_cells_change_no_observation(subgoal):
    """A change reaches the kept plans wherever the inflated grid changed (within the band)."""
    config = dataclasses.replace(LEARNING_NAV, observation=dataclasses.replace(LEARNING_NAV.observation,
                                                                               subgoal=subgoal))  # fmt: skip
    maps = fixed_sampler(fine_tasks(4), "fine:4")
    plain, inflates = rollout(config, maps, reuse=False)
    reused, _ = rollout(config, maps, reuse=True)
    assert inflates
    assert np.array_equal(plain, reused)


def test_1m_maps_never_inflate():
    """On 1 m cells no inflated grid is even allocated: the subgoal search is the one trained on."""
    _, inflates = rollout(LEARNING_NAV, "mixed:16", reuse=True, steps=5)
    assert not inflates


@pytest.mark.parametrize("k", [1, 4, 10])
def test_no_ray_clears_the_wall_cell_it_hit(k):
    """The own map never holds a wall cell as free: a ray's free trace stops short of the cell it hit
    (``HIT_MARGIN``). Without the margin, 4% (0.25 m) and 8.5% (0.1 m) of the marked wall cells were
    cleared again by the trace of the ray that hit them, whose boundary crossings reach the hit cell a
    rounding error before its range."""
    env = NavigationVectorEnv(6, LEARNING_NAV, maps=fixed_sampler(fine_tasks(k), f"fine:{k}"), threads=1)
    obs, _ = env.reset(seed=3)
    seek, width = goal_seeking_policy(LEARNING_NAV), LEARNING_NAV.sensors.n_beams + 3
    occ, checked = env.batch.perception.occ, 0
    for _ in range(60):
        obs, _, terminated, truncated, _ = env.step(seek(obs[:, :width]))
        for i, task in enumerate(env.tasks()):
            if terminated[i] or truncated[i]:
                continue  # a new episode: its map starts empty
            h, w = task.grid.blocked.shape
            mine = occ[i, :h, :w]
            assert not (task.grid.blocked & (mine == FREE)).any(), f"robot {i} cleared a wall cell"
            checked += int((mine == SEEN_BLOCKED).sum())
    env.close()
    assert checked > 1000  # the robots saw walls
