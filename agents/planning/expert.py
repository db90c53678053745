"""The expert controller: follows a modified-A* plan in the environment, replanning
when the robot drifts (motion noise) or its sensors see moving obstacles.

The expert knows the static map (it is the demonstrator of thesis ch. 3) but not
where the moving discs are: it infers them from its own range beams. A beam that
returns clearly shorter than the static map predicts hit a moving disc; the disc
centre is put one obstacle radius behind the hit point, inflated by a safety
margin (and, if remembered for more steps, by how far it could have moved
since). Any detection, or a pose further than ``replan_distance`` from the planned one,
triggers a new plan from the current pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.planning.astar import distance_field
from agents.planning.lattice import LatticeConfig, LatticePlan, plan_lattice
from worlds.config import NavConfig
from worlds.maps import Task
from worlds.robot import collides, move, wrap_angle
from worlds.sensors import cast_rays


@dataclass(frozen=True)
class ExpertConfig:
    """How the expert follows and repairs its plan."""

    replan_distance: float = 0.1
    """replan when the pose is this far from the planned pose (m)"""
    replan_heading: float = 0.15
    """... or its heading this far from the planned heading (rad)"""
    detection_margin: float = 0.2
    """a beam this much shorter than the static map predicts is a moving-disc detection (m)"""
    memory: int = 1
    """steps a detection is remembered (1: only what the beams show now; on mixed:16 with 4 discs,
    longer memories blocked more paths than they saved: 82% success with 2 steps, 75% with 4, 87% with 1)"""
    inflation: float = 0.1
    """extra safety radius around every detected disc (m), on top of its possible motion"""
    lead: int = 0
    """a detected disc is grown by ``speed * (age + lead)``: how far it may have moved since it was seen,
    plus ``lead`` steps ahead"""


class Expert:
    """Drives one robot on one task: ``reset(task, pose)`` then ``act(pose, obs)`` each step."""

    def __init__(
        self,
        nav: NavConfig | None = None,
        config: ExpertConfig | None = None,
        lattice: LatticeConfig | None = None,
    ):
        self.nav = nav or NavConfig()
        self.config = config or ExpertConfig()
        self.lattice = lattice or LatticeConfig()
        self.turns = self.nav.robot.turns
        self.replans = 0
        self.failures = 0
        self._task: Task | None = None

    # ------------------------------------------------------------------ planning
    def reset(self, task: Task, pose: tuple[float, float, float]) -> LatticePlan:
        """Start a new episode on ``task`` with the robot at ``pose``; returns the first plan."""
        self._task = task
        self._field = distance_field(task.grid, task.goal)
        self._detections: list[tuple[np.ndarray, int]] = []  # (discs (k, 3), age)
        self.replans = 0
        self.failures = 0
        self._replan(np.asarray(pose, dtype=np.float64))
        return self.plan

    def _known_discs(self) -> np.ndarray:
        obstacles = self.nav.obstacles
        rows = []
        for discs, age in self._detections:
            grown = discs.copy()
            grown[:, 2] += obstacles.speed * (age + self.config.lead) + self.config.inflation
            rows.append(grown)
        return np.concatenate(rows) if rows else np.zeros((0, 3))

    def _replan(self, pose: np.ndarray) -> None:
        assert self._task is not None
        nav = self.nav
        args = (self._task.grid, tuple(pose), self._task.goal, self.turns, nav.robot.step, nav.robot.radius)
        tolerance = nav.goal_tolerance
        plan = plan_lattice(*args, tolerance, self.lattice, self._known_discs(), self._field)
        if not plan.found and self._detections:
            plan = plan_lattice(*args, tolerance, self.lattice, None, self._field)  # ignore the discs
        if not plan.found:
            self.failures += 1
        self.plan = plan
        self._index = 0

    def _detect(self, pose: np.ndarray, obs: np.ndarray) -> bool:
        """Update the remembered moving discs from the beams; True when something new was seen."""
        sensors = self.nav.sensors
        n = sensors.n_beams
        measured = np.asarray(obs[:n], dtype=np.float64) * sensors.max_range
        angles = sensors.beam_angles
        rays = cast_rays(self._task.grid, pose[0], pose[1], pose[2], sensors.ray_angles, sensors.max_range)[0]
        expected = rays.reshape(n, sensors.rays_per_beam).min(axis=1)  # what each reading (sector) shows
        hit = measured < expected - self.config.detection_margin
        self._detections = [(d, age + 1) for d, age in self._detections if age + 1 < self.config.memory]
        if not hit.any():
            return False
        heading = pose[2] + angles[hit]
        reach = measured[hit] + self.nav.obstacles.radius
        discs = np.column_stack(
            [
                pose[0] + reach * np.cos(heading),
                pose[1] + reach * np.sin(heading),
                np.full(int(hit.sum()), self.nav.obstacles.radius),
            ]
        )
        self._detections.append((discs, 0))
        return True

    # ------------------------------------------------------------------ acting
    def act(self, pose: tuple[float, float, float], obs: np.ndarray | None = None) -> int:
        """The next action from the robot's true pose and (for moving discs) its observation."""
        if self._task is None:
            raise RuntimeError("call reset(task, pose) first")
        pose = np.asarray(pose, dtype=np.float64)
        seen = obs is not None and self.nav.obstacles.count > 0 and self._detect(pose, obs)
        planned = self.plan.poses[self._index] if self._index < len(self.plan.poses) else None
        drifted = planned is None or (
            np.hypot(*(pose[:2] - planned[:2])) > self.config.replan_distance
            or abs(float(wrap_angle(pose[2] - planned[2]))) > self.config.replan_heading
        )
        if seen or drifted or self._index >= len(self.plan.actions):
            self.replans += 1
            self._replan(pose)
        if self.plan.found and self._index < len(self.plan.actions):
            action = int(self.plan.actions[self._index])
            self._index += 1
            return action
        return self.safest_action(pose)

    def _next_steps(self, pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where each action would take the robot without noise, and whether it would collide."""
        x, y, theta = (np.full(len(self.turns), v) for v in pose)
        nx, ny, _ = move(x, y, theta, self.turns, self.nav.robot.step)
        return nx, ny, collides(self._task.grid, x, y, nx, ny, self.nav.robot.radius)

    def safe_actions(self, pose: tuple[float, float, float]) -> np.ndarray:
        """Actions whose noiseless step keeps the robot clear of the static map."""
        return np.flatnonzero(~self._next_steps(pose)[2])

    def safest_action(self, pose: tuple[float, float, float]) -> int:
        """Fallback without a plan: a non-colliding action that gets closest to the goal by grid distance."""
        nx, ny, hits = self._next_steps(pose)
        grid = self._task.grid
        rows = np.clip((ny / grid.cell_size).astype(int), 0, grid.height - 1)
        cols = np.clip((nx / grid.cell_size).astype(int), 0, grid.width - 1)
        return int(np.argmin(np.where(hits, np.inf, self._field[rows, cols])))
