"""Seeded map generators for unknown environments (thesis ch. 3-5 experiments).

Every family draws a bordered map from a seed alone, so ``generate(f, h, w, s)``
always returns the same map. Free space is made 4-connected (pockets cut off by
obstacles are filled in), so any two free cells are joined by a path a robot can
drive through cell centres, and :func:`generate_task` only has to keep start and
goal apart.
"""

from __future__ import annotations

import numpy as np

from worlds.maps import GridMap, Task, components, sample_task

FAMILIES = ("rects", "discs", "rooms", "maze")


def _bordered(height: int, width: int) -> np.ndarray:
    blocked = np.zeros((height, width), dtype=bool)
    blocked[0, :] = blocked[-1, :] = blocked[:, 0] = blocked[:, -1] = True
    return blocked


def _keep_largest_component(blocked: np.ndarray) -> np.ndarray:
    labels = components(GridMap(blocked))
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels != int(np.argmax(sizes))


def _rects(rng: np.random.Generator, height: int, width: int, density: float = 0.18) -> np.ndarray:
    blocked = _bordered(height, width)
    interior = (height - 2) * (width - 2)
    longest = max(2, min(height, width) // 5)
    for _ in range(10 * interior):
        if blocked[1:-1, 1:-1].mean() >= density:
            break
        h, w = rng.integers(1, longest + 1, size=2)
        r = rng.integers(1, height - 1)
        c = rng.integers(1, width - 1)
        blocked[r : min(r + h, height - 1), c : min(c + w, width - 1)] = True
    return blocked


def _discs(rng: np.random.Generator, height: int, width: int, density: float = 0.18) -> np.ndarray:
    blocked = _bordered(height, width)
    rows, cols = np.mgrid[0:height, 0:width] + 0.5
    largest = max(1.0, min(height, width) / 10)
    for _ in range(10 * height * width):
        if blocked[1:-1, 1:-1].mean() >= density:
            break
        radius = rng.uniform(0.6, largest + 0.5)
        cy, cx = rng.uniform(1, height - 1), rng.uniform(1, width - 1)
        blocked |= (rows - cy) ** 2 + (cols - cx) ** 2 <= radius**2
    return blocked


def _rooms(rng: np.random.Generator, height: int, width: int, min_room: int = 4, door: int = 2) -> np.ndarray:
    """Recursive division: split a region by a wall with one door, recurse while rooms are big."""
    blocked = _bordered(height, width)

    def divide(r0: int, c0: int, r1: int, c1: int) -> None:  # interior rows r0..r1-1, cols c0..c1-1
        h, w = r1 - r0, c1 - c0
        can_h, can_w = h >= 2 * min_room + 1, w >= 2 * min_room + 1
        if not (can_h or can_w):
            return
        horizontal = can_h and (not can_w or h > w or (h == w and rng.random() < 0.5))
        if horizontal:
            wall = int(rng.integers(r0 + min_room, r1 - min_room))
            blocked[wall, c0:c1] = True
            d = int(rng.integers(c0, c1 - door + 1))
            blocked[wall, d : d + door] = False
            divide(r0, c0, wall, c1)
            divide(wall + 1, c0, r1, c1)
        else:
            wall = int(rng.integers(c0 + min_room, c1 - min_room))
            blocked[r0:r1, wall] = True
            d = int(rng.integers(r0, r1 - door + 1))
            blocked[d : d + door, wall] = False
            divide(r0, c0, r1, wall)
            divide(r0, wall + 1, r1, c1)

    divide(1, 1, height - 1, width - 1)
    return blocked


def _maze(rng: np.random.Generator, height: int, width: int, loops: float = 0.1) -> np.ndarray:
    """Depth-first backtracker maze with 1-cell corridors, plus a few knocked-out walls (loops)."""
    blocked = np.ones((height, width), dtype=bool)
    n_r, n_c = (height - 1) // 2, (width - 1) // 2
    if n_r < 1 or n_c < 1:
        raise ValueError(f"a maze needs at least 3x3 cells, got {height}x{width}")
    seen = np.zeros((n_r, n_c), dtype=bool)
    stack = [(int(rng.integers(n_r)), int(rng.integers(n_c)))]
    seen[stack[0]] = True
    blocked[2 * stack[0][0] + 1, 2 * stack[0][1] + 1] = False
    while stack:
        r, c = stack[-1]
        options = [
            (r + dr, c + dc)
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1))
            if 0 <= r + dr < n_r and 0 <= c + dc < n_c and not seen[r + dr, c + dc]
        ]
        if not options:
            stack.pop()
            continue
        nr, nc = options[int(rng.integers(len(options)))]
        seen[nr, nc] = True
        blocked[2 * nr + 1, 2 * nc + 1] = False
        blocked[r + nr + 1, c + nc + 1] = False
        stack.append((nr, nc))
    inner = blocked[1 : 2 * n_r, 1 : 2 * n_c]
    # walls between two corridors (odd row, even col or even row, odd col) may be knocked out
    walls = np.argwhere(inner & (np.add.outer(np.arange(inner.shape[0]), np.arange(inner.shape[1])) % 2 == 1))
    if loops > 0 and len(walls):
        chosen = walls[rng.random(len(walls)) < loops]
        blocked[chosen[:, 0] + 1, chosen[:, 1] + 1] = False
    return blocked


_BUILDERS = {"rects": _rects, "discs": _discs, "rooms": _rooms, "maze": _maze}


def generate(family: str, height: int, width: int, seed: int, cell_size: float = 1.0, **kw) -> GridMap:
    """A ``height`` x ``width`` map of ``family`` (see :data:`FAMILIES`), bordered by walls,
    its free space 4-connected. Same arguments, same map. Keyword arguments go to the family:
    ``density`` (rects, discs), ``min_room`` and ``door`` (rooms), ``loops`` (maze)."""
    if family not in _BUILDERS:
        raise ValueError(f"unknown map family {family!r}; choose one of {', '.join(FAMILIES)}")
    if height < 5 or width < 5:
        raise ValueError(f"maps need at least 5x5 cells, got {height}x{width}")
    rng = np.random.default_rng([seed, FAMILIES.index(family), height, width])
    blocked = _BUILDERS[family](rng, height, width, **kw)
    blocked = _keep_largest_component(blocked)
    return GridMap(blocked, cell_size=cell_size, name=f"{family}-{height}x{width}-{seed}")


def min_task_distance(grid: GridMap) -> float:
    """Start and goal of generated tasks are at least this far apart (m): 40% of the shorter side."""
    return 0.4 * (min(grid.shape) - 2) * grid.cell_size


def generate_task(family: str, height: int, width: int, seed: int, cell_size: float = 1.0) -> Task:
    """A generated map with a start and goal, both free and connected, at least
    :func:`min_task_distance` apart (closer only if the map has no such pair)."""
    grid = generate(family, height, width, seed, cell_size)
    rng = np.random.default_rng([seed, 7919])
    distance = min_task_distance(grid)
    while True:
        try:
            return sample_task(grid, rng, min_distance=distance, max_tries=200)
        except ValueError:
            if distance <= grid.cell_size:
                raise
            distance /= 2
