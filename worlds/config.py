"""Configuration of the navigation world: robot, sensors, rewards, moving obstacles.

Defaults are chosen so a small Q-network learns the task in minutes on a CPU:
cells of 1 m, a 0.5 m step, a 0.25 m robot radius, 8 beams reaching 6 m and a
200-step limit. Lengths are metres, angles radians, speeds metres per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class RobotConfig:
    """Unicycle robot with discrete actions: turn by ``turns[k]`` then drive ``step`` forward."""

    n_actions: int = 5
    """number of discrete actions; their turns are ``linspace(-max_turn, max_turn, n_actions)``"""
    max_turn: float = math.pi / 2
    """largest heading change of one action (rad)"""
    step: float = 0.5
    """forward distance of one action (m)"""
    radius: float = 0.25
    """robot disc radius (m); the disc touching a blocked cell, the border or a moving disc is a collision"""
    trans_noise: float = 0.02
    """standard deviation of the Gaussian noise added to the forward distance (m)"""
    rot_noise: float = 0.02
    """standard deviation of the Gaussian noise added to the heading change (rad)"""
    heading_choices: int = 8
    """initial heading drawn uniformly among this many compass directions (0: uniform in [-pi, pi)),
    then turned to the nearest one with a collision-free action if it has none (see worlds.kernel)"""

    def __post_init__(self) -> None:
        _check(self.n_actions >= 1, f"n_actions must be >= 1, got {self.n_actions}")
        _check(self.step > 0 and self.radius > 0, "step and radius must be positive")
        _check(self.trans_noise >= 0 and self.rot_noise >= 0, "noise standard deviations must be >= 0")
        _check(self.heading_choices >= 0, f"heading_choices must be >= 0, got {self.heading_choices}")

    @property
    def turns(self) -> np.ndarray:
        """Heading change of each action (rad), shape ``(n_actions,)``."""
        if self.n_actions == 1:
            return np.zeros(1)
        return np.linspace(-self.max_turn, self.max_turn, self.n_actions)


@dataclass(frozen=True)
class SensorConfig:
    """Range beams spread evenly over ``fov``, centred on the heading."""

    n_beams: int = 8
    """number of range beams"""
    fov: float = 2 * math.pi
    """field of view (rad); 2*pi spreads the beams all around"""
    max_range: float = 6.0
    """longest measurable range (m); free beams read this"""
    noise_std: float = 0.02
    """standard deviation of the Gaussian noise on each range (m), result clipped to [0, max_range]"""
    dropout_prob: float = 0.0
    """probability that a beam returns nothing, read as ``max_range``"""

    def __post_init__(self) -> None:
        _check(self.n_beams >= 1, f"n_beams must be >= 1, got {self.n_beams}")
        _check(0 < self.fov <= 2 * math.pi, f"fov must be in (0, 2*pi], got {self.fov}")
        _check(self.max_range > 0 and self.noise_std >= 0, "max_range must be positive, noise_std >= 0")
        _check(0 <= self.dropout_prob <= 1, f"dropout_prob must be in [0, 1], got {self.dropout_prob}")

    @property
    def beam_angles(self) -> np.ndarray:
        """Beam directions relative to the heading (rad), shape ``(n_beams,)``."""
        if self.n_beams == 1:
            return np.zeros(1)
        if math.isclose(self.fov, 2 * math.pi):
            return -math.pi + np.arange(self.n_beams) * (2 * math.pi / self.n_beams)
        return np.linspace(-self.fov / 2, self.fov / 2, self.n_beams)


@dataclass(frozen=True)
class RewardConfig:
    """Reward of one step: ``step + progress * (d_before - d_after)``, plus ``goal`` or ``collision``
    on the step that ends the episode that way (``d`` is the distance to the goal, no progress
    term on a collision). The progress term is potential-based shaping (Ng et al. 1999 with
    gamma = 1); set it to 0 to switch shaping off."""

    goal: float = 1.0
    """reward for reaching the goal"""
    collision: float = -1.0
    """reward for hitting a blocked cell, the border or a moving disc"""
    step: float = -0.01
    """reward of every step (a cost, so negative)"""
    progress: float = 0.1
    """reward per metre of progress towards the goal (0 switches shaping off)"""


@dataclass(frozen=True)
class ObstacleConfig:
    """Moving discs placed at random free positions at every reset."""

    count: int = 0
    """number of moving discs per episode"""
    radius: float = 0.3
    """disc radius (m)"""
    speed: float = 0.2
    """disc speed (m per step)"""
    mode: str = "bounce"
    """"bounce": constant velocity, reflected by walls; "patrol": back and forth between two waypoints"""
    patrol_length: float = 4.0
    """longest patrol segment (m); shortened so the disc never touches a wall"""
    spawn_clearance: float = 1.5
    """no disc starts closer than this to the robot's start (m, between the disc edges)"""

    def __post_init__(self) -> None:
        _check(
            self.mode in ("bounce", "patrol"),
            f"obstacle mode must be 'bounce' or 'patrol', got {self.mode!r}",
        )
        _check(
            self.count >= 0 and self.radius > 0 and self.speed >= 0,
            "obstacle count and speed must be >= 0, radius > 0",
        )


@dataclass(frozen=True)
class NavConfig:
    """Everything that defines the navigation task apart from the maps."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    rewards: RewardConfig = field(default_factory=RewardConfig)
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)
    max_steps: int = 200
    """episode step limit; reaching it truncates the episode (outcome TIMEOUT)"""
    goal_tolerance: float = 0.5
    """the goal is reached when the robot centre ends a step this close to the goal cell centre (m)"""
    pool_size: int = 1024
    """number of maps drawn once from a map spec; episodes pick among them (see worlds.tasks)"""
    pool_seed: int = 0
    """seed of that draw (evaluation sets use other generator seeds, see worlds.tasks)"""

    def __post_init__(self) -> None:
        _check(self.max_steps >= 1 and self.pool_size >= 1, "max_steps and pool_size must be >= 1")
        _check(self.goal_tolerance > 0, f"goal_tolerance must be positive, got {self.goal_tolerance}")


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(message)
