"""Precomputed per-map fields for the compiled kernel.

The *gap* of a free cell ``c`` is ``min over blocked b of hypot(max(0,|dr|-1),
max(0,|dc|-1))`` cells: the exact distance between the squares of ``c`` and ``b``,
with the outside of the map counted as blocked. No blocked point lies within the gap
of *any* point of ``c``, so a ray or a swept disc may skip that far safely. It equals
the centre distance from ``c`` to the blocked set grown by one cell (3x3): moving each
``b`` one cell towards ``c`` along both axes gives a grown cell exactly that far, and
every grown cell is within one cell per axis of a blocked one.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy import ndimage

from worlds.maps import GridMap

_SQUARE = np.ones((3, 3), dtype=bool)


def _padded_gap(grid: GridMap) -> tuple[np.ndarray, np.ndarray]:
    padded = np.pad(grid.blocked, 1, constant_values=True)
    grown = ndimage.binary_dilation(padded, structure=_SQUARE, border_value=1)
    return padded, ndimage.distance_transform_edt(~grown)


def gap_field(grid: GridMap) -> np.ndarray:
    """Gap of every cell in metres, ``(height, width)``, 0 on blocked cells."""
    return _padded_gap(grid)[1][1:-1, 1:-1] * grid.cell_size


BLOCKED = 255
"""kernel field value of a blocked cell"""
GAP_UNIT = 0.25
"""kernel field values of free cells count the gap in quarter cells, rounded down (a safe bound)"""


def kernel_field(grid: GridMap) -> np.ndarray:
    """The map as the kernel reads it: ``(height + 2, width + 2)`` uint8 with a ring of
    blocked cells around it (so a ray always stops inside the array), :data:`BLOCKED` on
    blocked cells and the gap in :data:`GAP_UNIT` cells, rounded down, on free ones. One
    byte per cell keeps a pool of a thousand 16x16 maps in a core's L2 cache, which is what
    the kernel's speed depends on once robots drive different maps."""
    padded, gap = _padded_gap(grid)
    units = np.minimum(np.floor(gap / GAP_UNIT), BLOCKED - 1)
    return np.where(padded, BLOCKED, units).astype(np.uint8)


_RECENT: OrderedDict[int, tuple[GridMap, np.ndarray]] = OrderedDict()


def cached_kernel_field(grid: GridMap) -> np.ndarray:
    """:func:`kernel_field` of ``grid``, flattened, remembered for the last 16 maps (callers such
    as planners cast rays on the same map many times)."""
    hit = _RECENT.get(id(grid))
    if hit is not None and hit[0] is grid:
        _RECENT.move_to_end(id(grid))
        return hit[1]
    field = kernel_field(grid).ravel()
    _RECENT[id(grid)] = (grid, field)
    while len(_RECENT) > 16:
        _RECENT.popitem(last=False)
    return field
