"""The compiled grid searches against plain pure-Python references on random grids: Dijkstra
distances (worlds.gridsearch, and the geodesic reward's bucket-queue Dijkstra of worlds.geodesic,
paused at random cells) equal a heapq Dijkstra exactly; A* and Dijkstra parents (which of several
equal paths, i.e. the ties) equal a plain indexed-heap search written out here; work arrays reused
across searches (generation stamps, their wrap) change nothing."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest

from worlds.config import LEARNING_NAV
from worlds.fields import BLOCKED
from worlds.geodesic import field_distance, move_masks, new_fields, start_field
from worlds.gridsearch import GEN, grid_search, new_work, search_run, search_start
from worlds.perceive import STAMP_WRAP
from worlds.vector_env import NavigationVectorEnv

MOVES = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]


def neighbours(blocked, node, diagonal):
    """(neighbour, step) in the search's order: straight moves, then diagonals that cut no corner."""
    height, width = blocked.shape
    r, c = divmod(node, width)
    for k, (dr, dc) in enumerate(MOVES[: 8 if diagonal else 4]):
        nr, nc = r + dr, c + dc
        if not (0 <= nr < height and 0 <= nc < width) or blocked[nr, nc]:
            continue
        if k >= 4 and (blocked[r, nc] or blocked[nr, c]):
            continue
        yield nr * width + nc, math.sqrt(2.0) if k >= 4 else 1.0


def heapq_dijkstra(blocked, start, diagonal):
    """Textbook Dijkstra with heapq and lazy deletion: distance per cell (inf unreached)."""
    dist = np.full(blocked.size, np.inf)
    dist[start] = 0.0
    queue, done = [(0.0, start)], set()
    while queue:
        d, node = heapq.heappop(queue)
        if node in done:
            continue
        done.add(node)
        for nb, step in neighbours(blocked, node, diagonal):
            if nb not in done and d + step < dist[nb]:
                dist[nb] = d + step
                heapq.heappush(queue, (d + step, nb))
    return dist


