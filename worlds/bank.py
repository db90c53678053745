"""Maps and tasks packed into flat arrays for the compiled kernel.

A :class:`MapBank` holds every map an environment may use (their
:func:`worlds.fields.kernel_field` arrays end to end, with per-map offsets and sizes)
and a table of *entries*: map, start, goal, and the candidate cells for random starts,
goals and disc positions (the free cells of the start's 4-connected region). The first
``n_pool`` entries are the task pools environments draw their episodes from; tasks given
explicitly to ``reset`` are appended after them.

A pool is drawn once from a :class:`worlds.tasks.TaskSampler` with a fixed seed and
shared (read-only) by every environment built from the same spec, so a single env and a
vector env see the same pool, and building 1024 single envs for a baseline costs one pool.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from worlds.fields import kernel_field
from worlds.maps import GridMap, Task, components
from worlds.tasks import TaskSampler

# columns of MapBank.etab, one row per entry (kept together: one cache line per reset)
E_MAP, E_SR, E_SC, E_GR, E_GC, E_COFF, E_CN, E_RESAMPLE, E_MIN_D2, E_LIMIT = range(10)
"""E_MIN_D2: least squared start-goal distance of resampled endpoints, in cells^2, rounded up;
E_LIMIT: the entry's step limit once the kernel has computed it (-1 before, and always for
resampled entries, whose endpoints change every episode; see :func:`worlds.config.step_limit`)"""

MAX_EXTRA_ENTRIES = 4096
"""explicit tasks kept before unused ones are dropped"""


def _min_d2(distance: float, cell_size: float) -> int:
    """E_MIN_D2 of a least distance in metres: squared cells, rounded up."""
    return math.ceil((distance / cell_size) ** 2 - 1e-9)


class MapBank:
    def __init__(self) -> None:
        self.grids: list[GridMap] = []
        self._grid_index: dict[tuple, int] = {}
        self._regions: dict[tuple[int, int], tuple[int, int]] = {}
        self._labels: list[np.ndarray] = []
        self._entry_index: dict[tuple[int, tuple[int, int], tuple[int, int]], int] = {}
        self.n_pool = 0
        self.pool_tasks: list[Task] = []
        self.pool_resample = False
        self.pool_min_distance = 0.0  # metres, or a function of the task
        self.source: TaskSampler | None = None
        self._field: list[np.ndarray] = []
        self._cand: list[np.ndarray] = []
        self._cand_size = 0
        self._map_size = 0
        self._moff: list[int] = []
        self._entries: list[tuple[int, int, int, int, int, int, int, float, int]] = []
        self.tasks: list[Task] = []  # the task of each entry, as given

    def add_pool(self, tasks: list[Task], resample: bool, min_distance) -> tuple[int, int]:
        """Append a task pool (before any explicit task); returns its (first entry, size).
        ``min_distance``: metres, or a function of the task (pools mixing map sizes)."""
        if len(self._entries) != self.n_pool:
            raise RuntimeError("pools must be added before explicit tasks")
        first = len(self._entries)
        for task in tasks:
            self._add_entry(task, resample, min_distance(task) if callable(min_distance) else min_distance)
        self.n_pool = len(self._entries)
        self._pack()
        return first, len(tasks)

    # ------------------------------------------------------------------ building
    def _map_index(self, grid: GridMap) -> int:
        key = (grid.shape, grid.cell_size, grid.blocked.tobytes())  # same map built twice shares a slot
        if key in self._grid_index:
            return self._grid_index[key]
        m = len(self.grids)
        self.grids.append(grid)
        self._grid_index[key] = m
        field = kernel_field(grid).ravel()
        self._field.append(field)
        self._labels.append(components(grid))
        self._moff.append(self._map_size)
        self._map_size += field.size
        return m

    def _region(self, m: int, start: tuple[int, int]) -> tuple[int, int]:
        label = int(self._labels[m][start])
        if (m, label) not in self._regions:
            cells = np.flatnonzero(self._labels[m].ravel() == label).astype(np.int32)
            self._regions[(m, label)] = (self._cand_size, len(cells))
            self._cand.append(cells)
            self._cand_size += len(cells)
        return self._regions[(m, label)]

    def _add_entry(self, task: Task, resample: bool, min_distance: float) -> int:
        m = self._map_index(task.grid)
        key = (m, task.start, task.goal)
        if key in self._entry_index and not resample:
            return self._entry_index[key]
        c_off, c_n = self._region(m, task.start)
        self._entries.append((m, *task.start, *task.goal, c_off, c_n, min_distance, int(resample)))
        self.tasks.append(task)
        index = len(self._entries) - 1
        if not resample:
            self._entry_index[key] = index
        return index

    def _pack(self) -> None:
        self.field = np.concatenate(self._field)
        self.moff = np.asarray(self._moff, dtype=np.int64)
        self.mh = np.asarray([g.height for g in self.grids], dtype=np.int64)
        self.mw = np.asarray([g.width for g in self.grids], dtype=np.int64)
        self.mcell = np.asarray([g.cell_size for g in self.grids], dtype=np.float64)
        self.cand = np.concatenate(self._cand)
        rows = [(m, sr, sc, gr, gc, coff, cn, res, _min_d2(mind, self.grids[m].cell_size), -1)
                for m, sr, sc, gr, gc, coff, cn, mind, res in self._entries]  # fmt: skip
        self.etab = np.asarray(rows, dtype=np.int32).reshape(-1, 10)
        self.emap = self.etab[:, 0].astype(np.int64)

    # ------------------------------------------------------------------ use
    def add_tasks(self, tasks: list[Task], in_use: np.ndarray) -> tuple[list[int], np.ndarray | None]:
        """Entries for explicit tasks (used as given, never resampled). When too many extras
        piled up, extras not in ``in_use`` are dropped first; the returned array (or None)
        then maps old entry indices to new ones for the caller's robots."""
        remap = None
        if len(self._entries) - self.n_pool + len(tasks) > MAX_EXTRA_ENTRIES:
            remap = self._drop_unused(in_use)
        indices = [self._add_entry(t, False, 0.0) for t in tasks]
        self._pack()
        return indices, remap

    def _drop_unused(self, in_use: np.ndarray) -> np.ndarray:
        keep = np.zeros(len(self._entries), dtype=bool)
        keep[: self.n_pool] = True
        keep[np.asarray(in_use, dtype=np.int64)] = True
        remap = np.cumsum(keep) - 1
        self._entries = [e for e, k in zip(self._entries, keep, strict=True) if k]
        self.tasks = [t for t, k in zip(self.tasks, keep, strict=True) if k]
        self._entry_index = {key: int(remap[i]) for key, i in self._entry_index.items() if keep[i]}
        return remap

    def entry_task(self, index: int, start: tuple[int, int], goal: tuple[int, int]) -> Task:
        """Entry ``index``'s task, or the same map with another ``start``/``goal`` (resampled)."""
        task = self.tasks[index]
        if (task.start, task.goal) == (start, goal):
            return task
        return Task(task.grid, start, goal, task.map_id)

    @property
    def max_cells(self) -> int:
        """Padded cells of the largest map (the size of the kernel's A* work arrays)."""
        return max((g.height + 2) * (g.width + 2) for g in self.grids)

    def kernel_maps(self) -> tuple:
        return (self.field, self.moff, self.mh, self.mw, self.mcell)

    def kernel_entries(self) -> tuple:
        return (self.etab, self.cand)


