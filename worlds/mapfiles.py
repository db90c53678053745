"""Map files as users bring them: ROS map_server YAML + image, MovingAI ``.map`` (+ ``.scen``), ASCII.

One entry point, :func:`load_map_file`, turns any of them into a :class:`MapFile`: the occupancy
grid at the world's cell size, the file's own resolution and origin, and the start/goal pairs the
file carries (a MovingAI ``.scen`` beside the map, ASCII ``S``/``G`` markers). :func:`map_paths`
expands a spec's path part (a file or a directory) into the files of a training set.

**ROS map_server** (nav2's ``map_io``; https://docs.nav2.org/configuration/packages/configuring-map-server.html):
the YAML (read with PyYAML) names ``image`` (relative to the YAML), ``resolution`` (m per pixel),
``origin`` ``[x, y, yaw]`` (the pose of the lower-left pixel in the ROS map frame), ``negate``,
``occupied_thresh``, ``free_thresh`` and ``mode`` (``trinary`` default, ``scale``, ``raw``). The
image (PGM, PNG, anything Pillow reads) is read with Pillow; a pixel's shade ``p`` is the mean of its
colour channels over 255, its occupancy ``occ = 1 - p`` (``p`` with ``negate``). trinary and scale:
``occ > occupied_thresh`` is occupied, ``occ < free_thresh`` free, anything else unknown (scale
also makes pixels with alpha below opaque unknown). raw: the pixel value itself is the occupancy in
percent, 0 free, 1-100 occupied, anything else unknown. Unknown cells are blocked unless
``unknown="free"``: a robot should not plan through space nobody has seen. The image's top row is
row 0 of the grid, as navlearn's rows run (ROS's y runs up: :func:`MapFile.to_ros` converts).

**Cell size** (:func:`choose_factor`): the world keeps the map's metric size. Its cells are ``k``
file cells on a side, ``k`` the largest integer with ``k * resolution <= robot radius / 2`` (at least
1; ``cell_size`` asks for another size, rounded down to a multiple of the resolution): the robot's
radius then spans at least two cells, so a door the robot fits through stays open, while a 384x384
SLAM map at 0.05 m becomes 192x192 cells instead of a grid the robot's own-map planner crawls over.
Resampling is conservative (:func:`coarsen`): a world cell is blocked when any of its file cells is,
so no wall disappears; it may narrow a gap by up to one world cell on each side. The choice and its
reason are in :attr:`MapFile.note`, which every command prints. MovingAI and ASCII files have no
resolution: a cell is ``resolution`` metres (default 1 m, MovingAI's convention), never resampled.

**Your robot's size** (``radius``): every navlearn world runs one robot, :class:`worlds.config.RobotConfig`'s
(radius :data:`WORLD_RADIUS`, 0.25 m, a 0.5 m step, 6 m rays), the one its policies were trained with.
A map for a robot of another radius is read *scaled* by ``WORLD_RADIUS / radius``
(:attr:`MapFile.scale`): a TurtleBot3 Burger's map (``radius=0.105``) becomes a world 2.38 times as
big, in which the world's robot stands for the Burger, its step for 0.21 m and its rays for 2.5 m.
A policy reads every length over its sensor's range (readings, goal and subgoal distances), its
shield and the baselines work in the world's metres, and success, SPL and step limits are ratios, so
this is the same task as a robot and sensor scaled down on the file's map, without a second set of
robot settings to keep in step with the policy's. The world's metres (path lengths, A* distances)
are the file's times :attr:`MapFile.scale`; ``min_distance``, ``max_distance`` and ``cell_size`` are
given in the file's metres and scaled with it. At the default radius the scale is 1 and nothing
changes.

**Usable**: a map needs two free cells, 4-connected through cells the robot's disc fits on
(:func:`worlds.pairs.robot_cells`); otherwise it is one :class:`MapFormatError` naming the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from worlds.config import RobotConfig
from worlds.maps import GridMap, MapFormatError, Scenario, load_movingai, load_scenarios, parse_ascii
from worlds.pairs import check_usable

MAP_SUFFIXES = (".yaml", ".yml", ".map", ".txt", ".ascii")
"""files a directory contributes to a training set (a ``.scen`` is read beside its ``.map``)"""
MODES = ("trinary", "scale", "raw")
UNKNOWN = ("blocked", "free")
FREE, OCCUPIED, UNKNOWN_CELL = 0, 100, -1
WORLD_RADIUS = RobotConfig().radius
"""the radius (m) of the robot every world runs; a map for another robot is scaled by
``WORLD_RADIUS / radius`` (see the module docstring)"""


@dataclass(frozen=True, eq=False)
class MapFile:
    """A loaded map file: the world's grid and what the file says besides."""

    grid: GridMap
    path: Path
    resolution: float
    """metres per cell of the file (MovingAI/ASCII: the ``resolution`` given, default 1)"""
    factor: int = 1
    """file cells per world cell on a side"""
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """ROS pose ``(x, y, yaw)`` of the lower-left pixel (map_server); zeros for other formats"""
    scenarios: list[Scenario] = field(default_factory=list)
    """start/goal pairs the file carries (MovingAI ``.scen`` beside the map; ASCII S/G markers)"""
    note: str = ""
    """what cell size the world uses and why (printed by every command that loads the map)"""
    scale: float = 1.0
    """world metres per metre of the file: :data:`WORLD_RADIUS` over the robot radius the map was
    loaded for (1 for the world's own robot)"""

    def to_ros(self, x: float, y: float) -> tuple[float, float]:
        """World coordinates (m, y down from the top row) as ROS map-frame coordinates (yaw ignored,
        as most of ROS does; the file's metres, :attr:`scale` undone)."""
        height = self.grid.height * self.grid.cell_size
        return (self.origin[0] + x / self.scale, self.origin[1] + (height - y) / self.scale)