def indexed_heap_search(blocked, start, goal, diagonal):
    """The documented search written plainly: a binary heap of cells with decrease-key, ordered by f
    and, on equal f, by the larger g; A* with the octile (Manhattan) heuristic towards ``goal`` or
    Dijkstra (goal < 0). Returns (g, parent) as dicts."""
    width = blocked.shape[1]

    def h(node):
        if goal < 0:
            return 0.0
        dr, dc = abs(node // width - goal // width), abs(node % width - goal % width)
        return float(max(dr, dc)) + (math.sqrt(2.0) - 1.0) * min(dr, dc) if diagonal else float(dr + dc)

    g, f, parent, closed = {start: 0.0}, {start: h(start)}, {start: -1}, set()
    heap, pos = [start], {start: 0}

    def before(a, b):
        return f[a] < f[b] if f[a] != f[b] else g[a] > g[b]

    def place(i, node):
        heap[i], pos[node] = node, i

    def up(i):
        node = heap[i]
        while i > 0 and before(node, heap[(i - 1) // 2]):
            place(i, heap[(i - 1) // 2])
            i = (i - 1) // 2
        place(i, node)

    def down(i):
        node = heap[i]
        while 2 * i + 1 < len(heap):
            child = 2 * i + 1
            if child + 1 < len(heap) and before(heap[child + 1], heap[child]):
                child += 1
            if not before(heap[child], node):
                break
            place(i, heap[child])
            i = child
        place(i, node)

    while heap:
        node, last = heap[0], heap.pop()
        del pos[node]
        if heap:
            place(0, last)
            down(0)
        closed.add(node)
        if node == goal:
            break
        for nb, step in neighbours(blocked, node, diagonal):
            if nb in closed or g[node] + step >= g.get(nb, math.inf):
                continue
            g[nb], f[nb], parent[nb] = g[node] + step, g[node] + step + h(nb), node
            if nb not in pos:
                heap.append(nb)
                pos[nb] = len(heap) - 1
            up(pos[nb])
    return g, parent


def random_cases(n, seed):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        height, width = (int(v) for v in rng.integers(1, 14, size=2))
        density = rng.choice([0.0, 0.0, 0.15, 0.3, 0.45])  # open grids: many equal-length paths
        blocked = rng.random((height, width)) < density
        start, goal = (int(v) for v in rng.integers(height * width, size=2))
        blocked.flat[start] = False
        yield blocked, start, goal


@pytest.mark.parametrize("diagonal", [True, False])
def test_dijkstra_distances_equal_a_heapq_dijkstra_exactly(diagonal):
    for blocked, start, _ in random_cases(150, seed=1):
        g, _, _ = grid_search(blocked, start, -1, diagonal)
        np.testing.assert_array_equal(g, heapq_dijkstra(blocked, start, diagonal))


@pytest.mark.parametrize("diagonal", [True, False])
def test_parents_and_costs_equal_the_plain_indexed_heap_search_ties_included(diagonal):
    ties = 0
    for blocked, start, goal in random_cases(300, seed=2):
        for target in (goal, -1):
            g, parent, _ = grid_search(blocked, start, target, diagonal)
            ref_g, ref_parent = indexed_heap_search(blocked, start, target, diagonal)
            assert {k: g[k] for k in ref_g} == ref_g
            assert np.isinf(np.delete(g, list(ref_g))).all()
            assert {k: int(parent[k]) for k in ref_parent} == ref_parent
        # the goal has several shortest-path parents (g from the Dijkstra, the last target): a tie
        ties += sum(g[nb] + step == g[goal] for nb, step in neighbours(blocked, goal, diagonal)) > 1
    assert ties > 20


def test_a_tie_is_broken_as_before():
    # two paths of 1 + sqrt(2) from (0, 0) to (2, 1) on an open 3x3 grid; the heap's order picks one
    _, parent, expanded = grid_search(np.zeros((3, 3), bool), 0, 7, True)
    assert (int(parent[7]), int(parent[parent[7]])) == (4, 0) and expanded == 3


def padded(blocked):
    height, width = blocked.shape
    grid = np.full((height + 2, width + 2), BLOCKED, np.uint8)
    grid[1:-1, 1:-1] = np.where(blocked, BLOCKED, 0)
    return grid.ravel(), width + 2


def moves_of(blocked):
    """The geodesic field's move table of one map (a bank of one, at offset 0)."""
    field, stride = padded(blocked)
    height, width = blocked.shape
    return move_masks(field, np.zeros(1, np.int64), np.array([height]), np.array([width])), stride


@pytest.mark.parametrize("reuse", [True, False])
def test_paused_bucket_dijkstra_gives_the_distances_of_a_heapq_dijkstra(reuse):
    rng = np.random.default_rng(3)
    geo = new_fields(3, 16 * 16)
    for k in range(150):
        height, width = (int(v) for v in rng.integers(1, 15, size=2))
        blocked = rng.random((height, width)) < rng.choice([0.0, 0.2, 0.4])
        goal = int(rng.integers(blocked.size))
        blocked.flat[goal] = False
        whole = heapq_dijkstra(blocked, goal, True)
        moves, stride = moves_of(blocked)
        i = k % 3  # robots' rows reused episode after episode
        start_field(moves, 0, stride, (goal // width + 1) * stride + goal % width + 1, geo, i, reuse)
        for cell in rng.integers(-1, blocked.size + 1, size=12):  # -1, size: off the map
            x, y = ((cell % width + 0.5) * 0.5, (cell // width + 0.5) * 0.5) if cell >= 0 else (-1.0, 1.0)
            expected = whole[cell] * 0.5 if 0 <= cell < blocked.size else math.inf
            assert field_distance(moves, 0, height, width, geo, i, 0.5, x, y) == expected


def test_a_wrapped_generation_stamp_forgets_every_cell():
    moves, stride = moves_of(np.zeros((4, 4), bool))
    geo = new_fields(1, moves.size)
    start_field(moves, 0, stride, stride + 1, geo, 0, False)
    geo[-1][0, 0] = 2**30 - 2  # the next field wraps the stamps: cells of the last one must not count
    geo[1][geo[1] > 0] = 2 * (2**30 - 1) + 1
    start_field(moves, 0, stride, 4 * stride + 4, geo, 0, True)
    assert field_distance(moves, 0, 4, 4, geo, 0, 1.0, 0.5, 0.5) == pytest.approx(3 * math.sqrt(2.0))

    blocked = np.zeros((6, 6), bool)
    grid, stride = padded(blocked)
    work = new_work(grid.size)
    g, seen, meta = work[0], work[3], work[8]
    search_start(stride + 1, -1, stride, True, *work)
    search_run(grid, 0, stride, -1, True, *work)
    meta[GEN] = 2**31 - 2  # the next search wraps the stamp: cells the last one saw must not count
    seen[seen > 0] = 2**31 - 1
    search_start(stride + 1, 7 * stride - 2, stride, True, *work)
    expanded = search_run(grid, 0, stride, 7 * stride - 2, True, *work)
    assert meta[GEN] == 1 and expanded == 6 and g[7 * stride - 2] == pytest.approx(5 * math.sqrt(2.0))


def test_wrapped_plan_stamps_change_no_observation():
    """The own-map subgoal's int32 stamps (plan-map versions, search ids) start again when they wrap,
    forgetting the plans they mark: the observations stay those of a run that never wraps."""

    def rollout(wrap: bool) -> np.ndarray:
        env = NavigationVectorEnv(8, LEARNING_NAV, maps="rooms:12x20", threads=1)
        frames = [env.reset(seed=4)[0]]
        if wrap:
            env.batch.perception.version[:] = STAMP_WRAP - 1
            env.batch.perception.searches[:] = STAMP_WRAP - 1
        rng = np.random.default_rng(4)
        for _ in range(60):
            frames.append(env.step(rng.integers(LEARNING_NAV.robot.n_actions, size=8))[0])
        assert (env.batch.perception.version < (STAMP_WRAP if wrap else 1000)).all()
        return np.stack(frames)

    np.testing.assert_array_equal(rollout(False), rollout(True))
