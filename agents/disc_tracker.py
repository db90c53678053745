"""The disc tracker behind the reading shield: moving things found in the robot's own scan, and kept
clear of where they go next.

The reading shield (:mod:`agents.shield`) reads one frame: it keeps the robot's capsule inside what
the current readings show free, but a moving disc seen where it is now is 0.2 m further on by the
time the robot passes. The tracker looks at two frames of the scan:

- **finding the discs** - the robot's rays in the order the sensor casts them (the world's 96, of
  which the observation keeps the 24 sector minima; a real robot's LaserScan, resampled to the same
  directions by ``navlearn drive``), as a lidar tracker segments them: consecutive ray endpoints
  closer than :data:`JUMP` form a segment; a segment nearer than the rays on both sides of it (by
  :data:`JUMP`: something standing in front of what is behind it) and no wider than a disc (``2 *
  radius + WIDTH_SLACK``) is a disc, centred ``radius`` behind its nearest endpoint;
- **predicting** - a disc's velocity is its last displacement: the nearest of the last frame's
  centres within :data:`MATCH` m, carried into the current robot frame by the robot's commanded
  motion (dead reckoning: what it was told to do, noise-free); a disc with none stands still.
  Its next centre is one more such step;
- **keeping clear** - an action is *disc-clear* when its capsule (turn, then drive ``step``;
  noise-free) never comes within the robot's radius plus the disc's of any disc sweeping from its
  centre to its predicted one (:func:`worlds.obstacles.swept_contact`, the world's own contact
  test). Where the shield's choice is not disc-clear, the robot takes the first disc-clear action
  of: the policy's preference among the actions the readings leave clear, then the turn-around,
  then the others; where none is, the shield's choice stands.

Everything is in the robot's frame; nothing of the true map or of the discs' true state is read.
Why and how it was chosen (issue 39, validation seed 1 only, ``results/navigation/discs/``;
docs/navigation-by-size.md section 13): the shipped shield's remaining failures with 16 discs at
64 cells were the discs. A perfect detector with this predictor reached 97.3% on validation
``dynamic:64`` (the one-frame shield 95.0%); this scan detector 97.0% (+6 / -0 episodes,
McNemar p 0.03), changing no action on ``static:64``; at 16/32/48 cells 98.7/98.7/97.0% against
97.3/98.0/96.7%. Its screen on validation fixed the rule above (the turn-around before the
unclear actions; no margin beyond the radii).

The per-robot loops are compiled with numba (the world's own tool, :mod:`worlds.kernel`): a batch
of 512 robots is tracked every step of an evaluation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.obstacles import swept_contact

JUMP = 0.25
"""metres between consecutive ray endpoints that split the scan into segments"""
WIDTH_SLACK = 0.15
"""metres a disc's segment may be wider than the disc (rays meet its edge obliquely)"""
MATCH = 0.6
"""metres a disc's centre may be from its last-frame centre to be the same disc (a disc moves 0.2 m a
step; the robot's own motion is known only as commanded)"""
MAX_DISCS = 32
"""discs tracked per robot and frame (the nearest first; a scan of 96 rays holds at most 32
segments of three rays)"""


@njit(cache=True)
def detect(ranges, angles, radius, max_range, centres, counts):
    """Per robot, the disc centres found in its scan ``ranges`` ``(n, R)`` (m, rays at ``angles``):
    writes ``centres`` ``(n, K, 2)`` in the robot's frame and ``counts`` ``(n,)``."""
    n, rays = ranges.shape
    capacity = centres.shape[1]
    px = np.empty(rays)
    py = np.empty(rays)
    split = np.empty(rays, np.bool_)  # split[j]: a segment ends at ray j (gap to ray j + 1)
    for i in range(n):
        counts[i] = 0
        first = -1
        for j in range(rays):
            px[j] = ranges[i, j] * math.cos(angles[j])
            py[j] = ranges[i, j] * math.sin(angles[j])
        for j in range(rays):
            k = (j + 1) % rays
            split[j] = math.hypot(px[j] - px[k], py[j] - py[k]) > JUMP
            if split[j] and first < 0:
                first = k
        if first < 0:  # one closed outline: no disc stands apart
            continue
        start = first
        for step in range(rays):
            j = (first + step) % rays
            if not split[j]:
                continue
            members = (j - start) % rays + 1
            nearest, at, farthest = math.inf, start, 0.0
            for m in range(members):
                r = ranges[i, (start + m) % rays]
                if r < nearest:
                    nearest, at = r, (start + m) % rays
                farthest = max(farthest, r)
            before, after = (start - 1) % rays, (j + 1) % rays
            in_front = ranges[i, before] > nearest + JUMP and ranges[i, after] > nearest + JUMP
            width = math.hypot(px[start] - px[j], py[start] - py[j])
            seen = farthest < max_range - 1e-6
            if in_front and seen and width <= 2.0 * radius + WIDTH_SLACK and counts[i] < capacity:
                c = counts[i]
                centres[i, c, 0] = (nearest + radius) * math.cos(angles[at])
                centres[i, c, 1] = (nearest + radius) * math.sin(angles[at])
                counts[i] = c + 1
            start = (j + 1) % rays


