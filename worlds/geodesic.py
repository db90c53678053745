"""The geodesic reward's distance field, one paused Dijkstra per robot, with a bucket queue.

The reward (``rewards.geodesic_progress``, :mod:`worlds.perception`) needs the true shortest-path
distance from the robot's cell to the goal at every step (8-connected, no corner cutting: the
moves of :mod:`worlds.gridsearch`). The Dijkstra from the goal runs on the kernel's map field (its
padded layout, :mod:`worlds.gridsearch`), is paused once the robot's cell is settled and resumed
when the robot reaches a cell not settled yet.

**Bucket queue.** Every move costs at least 1 cell, so cells whose distance has the same integer
part cannot improve one another: the search takes cells bucket by bucket (bucket k holds the
reached cells with ``floor(g) = k``), in any order within a bucket, with no heap. When bucket
``b`` is being taken, every bucket below it is empty, so a reached cell in bucket ``b`` or below
is settled: its shortest path's last step comes from a cell at least 1 nearer, already taken.
A move costs less than 2, so the reached cells lie in buckets ``b .. b + 2``, kept in a ring of
4 stacks; a cell that improves into a lower bucket is pushed again and its old entry skipped.
Each settled distance is the least of ``g[u] + step`` over the neighbours ``u`` settled before it
(the floating-point sums of any Dijkstra), so the distances are those of
:func:`worlds.gridsearch.grid_search`'s Dijkstra, bit for bit (``tests/test_worlds_gridsearch.py``),
paused or not.

The moves out of each cell (which of its 8 neighbours it may step to: free, no corner cut) are
read from a table made once per bank of maps (:func:`move_masks`), one byte per cell, instead of
up to 8 cells of the field per taken cell.

``geo = (g, mark, ring, count, meta)``, one row per robot: distances, the cells' generation
stamps (``2 * generation`` once reached, ``+ 1`` once taken), the ring's stacks ``(4, cells)`` and
sizes ``(4,)``, and ``meta = (generation, current bucket)``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.fields import BLOCKED
from worlds.gridsearch import SQRT2

GEN, BUCKET = 0, 1
"""indices into a row of ``meta``"""
EVERY_CELL = np.int64(-1)
"""_settle's ``target`` for "settle every reachable cell", a numpy scalar: a literal -1 would
compile _settle a second time"""


def new_fields(n: int, cells: int) -> tuple:
    """Work rows ``geo`` for ``n`` robots on maps of up to ``cells`` padded cells."""
    i4 = np.int32
    return (np.zeros((n, cells)), np.zeros((n, cells), i4), np.zeros((n, 4, cells), i4), np.zeros((n, 4), i4),
            np.zeros((n, 2), i4))  # fmt: skip


@njit(cache=True)
def move_masks(field, moff, mh, mw):
    """Per padded cell of every map in ``field`` (kernel field layout, maps at ``moff``): a byte whose
    bit k says the move k is allowed (0-3: up, down, left, right; 4-7: up-left, up-right,
    down-left, down-right, which also need both cells they brush past free); 0 on the ring."""
    moves = np.zeros(field.shape[0], np.uint8)
    for m in range(moff.shape[0]):
        base, stride = moff[m], mw[m] + 2
        for r in range(1, mh[m] + 1):
            for c in range(1, mw[m] + 1):
                at = base + r * stride + c
                if field[at] == BLOCKED:
                    continue
                up, down = field[at - stride] != BLOCKED, field[at + stride] != BLOCKED
                left, right = field[at - 1] != BLOCKED, field[at + 1] != BLOCKED
                bits = (1 if up else 0) | (2 if down else 0) | (4 if left else 0) | (8 if right else 0)
                if up and left and field[at - stride - 1] != BLOCKED:
                    bits |= 16
                if up and right and field[at - stride + 1] != BLOCKED:
                    bits |= 32
                if down and left and field[at + stride - 1] != BLOCKED:
                    bits |= 64
                if down and right and field[at + stride + 1] != BLOCKED:
                    bits |= 128
                moves[at] = bits
    return moves


@njit(cache=True)
def _offer(g, mark, ring, count, gen, node, cand):
    """Reach ``node`` (not taken yet) at distance ``cand`` if that is new or shorter (pushed into its
    bucket's stack unless it stays in the same bucket)."""
    if mark[node] == 2 * gen:
        if not cand < g[node]:
            return
        same = int(g[node]) == int(cand)
        g[node] = cand
        if same:
            return
    else:
        mark[node] = 2 * gen
        g[node] = cand
    slot = int(cand) & 3
    ring[slot, count[slot]] = node
    count[slot] += 1


@njit(cache=True, _nrt=False)
def _settle(moves, base, stride, target, g, mark, ring, count, meta):
    """Take cells until ``target`` is settled (``target < 0``: until every reachable cell is)."""
    gen, b = meta[GEN], meta[BUCKET]
    taken = 2 * gen + 1
    while not (target >= 0 and mark[target] >= 2 * gen and int(g[target]) <= b):
        slot = b & 3
        if count[slot] == 0:
            if count[(b + 1) & 3] == 0 and count[(b + 2) & 3] == 0:
                break  # every reachable cell is settled
            b += 1
            continue
        count[slot] -= 1
        node = ring[slot, count[slot]]
        if mark[node] == taken or int(g[node]) != b:
            continue  # taken already, or moved to a lower bucket
        mark[node] = taken
        one, diag, bits = g[node] + 1.0, g[node] + SQRT2, moves[base + node]
        if bits & 1 and mark[node - stride] != taken:
            _offer(g, mark, ring, count, gen, node - stride, one)
        if bits & 2 and mark[node + stride] != taken:
            _offer(g, mark, ring, count, gen, node + stride, one)
        if bits & 4 and mark[node - 1] != taken:
            _offer(g, mark, ring, count, gen, node - 1, one)
        if bits & 8 and mark[node + 1] != taken:
            _offer(g, mark, ring, count, gen, node + 1, one)
        if bits & 16 and mark[node - stride - 1] != taken:
            _offer(g, mark, ring, count, gen, node - stride - 1, diag)
        if bits & 32 and mark[node - stride + 1] != taken:
            _offer(g, mark, ring, count, gen, node - stride + 1, diag)
        if bits & 64 and mark[node + stride - 1] != taken:
            _offer(g, mark, ring, count, gen, node + stride - 1, diag)
        if bits & 128 and mark[node + stride + 1] != taken:
            _offer(g, mark, ring, count, gen, node + stride + 1, diag)
    meta[BUCKET] = b


@njit(cache=True, _nrt=False)
def start_field(moves, base, stride, goal, geo, i, reuse):
    """Start robot ``i``'s distance field on its true map (at ``base`` in the table ``moves`` of
    :func:`move_masks`): a Dijkstra from padded cell ``goal``. With ``reuse`` it is only started
    (:func:`field_distance` runs it on as far as each robot cell needs), else run over the whole
    component at once."""
    g, mark, ring, count, meta = geo
    gen = meta[i, GEN] + 1
    if gen >= 2**30 - 1:  # the stamps wrap: forget every cell once
        for k in range(mark.shape[1]):
            mark[i, k] = 0
        gen = 1
    meta[i, GEN], meta[i, BUCKET] = gen, 0
    for slot in range(4):
        count[i, slot] = 0
    _offer(g[i], mark[i], ring[i], count[i], gen, goal, 0.0)
    if not reuse:
        _settle(moves, base, stride, EVERY_CELL, g[i], mark[i], ring[i], count[i], meta[i])


@njit(cache=True, _nrt=False)
def field_distance(moves, base, height, width, geo, i, cell, x, y):
    """Robot ``i``'s true shortest-path distance (m) from the cell under (x, y) to its goal (inf off
    the map or unreachable), searching on until that cell is settled."""
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or r >= height or c >= width:
        return math.inf
    g, mark, ring, count, meta = geo
    stride = width + 2
    node = (r + 1) * stride + c + 1
    _settle(moves, base, stride, node, g[i], mark[i], ring[i], count[i], meta[i])
    return g[i, node] * cell if mark[i, node] >= 2 * meta[i, GEN] else math.inf
