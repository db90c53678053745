"""Occupancy grids, map files (MovingAI, plain ASCII) and navigation tasks.

Conventions used everywhere in navlearn:

* a *cell* is ``(row, col)``, rows from 0 at the top;
* continuous coordinates are ``(x, y)`` in metres with ``x = col * cell_size``
  and ``y = row * cell_size`` (so ``y`` grows downwards, as rows do); the centre
  of cell ``(r, c)`` is ``((c + 0.5) * cell_size, (r + 0.5) * cell_size)``;
* headings are radians from the +x axis towards +y.

MovingAI scenario files give ``x`` (column) before ``y`` (row); the loaders
convert them to ``(row, col)`` cells.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

Cell = tuple[int, int]

MOVINGAI_FREE = frozenset(".GS")
"""passable terrain of MovingAI maps: ground ``.``/``G`` and swamp ``S`` (passable in the format)"""
MOVINGAI_BLOCKED = frozenset("@OTW")
"""out of bounds ``@``/``O``, trees ``T`` and water ``W`` (not reachable from ground in the format)"""
ASCII_FREE = frozenset(".SG ")
ASCII_BLOCKED = frozenset("#@")


class MapFormatError(ValueError):
    """A map or scenario file that cannot be used; names the file and line."""

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True, eq=False)
class GridMap:
    """A boolean occupancy grid: ``blocked[row, col]`` is True for obstacles."""

    blocked: np.ndarray
    cell_size: float = 1.0
    name: str = ""

    def __post_init__(self) -> None:
        blocked = np.ascontiguousarray(self.blocked, dtype=bool)
        if blocked.ndim != 2 or 0 in blocked.shape:
            raise ValueError(f"blocked must be a non-empty 2-D array, got shape {blocked.shape}")
        if not (np.isfinite(self.cell_size) and self.cell_size > 0):
            raise ValueError(f"cell_size must be positive, got {self.cell_size}")
        blocked.flags.writeable = False
        object.__setattr__(self, "blocked", blocked)

    @property
    def height(self) -> int:
        return int(self.blocked.shape[0])

    @property
    def width(self) -> int:
        return int(self.blocked.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def in_bounds(self, cell: Cell) -> bool:
        r, c = cell
        return 0 <= r < self.height and 0 <= c < self.width

    def is_free(self, cell: Cell) -> bool:
        return self.in_bounds(cell) and not bool(self.blocked[cell[0], cell[1]])

    def free_cells(self) -> np.ndarray:
        """All free cells as an ``(n, 2)`` int array of ``(row, col)``."""
        return np.argwhere(~self.blocked)

    def cell_center(self, cell: Cell) -> tuple[float, float]:
        """``(x, y)`` in metres of the centre of ``cell``."""
        return ((cell[1] + 0.5) * self.cell_size, (cell[0] + 0.5) * self.cell_size)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, GridMap)
            and self.cell_size == other.cell_size
            and np.array_equal(self.blocked, other.blocked)
        )

    def __hash__(self) -> int:
        return hash((self.shape, self.cell_size, self.blocked.tobytes()))


@dataclass(frozen=True)
class Task:
    """One navigation problem: a map, a start cell and a goal cell."""

    grid: GridMap = field(repr=False)
    start: Cell
    goal: Cell
    map_id: str = ""

    def __post_init__(self) -> None:
        for label, cell in (("start", self.start), ("goal", self.goal)):
            if not self.grid.is_free(cell):
                raise ValueError(f"{label} {cell} is blocked or outside the {self.grid.shape} map")


@dataclass(frozen=True)
class Scenario:
    """One line of a MovingAI ``.scen`` file, cells as ``(row, col)``."""

    bucket: int
    map_name: str
    width: int
    height: int
    start: Cell
    goal: Cell
    optimal_length: float


# --------------------------------------------------------------------------- loaders


def _read_lines(path: str | Path) -> list[str]:
    try:
        return Path(path).read_text(encoding="ascii").splitlines()
    except FileNotFoundError:
        raise MapFormatError(path, None, "file not found") from None
    except UnicodeDecodeError as exc:
        raise MapFormatError(path, None, f"not an ASCII text file ({exc.reason})") from None


def _header_int(path: str | Path, lines: list[str], index: int, key: str) -> int:
    if index >= len(lines):
        raise MapFormatError(path, index + 1, f"missing header line '{key} N'")
    parts = lines[index].split()
    if len(parts) != 2 or parts[0] != key or not parts[1].isdigit() or int(parts[1]) <= 0:
        raise MapFormatError(path, index + 1, f"expected '{key} N' with N > 0, got {lines[index]!r}")
    return int(parts[1])


def load_movingai(path: str | Path, cell_size: float = 1.0) -> GridMap:
    """Load a MovingAI ``.map`` file (``type octile``; ``.``/``G``/``S`` free, ``@OTW`` blocked)."""
    lines = _read_lines(path)
    if not lines or lines[0].strip() != "type octile":
        raise MapFormatError(path, 1, "missing header: the first line must be 'type octile'")
    height = _header_int(path, lines, 1, "height")
    width = _header_int(path, lines, 2, "width")
    if len(lines) < 4 or lines[3].strip() != "map":
        raise MapFormatError(path, 4, "missing header line 'map'")
    rows = lines[4:]
    while rows and not rows[-1].strip():
        rows.pop()
    if len(rows) != height:
        raise MapFormatError(path, 4 + len(rows), f"header says height {height}, found {len(rows)} rows")
    blocked = np.zeros((height, width), dtype=bool)
    for r, row in enumerate(rows):
        lineno = r + 5
        if len(row) != width:
            raise MapFormatError(path, lineno, f"row has {len(row)} characters, header says width {width}")
        for c, ch in enumerate(row):
            if ch in MOVINGAI_BLOCKED:
                blocked[r, c] = True
            elif ch not in MOVINGAI_FREE:
                raise MapFormatError(path, lineno, f"unknown map character {ch!r} at column {c}")
    return GridMap(blocked, cell_size=cell_size, name=Path(path).stem)


def load_scenarios(path: str | Path, grid: GridMap | None = None) -> list[Scenario]:
    """Load a MovingAI ``.scen`` file.

    When ``grid`` is given (or the scenario's map file sits beside it), every
    start and goal is checked to be a free cell inside the map.
    """
    lines = _read_lines(path)
    if not lines or lines[0].split() != ["version", "1"]:
        raise MapFormatError(path, 1, "missing header: the first line must be 'version 1'")
    scenarios: list[Scenario] = []
    maps: dict[str, GridMap | None] = {}
    for i, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) != 9:
            raise MapFormatError(path, i, f"expected 9 fields, found {len(fields)}")
        try:
            bucket, width, height, sx, sy, gx, gy = (int(fields[k]) for k in (0, 2, 3, 4, 5, 6, 7))
            optimal = float(fields[8])
        except ValueError:
            raise MapFormatError(path, i, f"non-numeric field in {line!r}") from None
        scen = Scenario(bucket, fields[1], width, height, (sy, sx), (gy, gx), optimal)
        check = grid
        if check is None:
            if scen.map_name not in maps:
                sibling = Path(path).parent / Path(scen.map_name).name
                maps[scen.map_name] = load_movingai(sibling) if sibling.exists() else None
            check = maps[scen.map_name]
        if check is not None:
            if check.shape != (height, width):
                raise MapFormatError(
                    path, i, f"size {width}x{height} does not match the map's {check.width}x{check.height}"
                )
            for label, cell in (("start", scen.start), ("goal", scen.goal)):
                if not check.is_free(cell):
                    raise MapFormatError(path, i, f"{label} (x={cell[1]}, y={cell[0]}) is blocked or outside")
        scenarios.append(scen)
    return scenarios


def parse_ascii(
    text: str, source: str | Path = "<string>", cell_size: float = 1.0
) -> tuple[GridMap, dict[str, Cell]]:
    """Parse the plain ASCII format: ``#``/``@`` blocked, ``.``/space free,
    ``S`` and ``G`` free cells marking start and goal. Returns the map and the markers."""
    rows = [line for line in text.splitlines()]
    while rows and not rows[-1].strip():
        rows.pop()
    if not rows:
        raise MapFormatError(source, 1, "empty map")
    width = len(rows[0])
    blocked = np.zeros((len(rows), width), dtype=bool)
    markers: dict[str, Cell] = {}
    for r, row in enumerate(rows):
        if len(row) != width:
            raise MapFormatError(source, r + 1, f"row has {len(row)} characters, the first row has {width}")
        for c, ch in enumerate(row):
            if ch in ASCII_BLOCKED:
                blocked[r, c] = True
            elif ch not in ASCII_FREE:
                raise MapFormatError(source, r + 1, f"unknown map character {ch!r} at column {c}")
            if ch in "SG":
                if ch in markers:
                    raise MapFormatError(source, r + 1, f"second '{ch}' marker")
                markers[ch] = (r, c)
    return GridMap(blocked, cell_size=cell_size, name=Path(str(source)).stem), markers


def load_ascii(path: str | Path, cell_size: float = 1.0) -> GridMap:
    """Load a plain ASCII map file (see :func:`parse_ascii`)."""
    return parse_ascii("\n".join(_read_lines(path)), path, cell_size)[0]


def load_ascii_task(path: str | Path, cell_size: float = 1.0) -> Task:
    """Load an ASCII map whose ``S`` and ``G`` markers give the start and goal."""
    grid, markers = parse_ascii("\n".join(_read_lines(path)), path, cell_size)
    for key in "SG":
        if key not in markers:
            raise MapFormatError(path, None, f"no '{key}' marker in the map")
    if not connected(grid, markers["S"], markers["G"]):
        raise MapFormatError(path, None, "start and goal are not connected")
    return Task(grid, markers["S"], markers["G"], map_id=grid.name)


def to_ascii(grid: GridMap, start: Cell | None = None, goal: Cell | None = None) -> str:
    chars = np.where(grid.blocked, "#", ".")
    if start is not None:
        chars[start] = "S"
    if goal is not None:
        chars[goal] = "G"
    return "\n".join("".join(row) for row in chars) + "\n"


def load_map(path: str | Path, cell_size: float = 1.0) -> GridMap:
    """Load a map file by its format: MovingAI when it starts with ``type``, ASCII otherwise."""
    lines = _read_lines(path)
    if lines and lines[0].startswith("type "):
        return load_movingai(path, cell_size)
    return load_ascii(path, cell_size)


# --------------------------------------------------------------------------- geometry


_FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)
"""4-connectivity (scipy.ndimage.generate_binary_structure(2, 1)); scipy is imported where used, so
importing worlds stays fast."""


def components(grid: GridMap) -> np.ndarray:
    """4-connected components of free space (0 = blocked). A 4-connected path is
    drivable by every motion model in navlearn, so this is the safe notion of
    'connected' for start/goal guarantees."""
    from scipy import ndimage

    labels, _ = ndimage.label(~grid.blocked, structure=_FOUR)
    return labels


def connected(grid: GridMap, a: Cell, b: Cell) -> bool:
    if not (grid.is_free(a) and grid.is_free(b)):
        return False
    labels = components(grid)
    return bool(labels[a] == labels[b])


def clearance(grid: GridMap) -> np.ndarray:
    """Distance in metres from each cell centre to the nearest blocked cell
    centre or the map border (0 on blocked cells)."""
    from scipy import ndimage

    padded = np.pad(~grid.blocked, 1, constant_values=False)
    dist = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
    return (dist * grid.cell_size).astype(np.float32)


def sample_task(
    grid: GridMap,
    rng: np.random.Generator,
    min_distance: float = 0.0,
    min_clearance: float = 0.0,
    max_tries: int = 1000,
) -> Task:
    """Draw a start and goal, free and connected, at least ``min_distance`` metres
    apart, each at least ``min_clearance`` metres from obstacles."""
    labels = components(grid)
    ok = labels > 0
    if min_clearance > 0:
        ok &= clearance(grid) >= min_clearance
    cells = np.argwhere(ok)
    if len(cells) < 2:
        raise ValueError(f"map {grid.name!r} has fewer than two usable free cells")
    for _ in range(max_tries):
        start = cells[rng.integers(len(cells))]
        same = cells[labels[cells[:, 0], cells[:, 1]] == labels[tuple(start)]]
        far = same[np.hypot(*(same - start).T) * grid.cell_size >= max(min_distance, 1e-9)]
        if len(far):
            goal = far[rng.integers(len(far))]
            return Task(grid, (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1])), grid.name)
    raise ValueError(
        f"could not place start and goal {min_distance} m apart on map {grid.name!r} in {max_tries} tries"
    )
