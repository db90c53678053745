"""The reading shield: a learned policy never takes an action its own range readings say hits something.

An action turns the robot in place and drives it ``robot.step`` metres straight ahead
(:mod:`worlds.robot`), so it sweeps the robot's disc along a segment: a capsule of the robot's radius.
Each range reading is the minimum of the rays of its sector (``sensors.n_rays`` per ``n_beams``), so
the readings say that every direction of sector ``j`` is free up to ``reading[j]``. The shield keeps
the policy's choice (the argmax of its Q-values or logits) among the actions whose whole capsule lies
inside that free region: action ``k`` is *clear* when, for every sector ``j``, ``reading[j] >=
reach[k, j]``, the farthest point of the capsule inside sector ``j`` (:func:`reach_table`, computed
once per robot and sensor). When no action is clear (the robot must drive ``step`` every step: there
is no stop), it takes the action that keeps most room, the largest ``min_j(reading[j] - reach[k, j])``.

It reads only the current frame's readings (what a real robot's scan gives, in the world and in
``navlearn drive``), nothing of the true map or the robot's own map. It is a filter at act time, like
the "shielding" of safe RL (Alshiekh et al. 2018, AAAI) or a collision monitor in front of a
controller: the actors of training explore without it (the Q-network learns from its collisions), and
``navlearn evaluate``, ``navlearn drive``, ``world show`` and ``bench/map_sizes.py`` act through it
unless told ``--no-shield``.

Why it exists (issue 39, validation seed 1, same episodes, ``results/navigation/shield/``): the
shipped network's remaining failures on maps of 32-64 cells were collisions with walls, the robot
cutting a wall it could see. The shield turns most of them into successes without retraining
(docs/navigation-by-size.md, section 8). A margin added to the robot's radius was screened on
validation: 0.03 m gained nothing consistent (+1.3 points at 64 cells, -1.0 at 48), 0.06 and 0.1 m
lost, since the robot must move every step and a wider capsule leaves it more often with no clear
action at all; so there is no margin. A two-step look-ahead (first the actions after which some
action is clear again) gained nothing consistent either.

The sector model is the readings' own: a sector's rays are 3.75 degrees apart (24 sectors of 4 rays),
so a corner between two rays can stand closer than the sector's reading. The shield is a filter of
what the robot sees, not a guarantee.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worlds.config import NavConfig
from worlds.perception import frame_layout

ANGLES_PER_SECTOR = 257
"""directions sampled across one sector to find the capsule's farthest point in it (the exit
distance is continuous in the direction; 257 samples of a 15-degree sector are 0.06 degrees apart)"""


def exit_distance(delta: np.ndarray, step: float, radius: float) -> np.ndarray:
    """How far from the robot's centre a ray at angle ``delta`` (rad) from the drive direction leaves
    the capsule swept by driving ``step`` metres with a disc of ``radius``: the largest of the exits
    from its three convex pieces (the start disc, the rectangle, the end disc) that the ray meets.
    The capsule is convex and holds the centre, so every ray leaves it exactly once."""
    c, s = np.cos(delta), np.abs(np.sin(delta))
    out = np.full(np.shape(delta), radius, dtype=np.float64)  # the start disc
    with np.errstate(divide="ignore", invalid="ignore"):
        side = np.where(s > 0, radius / s, np.inf)  # through a long side of the rectangle
        out = np.where((side * c >= 0) & (side * c <= step), np.maximum(out, side), out)
        front = np.where(c > 0, step / c, np.inf)  # through the rectangle's far end
        out = np.where((c > 0) & (front * s <= radius), np.maximum(out, front), out)
        disc = radius**2 - (step * s) ** 2  # through the end disc
        far = step * c + np.sqrt(np.maximum(disc, 0.0))
        out = np.where(disc >= 0, np.maximum(out, far), out)
    return out


def reach_table(nav: NavConfig) -> np.ndarray:
    """``(n_actions, n_beams)``: how far action ``k``'s capsule reaches into sector ``j`` (m), the
    reading sector ``j`` needs for the action to be clear. Sector ``j`` spans ``fov / n_beams``
    centred on ``sensors.beam_angles[j]``, as the kernel casts its rays."""
    robot, sensors = nav.robot, nav.sensors
    if not math.isclose(sensors.fov, 2 * math.pi):
        raise ValueError(
            f"sensors.fov={sensors.fov:.3f}: the reading shield needs readings all round (2*pi), since "
            "a robot that turns up to 90 degrees drives where a narrower field does not look; use "
            "--no-shield"
        )
    half = sensors.fov / sensors.n_beams / 2
    offsets = np.linspace(-half, half, ANGLES_PER_SECTOR)
    table = np.empty((robot.n_actions, sensors.n_beams))
    for k, turn in enumerate(robot.turns):
        for j, centre in enumerate(sensors.beam_angles):
            table[k, j] = exit_distance(centre + offsets - turn, robot.step, robot.radius).max()
    return table


@dataclass(frozen=True)
class ReadingShield:
    """The shield of one robot and sensor (:func:`for_nav`): ``choose(outputs, obs)`` -> actions."""

    reach: np.ndarray
    """``(n_actions, n_beams)`` metres, :func:`reach_table`"""
    readings: slice
    """where the newest frame's readings sit in an observation"""
    max_range: float
    """the readings are in units of it (the kernel writes ``range / max_range``)"""

    def room(self, obs: np.ndarray) -> np.ndarray:
        """``(N, n_actions)``: the least ``reading[j] - reach[k, j]`` over the sectors (m); an action
        is clear where it is >= 0."""
        readings = np.asarray(obs, dtype=np.float64)[:, self.readings] * self.max_range
        return (readings[:, None, :] - self.reach[None]).min(axis=2)

    def choose(self, outputs: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """The argmax of ``outputs`` (N, n_actions) among the clear actions; the roomiest action
        where none is clear."""
        room = self.room(obs)
        clear = room >= 0
        best = np.where(clear, outputs, -np.inf).argmax(axis=1)
        return np.where(clear.any(axis=1), best, room.argmax(axis=1)).astype(np.int64)


def for_nav(nav: NavConfig) -> ReadingShield:
    """The shield of ``nav``'s robot and sensor, reading observations of ``nav``'s layout."""
    a, b = frame_layout(nav)["readings"]
    return ReadingShield(reach_table(nav), slice(a, b), nav.sensors.max_range)
