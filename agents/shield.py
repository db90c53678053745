"""The reading shield: a learned policy never takes an action its own range readings say hits something.

An action turns the robot in place and drives it ``robot.step`` metres straight ahead
(:mod:`worlds.robot`), so it sweeps the robot's disc along a segment: a capsule of the robot's radius.
Each range reading is the minimum of the rays of its sector (``sensors.n_rays`` per ``n_beams``), so
the readings say that every direction of sector ``j`` is free up to ``reading[j]``. The shield keeps
the policy's choice (the argmax of its Q-values or logits) among the actions whose whole capsule lies
inside that free region: action ``k`` is *clear* when, for every sector ``j``, ``reading[j] >=
reach[k, j]``, the farthest point of the capsule inside sector ``j`` (:func:`reach_table`, computed
once per robot and sensor). It first asks for 0.1 m to spare (:data:`MARGINS`: the capsule of a
radius grown by 0.1 m), then for the capsule alone. When no action is clear even so (every action
drives ``step`` and turns at most ``max_turn``, so a robot in a pocket has none), it takes the
robot's turn-around (``RobotConfig.turn_around``: half a turn in place, no drive), which sweeps
nothing and faces the way the robot came.

It reads only the current frame's readings (what a real robot's scan gives, in the world and in
``navlearn drive``), nothing of the true map or the robot's own map. It is a filter at act time, like
the "shielding" of safe RL (Alshiekh et al. 2018, AAAI) or a collision monitor in front of a
controller: the actors of training explore without it (the Q-network learns from its collisions), and
``navlearn evaluate``, ``navlearn drive``, ``world show`` and ``bench/map_sizes.py`` act through it
unless told ``--no-shield``.

Why it exists (issue 39, validation seed 1, same episodes, ``results/navigation/shield/``): the
shipped network's remaining failures on maps of 32-64 cells were collisions with walls, the robot
cutting a wall it could see. Reading its own frame, the shield turns most of them into successes
without retraining (docs/navigation-by-size.md, section 8). Its two settings were screened on
validation only (``results/navigation/shield/screen_turn_around.jsonl``):

- the turn-around, against the roomiest action when nothing is clear: the robot that must drive
  into its least-bad option hits something; turned round, it drives back out. At 64 cells: 93.7 ->
  95.3% static;
- the margin, once the turn-around exists (without it a margin lost, since a wider capsule leaves
  the robot more often with nothing clear): 0.1 m first, then none, was the best sum over the eight
  sets (16-64 cells, static and with discs; 0.03, 0.06, 0.1, 0.15 and 0.2 m tried, and 0.2 then
  0.1 m). A disc seen where it is moves up to ``speed`` before the robot passes, so room to spare
  helps most with discs: 89.3 -> 91.0% at 64 cells, 92.3 -> 97.0% at 48.

The sector model is the readings' own: a sector's rays are 3.75 degrees apart (24 sectors of 4 rays),
so a corner between two rays can stand closer than the sector's reading. The shield is a filter of
what the robot sees, not a guarantee.

Behind it stands the disc tracker (:mod:`agents.disc_tracker`): moving discs found in two frames of
the robot's scan and an action's capsule kept clear of where they go next. It needs the scan's rays
and the robot's own history, so it acts where a batch of robots is driven step by step
(:meth:`ReadingShield.actor`: ``navlearn evaluate``, ``world show``, ``navlearn drive``,
``bench/map_sizes.py``); a bare ``choose(outputs, obs)`` is the one-frame shield alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import numpy as np

from agents.disc_tracker import DiscTracker
from worlds.config import NavConfig
from worlds.perception import frame_layout

MARGINS = (0.1, 0.0)
"""metres added to the robot's radius, tried in turn: the policy's argmax among the actions clear
with the first margin, else among those clear with the second, ...; the turn-around when none is
clear with the last (0: the robot's own capsule)"""

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


ScanActor = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``act(obs (n, obs_dim), rays (n, R) m, fresh (n,) bool) -> actions (n,)``: ``n`` robots driven step
by step, ``fresh`` marking those whose episode starts"""


@runtime_checkable
class ScanPolicy(Protocol):
    """A policy that reads the scans as well: ``scan_actor(n)`` gives a :data:`ScanActor` for ``n``
    robots, or None to be called as a plain ``policy(obs) -> actions``. The evaluation's runner,
    ``world show`` and ``navlearn drive`` drive such a policy through it."""

    def __call__(self, obs: np.ndarray) -> np.ndarray: ...

    def scan_actor(self, n: int) -> ScanActor | None: ...


@dataclass(frozen=True)
class ReadingShield:
    """The shield of one robot and sensor (:func:`for_nav`): ``choose(outputs, obs)`` -> actions."""

    reach: np.ndarray
    """``(len(MARGINS), n_actions, n_beams)`` metres: :func:`reach_table` with the robot's radius
    grown by each of :data:`MARGINS`"""
    readings: slice
    """where the newest frame's readings sit in an observation"""
    max_range: float
    """the readings are in units of it (the kernel writes ``range / max_range``)"""
    turn_around: int
    """the robot's turn-around action (``RobotConfig.turn_around``), taken when nothing is clear"""
    ray_angles: np.ndarray
    """the directions of the scan's rays (``SensorConfig.ray_angles``), which the disc tracker reads"""
    moves: np.ndarray
    """``(n_actions + 1, 2)``: each action's turn (rad) and forward distance (m), the turn-around last"""
    robot_radius: float
    disc_radius: float
    """the radius the tracker takes a moving disc to have (``ObstacleConfig.radius``)"""
    track_discs: bool = True
    """act with the disc tracker behind the shield (:meth:`actor`); False: the one-frame shield only"""

    def room(self, obs: np.ndarray) -> np.ndarray:
        """``(len(MARGINS), N, n_actions)``: the least ``reading[j] - reach[k, j]`` over the sectors
        (m), per margin; an action is clear at a margin where it is >= 0."""
        readings = np.asarray(obs)[:, self.readings].astype(np.float64) * self.max_range
        return (readings[None, :, None, :] - self.reach[:, None]).min(axis=3)

    def choose(self, outputs: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """The argmax of ``outputs`` (N, n_actions) among the actions clear at the first of
        :data:`MARGINS` that leaves one clear; the turn-around where none is clear at any."""
        return self.pick(outputs, self.room(obs))

    def pick(self, outputs: np.ndarray, room: np.ndarray) -> np.ndarray:
        """:meth:`choose`'s rule on a ``room`` (``(len(MARGINS), N, n_actions)``, as :meth:`room`
        gives) however it was judged."""
        action = np.full(len(outputs), self.turn_around, dtype=np.int64)
        for margin_room in room[::-1]:  # the widest margin, tried first, decides last
            clear = margin_room >= 0
            best = np.where(clear, outputs, -np.inf).argmax(axis=1)
            action = np.where(clear.any(axis=1), best, action)
        return action

    def keep_clear(
        self, action: np.ndarray, outputs: np.ndarray, room: np.ndarray, disc_clear: np.ndarray
    ) -> np.ndarray:
        """``action`` where it is disc-clear (``disc_clear`` ``(N, n_actions + 1)``, the tracker's),
        else the first disc-clear one of: the preference of ``outputs`` among the actions the readings
        leave clear (the capsule alone, ``room[-1]``), the turn-around, the others; else ``action``."""
        action = action.copy()
        for i in np.flatnonzero(~disc_clear[np.arange(len(action)), action]):
            order = np.argsort(-outputs[i], kind="stable")
            readings_clear = room[-1, i] >= 0
            tries = [*order[readings_clear[order]], self.turn_around, *order[~readings_clear[order]]]
            action[i] = next((a for a in tries if a != action[i] and disc_clear[i, a]), action[i])
        return action

    def actor(self, outputs: Callable[[np.ndarray], np.ndarray], n: int) -> ScanActor:
        """``act(obs, rays, fresh) -> actions`` for ``n`` robots driven step by step: the argmax of
        ``outputs(obs)`` through the shield and, with :attr:`track_discs`, the disc tracker, which
        reads the scans ``rays`` ``(n, len(ray_angles))`` (m) and forgets the robots marked ``fresh``
        (their episode starts)."""
        tracker = None
        if self.track_discs:
            radii = (self.robot_radius, self.disc_radius)
            tracker = DiscTracker(n, self.ray_angles, self.max_range, self.moves, *radii)

        def act(obs: np.ndarray, rays: np.ndarray, fresh: np.ndarray) -> np.ndarray:
            values, room = outputs(obs), self.room(obs)
            action = self.pick(values, room)
            if tracker is not None:
                tracker.observe(rays, fresh)
                action = self.keep_clear(action, values, room, tracker.clear())
                tracker.moved(action)
            return action

        return act

    def over(self, outputs: Callable[[np.ndarray], np.ndarray]) -> Shielded:
        """A policy acting on the argmax of ``outputs(obs)`` through this shield (and its tracker)."""
        return Shielded(self, outputs)


@dataclass(frozen=True)
class Shielded:
    """``policy(obs) -> actions`` through a shield's one frame; :meth:`scan_actor` with its tracker."""

    shield: ReadingShield
    outputs: Callable[[np.ndarray], np.ndarray]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.shield.choose(self.outputs(obs), obs)

    def scan_actor(self, n: int) -> ScanActor:
        """:meth:`ReadingShield.actor` of these outputs, for ``n`` robots."""
        return self.shield.actor(self.outputs, n)


def for_nav(nav: NavConfig, track_discs: bool = True) -> ReadingShield:
    """The shield of ``nav``'s robot and sensor, reading observations of ``nav``'s layout, with the
    disc tracker behind it unless ``track_discs`` is False."""
    a, b = frame_layout(nav)["readings"]
    grown = [replace(nav, robot=replace(nav.robot, radius=nav.robot.radius + m)) for m in MARGINS]
    reach = np.stack([reach_table(g) for g in grown])
    robot = nav.robot
    moves = np.array([robot.motion(k) for k in range(robot.n_actions + 1)])
    return ReadingShield(
        reach,
        slice(a, b),
        nav.sensors.max_range,
        robot.turn_around,
        nav.sensors.ray_angles,
        moves,
        robot.radius,
        nav.obstacles.radius,
        track_discs,
    )