# --------------------------------------------------------------------------- map_server


def _yaml_field(path: Path, data: dict, key: str, kind, default=None):
    if key not in data:
        if default is None:
            raise MapFormatError(path, None, f"missing field '{key}' (map_server YAMLs need it)")
        return default
    value = data[key]
    try:
        if kind is float:
            out = float(value)
            if not math.isfinite(out):
                raise ValueError
            return out
        return kind(value)
    except (TypeError, ValueError):
        raise MapFormatError(path, None, f"field '{key}': {value!r} is not a {kind.__name__}") from None


def read_map_server(path: str | Path) -> tuple[np.ndarray, float, tuple[float, float, float]]:
    """Occupancy of a map_server map as nav2 loads it: ``(cells, resolution, origin)`` with cells
    0 free, 100 occupied, 1-99 (scale/raw) in between, -1 unknown; rows from the image's top."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MapFormatError(path, None, "file not found") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise MapFormatError(path, None, f"not a YAML file ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise MapFormatError(path, None, "not a map_server YAML: expected a mapping (image, resolution, ...)")
    image = _yaml_field(path, data, "image", str)
    resolution = _yaml_field(path, data, "resolution", float)
    if resolution <= 0:
        raise MapFormatError(path, None, f"field 'resolution': {resolution} must be > 0 (metres per pixel)")
    origin = data.get("origin", [0.0, 0.0, 0.0])
    if not (isinstance(origin, list | tuple) and len(origin) == 3):
        raise MapFormatError(path, None, f"field 'origin': {origin!r} must be [x, y, yaw]")
    try:
        origin = tuple(float(v) for v in origin)
    except (TypeError, ValueError):
        raise MapFormatError(path, None, f"field 'origin': {origin!r} must hold three numbers") from None
    negate = _yaml_field(path, data, "negate", int, 0)
    if negate not in (0, 1):
        raise MapFormatError(path, None, f"field 'negate': {negate} must be 0 or 1")
    occupied = _yaml_field(path, data, "occupied_thresh", float, 0.65)
    free = _yaml_field(path, data, "free_thresh", float, 0.196)
    for key, value in (("occupied_thresh", occupied), ("free_thresh", free)):
        if not 0.0 <= value <= 1.0:
            raise MapFormatError(path, None, f"field '{key}': {value} is out of range [0, 1]")
    if free > occupied:
        raise MapFormatError(path, None, f"field 'free_thresh': {free} is above occupied_thresh {occupied}")
    mode = str(data.get("mode", "trinary")).lower()
    if mode not in MODES:
        raise MapFormatError(path, None, f"field 'mode': {mode!r}; choose one of {', '.join(MODES)}")
    image_path = Path(image) if Path(image).is_absolute() else path.parent / image
    try:
        with Image.open(image_path) as img:
            img.load()
            bands = img.getbands()
            alpha = np.asarray(img.getchannel("A"), dtype=np.uint8) if "A" in bands else None
            if img.mode in ("1", "L", "P", "I", "I;16", "F") or img.mode.startswith("I;"):
                values = np.asarray(img.convert("L") if img.mode in ("1", "P") else img, dtype=np.float64)
                if img.mode not in ("1", "L", "P"):
                    values = np.clip(values, 0, 255)
            else:
                colour = np.asarray(img.convert("RGB"), dtype=np.float64)
                values = colour.mean(axis=2)
    except FileNotFoundError:
        raise MapFormatError(path, None, f"field 'image': {image_path} not found") from None
    except (UnidentifiedImageError, OSError) as exc:
        why = f"field 'image': {image_path} is not an image Pillow reads ({exc})"
        raise MapFormatError(path, None, why) from None
    shade = values / 255.0
    occ = shade if negate else 1.0 - shade
    cells = np.full(shade.shape, UNKNOWN_CELL, dtype=np.int16)
    if mode == "raw":
        raw = np.rint(values)
        ok = (raw >= FREE) & (raw <= OCCUPIED)
        cells[ok] = raw[ok]
    else:
        cells[occ > occupied] = OCCUPIED
        cells[occ < free] = FREE
        if mode == "scale":
            between = (occ >= free) & (occ <= occupied)
            span = max(occupied - free, 1e-12)
            cells[between] = np.rint((occ[between] - free) / span * 100.0)
            if alpha is not None:
                cells[alpha < 255] = UNKNOWN_CELL
    return cells, resolution, origin


def occupancy_blocked(cells: np.ndarray, unknown: str = "blocked") -> np.ndarray:
    """Blocked cells of a map_server occupancy: anything but free (0) is blocked, except unknown
    cells (-1) with ``unknown="free"``. (Scale/raw values 1-99 are partly occupied: blocked.)"""
    if unknown not in UNKNOWN:
        raise ValueError(f"unknown cells must be one of {UNKNOWN}, got {unknown!r}")
    blocked = cells != FREE
    if unknown == "free":
        blocked &= cells != UNKNOWN_CELL
    return blocked


# --------------------------------------------------------------------------- cell size


def choose_factor(resolution: float, radius: float, cell_size: float | None = None) -> tuple[int, str]:
    """File cells per world cell (see the module docstring) and a sentence saying why."""
    if cell_size is not None:
        if not (math.isfinite(cell_size) and cell_size > 0):
            raise ValueError(f"cell size must be a positive number of metres, got {cell_size}")
        k = max(1, math.floor(cell_size / resolution + 1e-9))
        why = f"asked for {cell_size:g} m"
    else:
        k = max(1, math.floor(radius / 2 / resolution + 1e-9))
        why = f"the largest multiple of the resolution up to half the robot radius ({radius:g} m / 2)"
    return k, f"cells of {k * resolution:g} m = {k} x {resolution:g} m ({why})"


def coarsen(blocked: np.ndarray, k: int) -> np.ndarray:
    """``k`` x ``k`` blocks of ``blocked`` as one cell, blocked when any of its cells is (the last
    row/column of blocks, if partial, is padded with blocked cells): no wall disappears."""
    if k == 1:
        return np.ascontiguousarray(blocked, dtype=bool)
    h, w = blocked.shape
    hh, ww = -(-h // k), -(-w // k)
    padded = np.ones((hh * k, ww * k), dtype=bool)
    padded[:h, :w] = blocked
    return padded.reshape(hh, k, ww, k).any(axis=(1, 3))


# --------------------------------------------------------------------------- any file


def _is_movingai(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(5) == b"type "
    except OSError:
        return False


def load_map_file(
    path: str | Path,
    *,
    radius: float = WORLD_RADIUS,
    cell_size: float | None = None,
    unknown: str = "blocked",
    resolution: float = 1.0,
) -> MapFile:
    """Load a map file by its format: ``.yaml``/``.yml`` map_server, a file starting ``type `` MovingAI
    (with the ``<name>.map.scen`` or ``<name>.scen`` beside it), anything else ASCII. ``radius`` is
    the robot's (m): the map is scaled by ``WORLD_RADIUS / radius`` (the module docstring), then the
    cell-size rule and the usability check take the world's robot; ``cell_size`` overrides the rule
    for map_server maps; ``resolution`` is the metres per cell of MovingAI/ASCII files (both in the
    file's metres). Raises one :class:`MapFormatError` naming the file (and field or line) on
    anything unusable."""
    path = Path(path)
    if not path.is_file():
        raise MapFormatError(path, None, "file not found" if not path.exists() else "not a file")
    if not (math.isfinite(resolution) and resolution > 0):
        raise MapFormatError(path, None, f"resolution {resolution} must be a positive number of metres")
    if not (math.isfinite(radius) and radius > 0):
        raise MapFormatError(path, None, f"robot radius {radius} must be a positive number of metres")
    scale = WORLD_RADIUS / radius
    if path.suffix.lower() in (".yaml", ".yml"):
        cells, res, origin = read_map_server(path)
        k, note = choose_factor(res * scale, WORLD_RADIUS, None if cell_size is None else cell_size * scale)
        blocked = coarsen(occupancy_blocked(cells, unknown), k)
        grid = GridMap(blocked, cell_size=k * res * scale, name=path.stem)
        h, w = cells.shape
        note = f"{path}: {w}x{h} pixels of {res:g} m -> {grid.width}x{grid.height} {note}"
        result = MapFile(grid, path, res, k, origin, [], note, scale)
    elif _is_movingai(path):
        grid = load_movingai(path, cell_size=resolution * scale)
        scen = next((p for p in (Path(f"{path}.scen"), path.with_suffix(".scen")) if p.is_file()), None)
        scenarios = load_scenarios(scen, grid) if scen is not None else []
        note = f"{path}: {grid.width}x{grid.height} cells of {grid.cell_size:g} m (MovingAI, not resampled)"
        if scen is not None:
            note += f", {len(scenarios)} scenarios from {scen.name}"
        result = MapFile(grid, path, resolution, 1, (0.0, 0.0, 0.0), scenarios, note, scale)
    else:
        try:
            text = path.read_text(encoding="ascii")
        except UnicodeDecodeError as exc:
            why = f"not an ASCII map, a MovingAI map or a map_server YAML ({exc.reason})"
            raise MapFormatError(path, None, why) from None
        grid, markers = parse_ascii(text, path, resolution * scale)
        scenarios = []
        if "S" in markers and "G" in markers:
            marked = Scenario(0, path.name, grid.width, grid.height, markers["S"], markers["G"], math.nan)
            scenarios = [marked]
        note = f"{path}: {grid.width}x{grid.height} cells of {grid.cell_size:g} m (ASCII, not resampled)"
        result = MapFile(grid, path, resolution, 1, (0.0, 0.0, 0.0), scenarios, note, scale)
    if scale != 1.0:
        result = replace(result, note=result.note + f"; {scaled(radius)}")
    check_usable(result.grid, WORLD_RADIUS, path, scale)
    return result


def scaled(radius: float) -> str:
    """What the note of a map loaded for a robot of ``radius`` says of its scale."""
    return (
        f"scaled x{WORLD_RADIUS / radius:.4g} for a robot of radius {radius:g} m, for which the world's "
        f"robot ({WORLD_RADIUS:g} m) stands: world metres are the file's x{WORLD_RADIUS / radius:.4g}"
    )


def map_paths(path: str | Path) -> list[Path]:
    """The map files of ``path``: itself when a file, else the files with :data:`MAP_SUFFIXES`
    directly in the directory, sorted by name (a ``.scen`` is used beside its map, not listed)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in MAP_SUFFIXES)
        if not files:
            raise MapFormatError(path, None, f"directory holds no map files ({', '.join(MAP_SUFFIXES)})")
        return files
    if not path.exists():
        raise MapFormatError(path, None, "file not found")
    return [path]