_POOLS: OrderedDict[tuple, MapBank] = OrderedDict()
_POOL_CACHE_SIZE = 8


def pool_bank(sampler: TaskSampler, size: int, seed: int) -> MapBank:
    """The bank of ``sampler``'s task pool: its tasks when finite, else ``size`` draws, draw ``k``
    with ``np.random.default_rng([seed, k])``. Cached per (spec, size, seed) for samplers built
    from a spec, per sampler object otherwise. Share it read-only (see :func:`private_copy`)."""
    key = (sampler.cache_key if sampler.cache_key is not None else id(sampler), size, seed)
    cached = _POOLS.get(key)
    if cached is not None and (sampler.cache_key is not None or cached.source is sampler):
        _POOLS.move_to_end(key)
        return cached
    if sampler.tasks:
        tasks = list(sampler.tasks)
    elif sampler.draw_pool is not None:
        tasks = sampler.draw_pool(size, seed)
    else:
        tasks = [sampler(np.random.default_rng([seed, k])) for k in range(size)]
    bank = MapBank()
    bank.add_pool(tasks, sampler.resample, sampler.min_distance_of)
    bank.pool_tasks, bank.pool_resample, bank.pool_min_distance = (
        tasks,
        sampler.resample,
        sampler.min_distance_of,
    )
    bank.source = sampler
    _POOLS[key] = bank
    while len(_POOLS) > _POOL_CACHE_SIZE:
        _POOLS.popitem(last=False)
    return bank


def private_copy(bank: MapBank) -> MapBank:
    """A bank that can take extra tasks without touching the shared one (lists copied,
    packed arrays rebuilt on the next add)."""
    clone = object.__new__(MapBank)
    clone.__dict__.update(bank.__dict__)
    for name in ("grids", "_field", "_cand", "_moff", "_entries", "_labels", "tasks"):
        setattr(clone, name, list(getattr(bank, name)))
    for name in ("_grid_index", "_regions", "_entry_index"):
        setattr(clone, name, dict(getattr(bank, name)))
    return clone


def merged_bank(samplers: list[TaskSampler], size: int, seed: int) -> tuple[MapBank, np.ndarray, np.ndarray]:
    """One bank holding the pools of several samplers (one per robot, repeats shared);
    returns it with each robot's (first pool entry, pool size)."""
    pools = [pool_bank(s, size, seed) for s in samplers]
    if all(p is pools[0] for p in pools):
        lo, n = 0, pools[0].n_pool
        return pools[0], np.full(len(samplers), lo, dtype=np.int64), np.full(len(samplers), n, dtype=np.int64)
    bank = MapBank()
    ranges: dict[int, tuple[int, int]] = {}
    for p in pools:
        if id(p) not in ranges:
            ranges[id(p)] = bank.add_pool(p.pool_tasks, p.pool_resample, p.pool_min_distance)
    lo = np.asarray([ranges[id(p)][0] for p in pools], dtype=np.int64)
    n = np.asarray([ranges[id(p)][1] for p in pools], dtype=np.int64)
    return bank, lo, n
