"""The geodesic reward's distance field, one paused Dijkstra per robot, with a bucket queue.

The reward (``rewards.geodesic_progress``, :mod:`worlds.perception`) needs the true shortest-path
distance from the robot's cell to the goal at every step (8-connected, no corner cutting: the
moves of :mod:`worlds.gridsearch`). The Dijkstra from the goal runs on the kernel's map field in
place (it has the padded layout of :mod:`worlds.gridsearch`), is paused once the robot's cell is
settled and resumed when the robot reaches a cell not settled yet.

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


def new_fields(n: int, cells: int) -> tuple:
    """Work rows ``geo`` for ``n`` robots on maps of up to ``cells`` padded cells."""
    i4 = np.int32
    return (np.zeros((n, cells)), np.zeros((n, cells), i4), np.zeros((n, 4, cells), i4), np.zeros((n, 4), i4),
            np.zeros((n, 2), i4))  # fmt: skip


@njit(cache=True, inline="always")
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
def _settle(field, base, stride, target, g, mark, ring, count, meta):
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
        at, one, diag = base + node, g[node] + 1.0, g[node] + SQRT2
        up, down = field[at - stride] != BLOCKED, field[at + stride] != BLOCKED
        left, right = field[at - 1] != BLOCKED, field[at + 1] != BLOCKED
        if up and mark[node - stride] != taken:
            _offer(g, mark, ring, count, gen, node - stride, one)
        if down and mark[node + stride] != taken:
            _offer(g, mark, ring, count, gen, node + stride, one)
        if left and mark[node - 1] != taken:
            _offer(g, mark, ring, count, gen, node - 1, one)
        if right and mark[node + 1] != taken:
            _offer(g, mark, ring, count, gen, node + 1, one)
        # a diagonal move needs both cells it brushes past free (no corner cutting)
        if up and left and field[at - stride - 1] != BLOCKED and mark[node - stride - 1] != taken:
            _offer(g, mark, ring, count, gen, node - stride - 1, diag)
        if up and right and field[at - stride + 1] != BLOCKED and mark[node - stride + 1] != taken:
            _offer(g, mark, ring, count, gen, node - stride + 1, diag)
        if down and left and field[at + stride - 1] != BLOCKED and mark[node + stride - 1] != taken:
            _offer(g, mark, ring, count, gen, node + stride - 1, diag)
        if down and right and field[at + stride + 1] != BLOCKED and mark[node + stride + 1] != taken:
            _offer(g, mark, ring, count, gen, node + stride + 1, diag)
    meta[BUCKET] = b


@njit(cache=True, _nrt=False)
def start_field(field, base, stride, goal, geo, i, reuse):
    """Start robot ``i``'s distance field on its true map (the padded field at ``base``): a Dijkstra
    from padded cell ``goal``. With ``reuse`` it is only started (:func:`field_distance` runs it on as
    far as each robot cell needs), else run over the whole component at once."""
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
        _settle(field, base, stride, -1, g[i], mark[i], ring[i], count[i], meta[i])


@njit(cache=True, _nrt=False)
def field_distance(field, base, height, width, geo, i, cell, x, y):
    """Robot ``i``'s true shortest-path distance (m) from the cell under (x, y) to its goal (inf off
    the map or unreachable), searching on until that cell is settled."""
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or r >= height or c >= width:
        return math.inf
    g, mark, ring, count, meta = geo
    stride = width + 2
    node = (r + 1) * stride + c + 1
    _settle(field, base, stride, node, g[i], mark[i], ring[i], count[i], meta[i])
    return g[i, node] * cell if mark[i, node] >= 2 * meta[i, GEN] else math.inf
