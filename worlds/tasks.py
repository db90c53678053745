"""Map specs: one string naming where navigation tasks come from, used by every command that takes
``--maps`` (train, up and its actors, evaluator, demos, nirl, world show, evaluate's ``--map``).

A spec is one or more comma-separated *sources*, optionally followed by ``key=value`` options:

=========================  ======================================================================
source                     tasks
=========================  ======================================================================
``rooms:16``               a new generated 16x16 map per task (any family of
``rects:24x32``            :data:`worlds.generators.FAMILIES`; ``HxW`` is rows x columns), random
``maze:15``                start and goal; several generated sources (``mixed:16,mixed:32``): each
``mixed:16``               task from one of them, uniformly; ``mixed`` is a random family among
                           :data:`MIXED_FAMILIES` per task
``mixed:16-64``            a side per task too, square, log-uniform in 16..64 cells (about equal
                           robot-steps per doubling of the side): :data:`worlds.config.TRAINING_MAPS`
``path/map.yaml``          a ROS map_server map (YAML + PGM/PNG image)
``path/x.map``             a MovingAI map: the scenarios of the ``.scen`` beside it when there is
                           one, else drawn pairs
``path/x.scen``            the scenarios of a MovingAI scenario file (maps beside it)
``path/x.txt``             an ASCII map: its S/G markers, else drawn pairs
``path/dir``               every map file in the directory (a training set)
=========================  ======================================================================

Map files load through :func:`worlds.mapfiles.load_map_file` (formats, the cell-size rule, errors).
Their pairs are drawn by :func:`worlds.pairs.draw_pairs`: reachable for the robot, spread over A*
distance buckets, ``pool_size`` of them per spec from the pool seed (split evenly over the files).
Options (for map files): ``min_distance`` / ``max_distance`` (m, the pairs' A* distance range,
default 2 m to the map's longest), ``unknown`` (``blocked``, the default, or ``free``: map_server
cells of unknown occupancy), ``cell_size`` (m, overrides the cell-size rule of map_server maps),
``resolution`` (m per cell of MovingAI/ASCII maps, default 1), ``radius`` (m, your robot's, default
the world's robot, :class:`worlds.config.RobotConfig`'s: a map for a robot of another radius is
scaled so that the world's robot stands for it, :mod:`worlds.mapfiles`). Distances and cell sizes
are the file's metres. Example: ``--maps office.yaml,min_distance=5,unknown=free``.

Generated training tasks use generator seeds below :data:`TRAIN_SEEDS`; held-out
evaluation sets use seeds at or above it, so they never share a map with training.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worlds.generators import FAMILIES, generate, min_task_distance
from worlds.mapfiles import UNKNOWN, WORLD_RADIUS, MapFile, load_map_file, map_paths
from worlds.maps import GridMap, MapFormatError, Task, components, load_movingai, load_scenarios
from worlds.pairs import draw_pairs

TRAIN_SEEDS = 2**31
"""generated training maps use seeds in [0, TRAIN_SEEDS); evaluation maps use larger seeds"""
MIXED_FAMILIES = ("rects", "discs", "rooms")
"""families of ``mixed:N``; mazes are left out because a memoryless policy cannot solve them"""
DEFAULT_MAPS = "mixed:16"

_GENERATED = re.compile(r"^(?P<family>[a-z]+):(?P<h>\d+)(?:x(?P<w>\d+)|-(?P<hi>\d+))?$")


PAIRS = ("own", "drawn")
"""where a map file's start/goal pairs come from (``MapOptions.pairs``)"""