@njit(cache=True)
def predict(centres, counts, previous, previous_counts, nxt):
    """Each disc's next centre ``nxt`` ``(n, K, 2)``: one more of its last displacement (the nearest
    previous centre within :data:`MATCH`), or where it is when it has none."""
    for i in range(centres.shape[0]):
        for c in range(counts[i]):
            best, bx, by = math.inf, 0.0, 0.0
            for p in range(previous_counts[i]):  # the nearest (the first of equals)
                gap = math.hypot(centres[i, c, 0] - previous[i, p, 0], centres[i, c, 1] - previous[i, p, 1])
                if gap < best:
                    best = gap
                    bx = centres[i, c, 0] - previous[i, p, 0]
                    by = centres[i, c, 1] - previous[i, p, 1]
            if best > MATCH:  # none near enough: standing
                bx, by = 0.0, 0.0
            nxt[i, c, 0] = centres[i, c, 0] + bx
            nxt[i, c, 1] = centres[i, c, 1] + by


@njit(cache=True)
def disc_clear(centres, counts, nxt, ends, reach, clear):
    """``clear[i, a]``: does action ``a`` (its capsule from the origin to ``ends[a]``) keep robot
    ``i`` clear of every disc's sweep by ``reach`` (the two radii)?"""
    for i in range(centres.shape[0]):
        for a in range(ends.shape[0]):
            ok = True
            for c in range(counts[i]):
                if swept_contact(
                    0.0, 0.0, ends[a, 0], ends[a, 1],
                    centres[i, c, 0], centres[i, c, 1], nxt[i, c, 0], nxt[i, c, 1], reach,
                ):  # fmt: skip
                    ok = False
                    break
            clear[i, a] = ok


@njit(cache=True)
def carry(centres, counts, moves, actions, previous, previous_counts):
    """This frame's centres, seen from the robot after it took ``actions`` (``moves[a]`` = turn,
    forward distance): the next frame's ``previous``."""
    for i in range(centres.shape[0]):
        turn, step = moves[actions[i], 0], moves[actions[i], 1]
        dx, dy = step * math.cos(turn), step * math.sin(turn)
        c, s = math.cos(turn), math.sin(turn)
        for k in range(counts[i]):
            x, y = centres[i, k, 0] - dx, centres[i, k, 1] - dy
            previous[i, k, 0] = c * x + s * y
            previous[i, k, 1] = -s * x + c * y
        previous_counts[i] = counts[i]


class DiscTracker:
    """The discs of ``n`` robots from frame to frame (module docstring). Each step:
    :meth:`observe` the scans (``fresh`` marks robots whose episode starts: nothing carried), then
    :meth:`clear` gives every action's disc-clearance, then :meth:`moved` with the actions taken."""

    def __init__(
        self,
        n: int,
        angles: np.ndarray,
        max_range: float,
        moves: np.ndarray,
        robot_radius: float,
        disc_radius: float,
    ) -> None:
        self.angles = np.asarray(angles, np.float64)
        self.max_range, self.disc_radius = float(max_range), float(disc_radius)
        self.moves = np.asarray(moves, np.float64)
        """``(n_actions + 1, 2)``: each action's turn (rad) and forward distance (m), the turn-around last"""
        turn, step = self.moves[:, 0], self.moves[:, 1]
        self.ends = np.stack([step * np.cos(turn), step * np.sin(turn)], 1)
        """``(n_actions + 1, 2)``: where each action leaves the robot's centre, in its frame"""
        self.reach = float(robot_radius + disc_radius)
        self.centres, self.nxt = np.zeros((n, MAX_DISCS, 2)), np.zeros((n, MAX_DISCS, 2))
        self.previous = np.zeros((n, MAX_DISCS, 2))
        self.counts, self.previous_counts = np.zeros(n, np.int64), np.zeros(n, np.int64)

    def observe(self, rays: np.ndarray, fresh: np.ndarray) -> None:
        """This frame's scans ``(n, R)`` (m, at ``angles``); ``fresh`` ``(n,)`` robots starting an episode."""
        rays = np.ascontiguousarray(rays, dtype=np.float64)
        if rays.shape != (len(self.counts), len(self.angles)):
            raise ValueError(f"expected scans {(len(self.counts), len(self.angles))}, got {rays.shape}")
        self.previous_counts[np.asarray(fresh, bool)] = 0
        detect(rays, self.angles, self.disc_radius, self.max_range, self.centres, self.counts)
        predict(self.centres, self.counts, self.previous, self.previous_counts, self.nxt)

    def clear(self) -> np.ndarray:
        """``(n, n_actions + 1)`` bool: the actions (the turn-around last) clear of every disc's sweep."""
        out = np.empty((len(self.counts), len(self.moves)), np.bool_)
        disc_clear(self.centres, self.counts, self.nxt, self.ends, self.reach, out)
        return out

    def moved(self, actions: np.ndarray) -> None:
        """The robots took ``actions``: carry this frame's discs into their next frame."""
        actions = np.asarray(actions, np.int64)
        carry(self.centres, self.counts, self.moves, actions, self.previous, self.previous_counts)
