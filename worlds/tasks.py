"""Map specs: one string naming where navigation tasks come from.

=====================  ======================================================
spec                   tasks
=====================  ======================================================
``rooms:16``           a new generated 16x16 map per task (any family of
``rects:24x32``        :data:`worlds.generators.FAMILIES`; ``HxW`` is rows x
``maze:15``            columns), random start and goal
``mixed:16``           a random family among :data:`MIXED_FAMILIES` per task
``path/to/x.map``      a MovingAI map, random free connected start and goal
``path/to/x.scen``     the scenarios of a MovingAI scenario file, in turn
``path/to/x.txt``      an ASCII map: its S/G markers, else random start/goal
=====================  ======================================================

Generated training tasks use generator seeds below :data:`TRAIN_SEEDS`; held-out
evaluation sets use seeds at or above it, so they never share a map with training.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from worlds.generators import FAMILIES, generate, min_task_distance
from worlds.maps import GridMap, Task, components, load_map, load_movingai, load_scenarios, parse_ascii

TRAIN_SEEDS = 2**31
"""generated training maps use seeds in [0, TRAIN_SEEDS); evaluation maps use larger seeds"""
MIXED_FAMILIES = ("rects", "discs", "rooms")
"""families of ``mixed:N``; mazes are left out because a memoryless policy cannot solve them"""
DEFAULT_MAPS = "mixed:16"

_GENERATED = re.compile(r"^(?P<family>[a-z]+):(?P<h>\d+)(?:x(?P<w>\d+))?$")


class TaskSampler:
    """A callable ``(rng) -> Task``. ``tasks`` is the full list when the source is finite;
    ``resample`` says whether an environment may draw new random start/goal pairs on the
    maps of its tasks (true for sources whose start and goal are random anyway), at least
    ``min_distance`` metres apart. ``cache_key``, set for samplers built from a spec, lets
    environments share the task pool of equal specs (see :func:`worlds.bank.pool_bank`)."""

    def __init__(
        self,
        draw: Callable[[np.random.Generator], Task],
        key: str,
        tasks: list[Task] | None = None,
        resample: bool = False,
        min_distance: float = 0.0,
        cache_key: str | None = None,
    ) -> None:
        self._draw = draw
        self.key = key
        self.cache_key = cache_key
        self.tasks = tasks
        self.resample = resample
        self.min_distance = min_distance

    def __call__(self, rng: np.random.Generator) -> Task:
        return self._draw(rng)

    def __repr__(self) -> str:
        return f"TaskSampler({self.key!r})"


def _random_endpoints(grid: GridMap, min_distance: float) -> Callable[[np.random.Generator], Task]:
    labels = components(grid)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    cells = np.argwhere(labels == int(np.argmax(sizes)))  # the largest free region

    def draw(rng: np.random.Generator) -> Task:
        start = cells[rng.integers(len(cells))]
        far = cells[np.hypot(*(cells - start).T) * grid.cell_size >= min_distance]
        goal = far[rng.integers(len(far))] if len(far) else cells[rng.integers(len(cells))]
        return Task(grid, (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1])), grid.name)

    return draw


def _generated(family: str, height: int, width: int) -> TaskSampler:
    families = MIXED_FAMILIES if family == "mixed" else (family,)

    def draw(rng: np.random.Generator) -> Task:
        fam = families[int(rng.integers(len(families)))]
        grid = generate(fam, height, width, int(rng.integers(TRAIN_SEEDS)))
        return _random_endpoints(grid, min_task_distance(grid))(rng)

    probe = GridMap(np.zeros((height, width), dtype=bool))
    key = f"{family}:{height}x{width}"
    return TaskSampler(draw, key, resample=True, min_distance=min_task_distance(probe), cache_key=key)


def parse_map_spec(spec: str) -> TaskSampler:
    """The :class:`TaskSampler` for ``spec`` (see the module docstring). Raises ValueError
    (or :class:`worlds.maps.MapFormatError`, a ValueError) with a clear message on a bad spec."""
    spec = spec.strip()
    match = _GENERATED.match(spec)
    if match:
        family = match["family"]
        if family not in (*FAMILIES, "mixed"):
            raise ValueError(
                f"unknown map family {family!r} in {spec!r}; choose one of {', '.join(FAMILIES)}, mixed"
            )
        height = int(match["h"])
        width = int(match["w"] or height)
        if min(height, width) < 5 or max(height, width) > 1024:
            raise ValueError(f"map size in {spec!r} must be between 5 and 1024 cells a side")
        return _generated(family, height, width)
    path = Path(spec)
    if not path.exists():
        raise ValueError(
            f"map spec {spec!r} is neither FAMILY:N[xM] (families: {', '.join((*FAMILIES, 'mixed'))}) "
            "nor an existing map file"
        )
    stat = path.stat()
    file_key = f"{path.resolve()}@{stat.st_mtime_ns}:{stat.st_size}"
    if path.suffix == ".scen":
        scenarios = load_scenarios(path)
        if not scenarios:
            raise ValueError(f"{path}: no scenarios")
        grids: dict[str, GridMap] = {}
        tasks = []
        for scen in scenarios:
            if scen.map_name not in grids:
                grids[scen.map_name] = load_movingai(path.parent / Path(scen.map_name).name)
            tasks.append(Task(grids[scen.map_name], scen.start, scen.goal, scen.map_name))
        turn = iter(range(2**62))
        return TaskSampler(
            lambda rng: tasks[next(turn) % len(tasks)], str(path), tasks=tasks, cache_key=file_key
        )
    grid = load_map(path)
    if not path.read_text(encoding="ascii").startswith("type "):
        grid, markers = parse_ascii(path.read_text(encoding="ascii"), path)
        if "S" in markers and "G" in markers:
            task = Task(grid, markers["S"], markers["G"], grid.name)
            return TaskSampler(lambda rng: task, str(path), tasks=[task], cache_key=file_key)
    distance = 0.25 * min(grid.shape) * grid.cell_size
    draw = _random_endpoints(grid, distance)
    return TaskSampler(draw, str(path), resample=True, min_distance=distance, cache_key=file_key)


def as_sampler(maps: str | Callable[[np.random.Generator], Task]) -> TaskSampler:
    """A spec string or any ``(rng) -> Task`` callable, as a :class:`TaskSampler`."""
    if isinstance(maps, TaskSampler):
        return maps
    if isinstance(maps, str):
        return parse_map_spec(maps)
    if callable(maps):
        return TaskSampler(maps, getattr(maps, "__name__", "callable"))
    raise TypeError(f"maps must be a spec string or a callable (rng) -> Task, got {type(maps).__name__}")