@dataclass(frozen=True)
class MapOptions:
    """How map files are read and their start/goal pairs drawn (the ``key=value`` options of a spec)."""

    min_distance: float = 2.0
    """least A* distance between start and goal (m)"""
    max_distance: float = math.inf
    """largest A* distance between start and goal (m; default the map's longest)"""
    unknown: str = "blocked"
    """map_server cells of unknown occupancy: blocked or free"""
    cell_size: float | None = None
    """world cell size for map_server maps (m; default the rule of worlds.mapfiles)"""
    resolution: float = 1.0
    """metres per cell of MovingAI and ASCII maps"""
    radius: float = WORLD_RADIUS
    """the robot's radius (m): a map for a robot of another radius than the world's is scaled by
    ``WORLD_RADIUS / radius`` (:mod:`worlds.mapfiles`), so the world's robot stands for it; pairs are
    reachable for it, maps must fit it"""
    pairs: str = "own"
    """``own``: a file's own start/goal pairs (a MovingAI ``.scen``, an ASCII map's S/G) when it has
    them, else drawn; ``drawn``: always drawn (:func:`worlds.pairs.draw_pairs`), as many as asked"""

    def __post_init__(self) -> None:
        if self.unknown not in UNKNOWN:
            raise ValueError(f"map option unknown={self.unknown!r}; choose one of {', '.join(UNKNOWN)}")
        if self.pairs not in PAIRS:
            raise ValueError(f"map option pairs={self.pairs!r}; choose one of {', '.join(PAIRS)}")
        if not (0 <= self.min_distance < self.max_distance):
            raise ValueError(
                "map options need 0 <= min_distance < max_distance, got "
                f"{self.min_distance}, {self.max_distance}"
            )
        for name in ("resolution", "radius"):
            if not getattr(self, name) > 0:
                raise ValueError(f"map option {name}={getattr(self, name)} must be > 0")


class TaskSampler:
    """A callable ``(rng) -> Task``. ``tasks`` is the full list when the source is finite;
    ``draw_pool(size, seed)``, when set, draws a pool of ``size`` tasks at once (map files: pairs
    need distance searches, cheaper in bulk); ``resample`` says whether an environment may draw new
    random start/goal pairs on the maps of its tasks (true for sources whose start and goal are
    random anyway), at least ``min_distance`` metres apart (``min_distance_of(task)`` when set: a
    mix of map sizes). ``cache_key``, set for samplers built from a spec, lets environments share
    the task pool of equal specs (see :func:`worlds.bank.pool_bank`). ``maps`` holds the loaded map
    files (their ``note`` says what cell size was chosen)."""

    def __init__(
        self,
        draw: Callable[[np.random.Generator], Task],
        key: str,
        tasks: list[Task] | None = None,
        resample: bool = False,
        min_distance: float = 0.0,
        cache_key: str | None = None,
        draw_pool: Callable[[int, int], list[Task]] | None = None,
        min_distance_of: Callable[[Task], float] | None = None,
        maps: list[MapFile] | None = None,
    ) -> None:
        self._draw = draw
        self.key = key
        self.cache_key = cache_key
        self.tasks = tasks
        self.resample = resample
        self.min_distance = min_distance
        self.draw_pool = draw_pool
        self.min_distance_of = min_distance_of or (lambda task: self.min_distance)
        self.maps = maps or []
        self.spec = key  # the spec it was parsed from (samplers of parse_map_spec)

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


def _generated_draw(
    family: str, height: int, width: int, high: int = 0
) -> Callable[[np.random.Generator], Task]:
    """Tasks of ``family`` on ``height`` x ``width`` maps, or (``high`` > 0) on square maps of a side drawn
    per task, log-uniform in ``height``..``high``."""
    families = MIXED_FAMILIES if family == "mixed" else (family,)
    log_low, log_high = np.log(height), np.log(high + 1)

    def draw(rng: np.random.Generator) -> Task:
        h = w = min(int(np.exp(rng.uniform(log_low, log_high))), high) if high else None
        fam = families[int(rng.integers(len(families)))]
        grid = generate(fam, h or height, w or width, int(rng.integers(TRAIN_SEEDS)))
        return _random_endpoints(grid, min_task_distance(grid))(rng)

    return draw


def _parse_generated(spec: str) -> tuple[str, int, int, int] | None:
    match = _GENERATED.match(spec)
    if not match:
        return None
    family = match["family"]
    if family not in (*FAMILIES, "mixed"):
        choices = ", ".join((*FAMILIES, "mixed"))
        raise ValueError(f"unknown map family {family!r} in {spec!r}; choose one of {choices}")
    height = int(match["h"])
    width = int(match["w"] or match["hi"] or height)
    if min(height, width) < 5 or max(height, width) > 1024:
        raise ValueError(f"map size in {spec!r} must be between 5 and 1024 cells a side")
    if match["hi"]:
        if width <= height:
            raise ValueError(f"size range in {spec!r} must go up (e.g. mixed:16-64)")
        return family, height, height, width
    return family, height, width, 0


def _generated(parts: list[tuple[str, int, int, int]]) -> TaskSampler:
    draws = [_generated_draw(*p) for p in parts]

    def draw(rng: np.random.Generator) -> Task:
        return draws[int(rng.integers(len(draws)))](rng) if len(draws) > 1 else draws[0](rng)

    key = ",".join(f"{f}:{h}-{hi}" if hi else f"{f}:{h}x{w}" for f, h, w, hi in parts)
    least = min(min_task_distance(GridMap(np.zeros((h, w), dtype=bool))) for _, h, w, _ in parts)
    return TaskSampler(
        draw, key, resample=True, min_distance=least, cache_key=key,
        min_distance_of=lambda task: min_task_distance(task.grid),
    )  # fmt: skip


def names_files(spec: str) -> bool:
    """Does ``spec`` name map files (not only generated maps)? Read from the text alone."""
    items = [p.strip() for p in spec.split(",") if p.strip() and "=" not in p]
    return any(_GENERATED.match(p) is None for p in items)


def parse_options(items: list[str], spec: str) -> MapOptions:
    """The :class:`MapOptions` of a spec's ``key=value`` items."""
    fields = {f.name: f for f in dataclasses.fields(MapOptions)}
    values: dict = {}
    for item in items:
        key, _, raw = item.partition("=")
        key = key.strip()
        if key not in fields:
            raise ValueError(f"map spec {spec!r}: unknown option {key!r}; known: {', '.join(fields)}")
        if fields[key].type == "str":  # a word (unknown, pairs); every other option is metres
            values[key] = raw.strip()
            continue
        try:
            values[key] = float(raw)
        except ValueError:
            raise ValueError(f"map spec {spec!r}: option {key}={raw!r} is not a number (metres)") from None
    return MapOptions(**values)


def spec_options(spec: str) -> MapOptions:
    """The :class:`MapOptions` a spec's ``key=value`` items give (defaults for the rest)."""
    return parse_options([p.strip() for p in spec.split(",") if "=" in p], spec)


def with_options(spec: str, **options) -> str:
    """``spec`` with ``key=value`` map options appended (those that are not None): how command-line
    flags such as ``--min-distance`` become part of the one spec every process parses."""
    extra = [f"{k}={v}" for k, v in options.items() if v is not None]
    return ",".join([spec, *extra])


def load_files(paths: list[Path], options: MapOptions) -> list[MapFile]:
    """The map files of ``paths`` (directories expanded), each loaded with ``options``."""
    files = [f for p in paths for f in map_paths(p)]
    loaded = [
        load_map_file(
            f, radius=options.radius, cell_size=options.cell_size, unknown=options.unknown,
            resolution=options.resolution,
        )
        for f in files
    ]  # fmt: skip
    if options.pairs == "drawn":  # the note says where the pairs come from
        loaded = [
            dataclasses.replace(mf, note=f"{mf.note}; not used: pairs=drawn") if mf.scenarios else mf
            for mf in loaded
        ]
    return loaded


def file_tasks(maps: list[MapFile], options: MapOptions, size: int, seed: int) -> list[Task]:
    """``size`` tasks over ``maps`` (split evenly, at least one each): a file's own scenarios in turn
    when it has them and ``options.pairs`` is ``own``, else pairs drawn by
    :func:`worlds.pairs.draw_pairs` with ``seed``."""
    tasks: list[Task] = []
    for k, mf in enumerate(maps):
        share = max(1, size // len(maps) + (1 if k < size % len(maps) else 0))
        if mf.scenarios and options.pairs == "own":
            picks = np.random.default_rng([seed, k, 7]).permutation(len(mf.scenarios))
            chosen = [mf.scenarios[picks[i % len(picks)]] for i in range(share)]
            tasks += [Task(mf.grid, sc.start, sc.goal, mf.grid.name) for sc in chosen]
            continue
        try:
            pairs = draw_pairs(  # on the world's grid: its robot, the distances in its metres
                mf.grid, share, int(seed) * 1_000_003 + k, WORLD_RADIUS, options.min_distance * mf.scale,
                options.max_distance * mf.scale,
            )  # fmt: skip
        except ValueError as exc:
            raise MapFormatError(mf.path, None, str(exc)) from None
        tasks += [task for task, _ in pairs]
    return tasks


def _file_key(paths: list[Path], options: MapOptions) -> str:
    stamps = []
    for p in paths:
        for f in map_paths(p):
            st = f.stat()
            stamps.append(f"{f.resolve()}@{st.st_mtime_ns}:{st.st_size}")
    return ";".join(stamps) + f"|{options}"


def _scen_file(path: Path) -> TaskSampler:
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
    stat = path.stat()
    key = f"{path.resolve()}@{stat.st_mtime_ns}:{stat.st_size}"
    return TaskSampler(lambda rng: tasks[next(turn) % len(tasks)], str(path), tasks=tasks, cache_key=key)


def parse_map_spec(spec: str) -> TaskSampler:
    """The :class:`TaskSampler` for ``spec`` (see the module docstring). Raises ValueError
    (or :class:`worlds.maps.MapFormatError`, a ValueError) with a clear message on a bad spec;
    map files are loaded (and checked) here, once."""
    items = [p.strip() for p in spec.split(",") if p.strip()]
    if not items:
        raise ValueError("empty map spec: give FAMILY:N[xM] or a map file or directory")
    options = [p for p in items if "=" in p]
    sources = [p for p in items if "=" not in p]
    if not sources:
        raise ValueError(f"map spec {spec!r} names no map, only options")
    generated = [_parse_generated(p) for p in sources]
    if all(g is not None for g in generated):
        if options:
            raise ValueError(f"map spec {spec!r}: options ({', '.join(options)}) apply to map files only")
        return _generated(generated)
    if any(g is not None for g in generated):
        raise ValueError(f"map spec {spec!r} mixes generated maps and map files; train on one kind per spec")
    for p in sources:
        if not Path(p).exists():
            raise ValueError(
                f"map spec {p!r} is neither FAMILY:N[xM] (families: {', '.join((*FAMILIES, 'mixed'))}) "
                "nor an existing map file or directory"
            )
    paths = [Path(p) for p in sources]
    if len(paths) == 1 and paths[0].suffix == ".scen" and not options:
        return _scen_file(paths[0])
    opts = parse_options(options, spec)
    maps = load_files(paths, opts)

    def draw_pool(size: int, seed: int) -> list[Task]:
        return file_tasks(maps, opts, size, seed)

    def draw(rng: np.random.Generator) -> Task:
        return draw_pool(1, int(rng.integers(2**31)))[0]

    return TaskSampler(draw, spec, cache_key=_file_key(paths, opts), draw_pool=draw_pool, maps=maps)


def as_sampler(maps: str | Callable[[np.random.Generator], Task]) -> TaskSampler:
    """A spec string or any ``(rng) -> Task`` callable, as a :class:`TaskSampler`."""
    if isinstance(maps, TaskSampler):
        return maps
    if isinstance(maps, str):
        return parse_map_spec(maps)
    if callable(maps):
        return TaskSampler(maps, getattr(maps, "__name__", "callable"))
    raise TypeError(f"maps must be a spec string or a callable (rng) -> Task, got {type(maps).__name__}")
