"""Configuration of the navigation world: robot, sensors, rewards, moving obstacles.

Defaults are chosen so a small Q-network learns the task in minutes on a CPU:
cells of 1 m, a 0.5 m step, a 0.25 m robot radius, 8 beams reaching 6 m and a
200-step limit. Lengths are metres, angles radians, speeds metres per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

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
    held_headings: int = 0
    """compass headings the robot holds, as a real base does with its odometry or IMU: before each
    action its heading is turned to the nearest of this many (8: every 45 degrees, the actions'
    turns), so one step's heading noise does not carry into the next; 0: not held, the heading
    noise adds up as a random walk (docs/navigation-by-size.md section 14)"""

    def __post_init__(self) -> None:
        _check(self.n_actions >= 1, f"n_actions must be >= 1, got {self.n_actions}")
        _check(self.step > 0 and self.radius > 0, "step and radius must be positive")
        _check(self.trans_noise >= 0 and self.rot_noise >= 0, "noise standard deviations must be >= 0")
        _check(self.heading_choices >= 0, f"heading_choices must be >= 0, got {self.heading_choices}")
        _check(self.held_headings >= 0, f"held_headings must be >= 0 (0: not held), got {self.held_headings}")

    @property
    def turns(self) -> np.ndarray:
        """Heading change of each action (rad), shape ``(n_actions,)``."""
        if self.n_actions == 1:
            return np.zeros(1)
        return np.linspace(-self.max_turn, self.max_turn, self.n_actions)

    @property
    def turn_around(self) -> int:
        """The index of the robot's turn-around, ``n_actions``: half a turn in place, no drive.
        It lies outside the learned actions (a policy's ``Discrete(n_actions)``): the world and
        ``navlearn drive`` execute it, and only the reading shield (:mod:`agents.shield`) takes it, when
        its readings leave no action clear (a robot that must drive ``step`` would otherwise hit
        something). The kernel (:mod:`worlds.kernel`) tests ``action == len(turns)``."""
        return self.n_actions

    def motion(self, action: int) -> tuple[float, float]:
        """``(turn, forward distance)`` of ``action``, :attr:`turn_around` included."""
        if action == self.turn_around:
            return math.pi, 0.0
        if not 0 <= action < self.n_actions:
            raise ValueError(f"action {action} is not in [0, {self.n_actions}] (the last is the turn-around)")
        return float(self.turns[action]), self.step


@dataclass(frozen=True)
class SensorConfig:
    """Range beams spread evenly over ``fov``, centred on the heading."""

    n_beams: int = 8
    """number of range readings in the observation: beams, or sectors when ``n_rays`` > ``n_beams``"""
    n_rays: int = 0
    """rays cast per step (0: one per reading). With more, reading k is the minimum of the
    ``n_rays / n_beams`` exactly cast rays spread evenly across sector k (centred on
    ``beam_angles[k]``), so no corner hides between readings; must be a multiple of ``n_beams``"""
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
        _check(
            self.n_rays == 0 or (self.n_rays >= self.n_beams and self.n_rays % self.n_beams == 0),
            f"sensors.n_rays={self.n_rays}: must be 0 or a multiple of n_beams={self.n_beams} "
            "(sectors > rays is not allowed); e.g. n_beams=24, n_rays=96",
        )
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

    @property
    def rays_per_beam(self) -> int:
        """Rays whose minimum makes one reading (1 without sectors)."""
        return max(self.n_rays // self.n_beams, 1)

    @property
    def ray_angles(self) -> np.ndarray:
        """Directions of the cast rays relative to the heading (rad), shape ``(n_beams * rays_per_beam,)``,
        sector by sector: sector k spans ``fov / n_beams`` centred on ``beam_angles[k]``, its rays
        evenly inside it (one ray: the centre itself, the plain beam)."""
        per = self.rays_per_beam
        offsets = ((np.arange(per) + 0.5) / per - 0.5) * (self.fov / self.n_beams)
        return (self.beam_angles[:, None] + offsets[None, :]).ravel()


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
    """reward per metre of progress towards the goal in a straight line (0 switches it off)"""
    geodesic_progress: float = 0.0
    """reward per metre of progress along the shortest grid path to the goal on the true map
    (walls included; a training signal only, never observed; 0 switches it off)"""

    def __post_init__(self) -> None:
        _check(
            self.geodesic_progress >= 0, f"rewards.geodesic_progress={self.geodesic_progress}: must be >= 0"
        )


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
    mix: bool = False
    """draw each episode's disc count uniformly from 0..count (a training mix of static and crowded
    episodes; evaluation sets keep a fixed count)"""

    def __post_init__(self) -> None:
        _check(
            self.mode in ("bounce", "patrol"),
            f"obstacle mode must be 'bounce' or 'patrol', got {self.mode!r}",
        )
        _check(
            self.count >= 0 and self.radius > 0 and self.speed >= 0,
            "obstacle count and speed must be >= 0, radius > 0",
        )


SUBGOALS = ("none", "own_map", "known_map")


@dataclass(frozen=True)
class ObservationConfig:
    """What the policy observes beyond the range readings and the goal (each option off by default;
    see :mod:`worlds.perception`). Everything comes from the robot's own sensing and poses, except
    the ``known_map`` subgoal, which is for users who have a map."""

    previous_action: bool = False
    """append the previous action, one-hot (zeros at the first step)"""
    frame_stack: int = 1
    """observe the last k frames, newest first (the first frame repeated after a reset)"""
    subgoal: str = "none"
    """"none"; "own_map": distance and bearing to a waypoint ``subgoal_distance`` along the shortest
    path to the goal on the map the robot built from its own beams (unseen cells passable, see
    ``subgoal_prefers_seen``), replanned every step; "known_map": the same path on the true map (a
    user-supplied map, not learning alone)"""
    subgoal_distance: float = 2.5
    """path length from the robot to the subgoal waypoint (m); the goal itself when closer"""
    subgoal_clearance: float = 0.0
    """> 0: the waypoint is the furthest cell of the path, up to ``subgoal_distance``, that a straight
    line from the centre of the robot's cell reaches this far (m) from every blocked cell of the plan
    map (else the path's next cell): it never lies round a corner, so heading for it does not cut a
    door's jamb. 0: the cell ``subgoal_distance`` along the path, round corners or not (what policies
    saved before the setting observe). Learned policies use 0.4 (the robot's radius and 0.15 m;
    issue 39: nearly every collision on bigger room maps was at a jamb). On maps of cells finer than
    it, the path itself keeps this far from walls where it can (:mod:`worlds.own_map`: the plan
    grid's soft band)"""
    subgoal_prefers_seen: bool = False
    """True: the own map's plan enters a cell the robot has not seen at twice a seen free cell's cost
    (``1 +`` :data:`worlds.own_map.PENALTY` times the move, the cost of the clearance's band), so an
    unseen stretch of path counts double and the plan keeps to ways the robot has seen unless an
    unseen one is clearly shorter. False: unseen cells plan as free (what policies saved before the
    setting observe). Learned policies use True (issue 39: on 64-cell room maps the timeouts were the
    optimistic plan sending the robot down one unseen shortcut after another; validation
    ``static:64`` 97.3 -> 99.3%, docs/navigation-by-size.md section 12). It applies on maps whose cells
    need no inflation (0.8 m and more for the default robot); on finer cells unseen cells stay free
    (:mod:`worlds.own_map`: there the own map's rays leave most cells unseen)"""
    patch_size: int = 0
    """side of the egocentric, heading-aligned patch of the robot's own map (cells; 0: off), two
    channels: occupancy (1 seen blocked, 0 seen free, 0.5 unknown) and visits (1 - 1/(1+n))"""
    range_rate: bool = False
    """append each reading's change since the previous step, in metres, clipped to [-1, 1] (negative:
    something came closer; 0 at the first step): a cheap motion cue for moving discs in place of a
    frame stack"""
    plan_length: bool = False
    """append the length of the subgoal's path from the robot's cell to the goal (m, squashed like
    the goal distance; the straight-line distance when no path exists): how far the goal is around
    the walls the robot has seen, which the straight line and a waypoint 2.5 m ahead do not say.
    Needs a subgoal"""

    def __post_init__(self) -> None:
        for name in ("range_rate", "plan_length", "subgoal_prefers_seen"):
            value = getattr(self, name)
            _check(isinstance(value, bool | np.bool_), f"observation.{name}={value!r}: must be True or False")
        _check(
            not self.plan_length or self.subgoal != "none",
            "observation.plan_length=True needs a subgoal planner (subgoal 'own_map' or 'known_map'), "
            "got subgoal='none'",
        )
        _check(self.frame_stack >= 1, f"observation.frame_stack={self.frame_stack}: must be >= 1")
        _check(self.subgoal in SUBGOALS, f"observation.subgoal={self.subgoal!r}: expected one of {SUBGOALS}")
        _check(
            self.subgoal_distance > 0, f"observation.subgoal_distance={self.subgoal_distance}: must be > 0"
        )
        _check(
            self.subgoal_clearance >= 0,
            f"observation.subgoal_clearance={self.subgoal_clearance}: must be >= 0 (0: off)",
        )
        _check(self.patch_size >= 0, f"observation.patch_size={self.patch_size}: must be >= 0 (0: off)")

    @property
    def needs_map(self) -> bool:
        """Does the observation read the robot's own map?"""
        return self.subgoal == "own_map" or self.patch_size > 0

    @property
    def plain(self) -> bool:
        """Nothing beyond the readings and the goal (the kernel's observation as it is)."""
        return (
            not self.previous_action
            and self.frame_stack == 1
            and self.subgoal == "none"
            and not self.patch_size
            and not self.range_rate
            and not self.plan_length
        )


@dataclass(frozen=True)
class NavConfig:
    """Everything that defines the navigation task apart from the maps."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    rewards: RewardConfig = field(default_factory=RewardConfig)
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    max_steps: int = 200
    """least episode step limit; reaching the limit truncates the episode (outcome TIMEOUT)"""
    step_factor: float = 4.0
    """the step limit grows with the episode's path: at least ``step_factor`` times the steps the
    grid A* path from start to goal takes (see :func:`step_limit`; 0: ``max_steps`` for every
    episode, the rule before maps grew)"""
    goal_tolerance: float = 0.5
    """the goal is reached when the robot centre ends a step this close to the goal cell centre (m)"""
    pool_size: int = 1024
    """number of maps drawn once from a map spec; episodes pick among them (see worlds.tasks)"""
    pool_seed: int = 0
    """seed of that draw (evaluation sets use other generator seeds, see worlds.tasks)"""

    def __post_init__(self) -> None:
        _check(self.max_steps >= 1 and self.pool_size >= 1, "max_steps and pool_size must be >= 1")
        _check(self.step_factor >= 0, f"step_factor must be >= 0 (0: a fixed limit), got {self.step_factor}")
        _check(self.goal_tolerance > 0, f"goal_tolerance must be positive, got {self.goal_tolerance}")


def step_limit(config: NavConfig, path_length: float) -> int:
    """The step limit of an episode whose grid A* path (8-connected, no corner cutting, on the
    world's map) is ``path_length`` metres: ``max(max_steps, ceil(step_factor * path_length /
    robot.step))``. A robot that drives straight along the path needs ``path_length / step`` steps,
    so a timeout means it drove ``step_factor`` times that (4 by default) without arriving: it
    dawdled, the map's size did not cause it. The floor ``max_steps`` (200) keeps short episodes,
    and so every figure on 16-cell maps, as they were. The compiled kernel applies the same rule
    (:func:`worlds.kernel._limit`); an unreachable goal gets the floor."""
    if config.step_factor <= 0 or not math.isfinite(path_length):
        return config.max_steps
    return max(config.max_steps, math.ceil(config.step_factor * path_length / config.robot.step - 1e-9))


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(message)


OBSERVATION_FIELDS = (
    "sensors.n_beams",
    "sensors.n_rays",
    "sensors.fov",
    "sensors.max_range",
    "robot.n_actions",
    "observation.previous_action",
    "observation.frame_stack",
    "observation.subgoal",
    "observation.subgoal_distance",
    "observation.subgoal_clearance",
    "observation.subgoal_prefers_seen",
    "observation.patch_size",
    "observation.range_rate",
    "observation.plan_length",
)
"""the settings that fix what a policy observes (and its action count); saved policies record them"""

LEGACY_OBSERVATION = {
    "sensors.n_beams": 8,
    "sensors.n_rays": 0,
    "sensors.fov": 2 * math.pi,
    "sensors.max_range": 6.0,
    "robot.n_actions": 5,
    "observation.previous_action": False,
    "observation.frame_stack": 1,
    "observation.subgoal": "none",
    "observation.subgoal_distance": 2.5,
    "observation.subgoal_clearance": 0.0,
    "observation.subgoal_prefers_seen": False,
    "observation.patch_size": 0,
    "observation.range_rate": False,
    "observation.plan_length": False,
}
"""what a policy saved without an ``observation`` record observes: 8 beams, goal, one frame
(every navlearn policy saved before these settings existed, e.g. the first ``pretrained/nnql``)"""


def saved_observation(record: dict | None) -> dict:
    """The observation settings of a saved policy's ``observation`` record: a field the record lacks
    did not exist when it was saved, so the policy observes its :data:`LEGACY_OBSERVATION` value (off)."""
    return {**LEGACY_OBSERVATION, **(record or {})}


def observation_settings(config: NavConfig) -> dict:
    """The :data:`OBSERVATION_FIELDS` of ``config``, as a flat JSON-able dict."""
    settings = {}
    for name in OBSERVATION_FIELDS:
        part, attr = name.split(".")
        settings[name] = getattr(getattr(config, part), attr)
    return settings


def check_observation(saved: dict, config: NavConfig, what: str = "the policy") -> None:
    """Raise a ValueError naming every field where ``config``'s observation differs from ``saved``."""
    unknown = sorted(set(saved) - set(OBSERVATION_FIELDS))
    if unknown:
        raise ValueError(f"{what} records unknown observation settings {unknown}; known {OBSERVATION_FIELDS}")
    wrong = observation_differences(saved, config)
    if wrong:
        raise ValueError(
            f"{what} was trained to observe " + ", ".join(wrong) + ": evaluate it in an env with its "
            "settings (worlds.config.with_observation) or retrain it"
        )


def observation_differences(saved: dict, config: NavConfig, other: str = "the env") -> list[str]:
    """``"field=saved (the env has value)"`` for every field where ``config``'s observation differs
    from ``saved`` (fields ``saved`` lacks are not compared); ``other`` names ``config``'s side."""
    given = observation_settings(config)
    return [
        f"{name}={saved[name]!r} ({other} has {given[name]!r})"
        for name in OBSERVATION_FIELDS
        if name in saved and not _same(saved[name], given[name])
    ]


def with_observation(config: NavConfig, saved: dict) -> NavConfig:
    """``config`` with the observation settings ``saved`` (missing fields keep ``config``'s)."""
    parts: dict[str, dict] = {}
    for name, value in saved.items():
        if name not in OBSERVATION_FIELDS:
            raise ValueError(f"unknown observation setting {name!r}; known: {OBSERVATION_FIELDS}")
        part, attr = name.split(".")
        parts.setdefault(part, {})[attr] = value
    updated = {part: replace(getattr(config, part), **values) for part, values in parts.items()}
    return replace(config, **updated)


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


LEARNING_NAV = NavConfig(
    sensors=SensorConfig(n_beams=24, n_rays=96),
    observation=ObservationConfig(subgoal="own_map", subgoal_clearance=0.4, subgoal_prefers_seen=True),
    rewards=RewardConfig(progress=0.0, geodesic_progress=0.1),
)
"""the task as learned policies see it by default (``navlearn train --local``, the actors, learner,
evaluator and demonstrator of ``navlearn up``): 24 sector minima of 96 rays, the goal, the subgoal
from the robot's own map, trained with the geodesic progress reward - the winner on validation
success of the observation ablation (``bench/perception.py``, variant "D+geo")"""

LEARNING_PLAN_NAV = replace(LEARNING_NAV, observation=replace(LEARNING_NAV.observation, plan_length=True))
"""LEARNING_NAV with the length of the own map's plan to the goal observed (``plan_length``): NIRL's
observation (``navlearn demos generate / nirl train --observation learning_plan``) - its progress
potential, fitted on the demonstrations' steps to go, reads how far the goal is round the walls the
robot has seen"""

OBSERVATIONS = {
    "learning": LEARNING_NAV,
    "learning_plan": LEARNING_PLAN_NAV,
    "plain": with_observation(NavConfig(), LEGACY_OBSERVATION),
}
"""the named observations of ``--observation`` (demonstration sets, behaviour cloning, NIRL):
``learning`` (LEARNING_NAV, what NNQL learns in), ``learning_plan`` (LEARNING_PLAN_NAV) and ``plain``
(8 beams + goal, the older sets)"""


def observation_name(settings: dict) -> str | None:
    """The name in :data:`OBSERVATIONS` of the observation ``settings`` (an ``observation_settings``
    record) describe, or None if none of them (what an error tells a user to give)."""
    return next(
        (name for name, nav in OBSERVATIONS.items() if not observation_differences(settings, nav)), None
    )


OBSERVATION_ENV = "NAVLEARN_OBSERVATION"
"""the one environment variable every service reads ``--observation`` from (like NAVLEARN_RUN)"""


def observation_field():
    """The ``observation`` field of a service's config (``--observation NAME``, one of
    :data:`OBSERVATIONS`, default ``learning``; environment :data:`OBSERVATION_ENV` for all of them):
    what the robots of one run observe. The actors, the learner, the evaluator and the demonstrator
    of a run must name the same one (``navlearn up`` passes its own to each; the learner's weights
    say which it is, and an actor or evaluator on another refuses them naming the field)."""
    return field(default="learning", metadata={"choices": tuple(OBSERVATIONS), "env": OBSERVATION_ENV})


TRAINING_MAPS = "mixed:16-64"
"""the maps learned policies train on by default (``navlearn train --local``, the actors of ``navlearn
up``): the three families of ``mixed`` at every side from 16 to 64 cells, so one policy holds at every
map size (docs/navigation-by-size.md)"""


TRAINING_DISCS = 6
"""moving discs per training episode by default (``navlearn train --local``, the actors of ``navlearn
up``): 0..6, uniform per episode, so training sees static maps, the dynamic test set's crowds of 4
and denser ones - the shipped policy's recipe, chosen on validation over 0..4"""


def with_moving_discs(nav: NavConfig, count: int) -> NavConfig:
    """``nav`` whose episodes each have 0..``count`` moving discs (uniform, the evaluation sets'
    disc settings otherwise): training that sees the dynamic set's crowds. ``count`` 0: ``nav``."""
    _check(count >= 0, f"moving discs must be >= 0, got {count}")
    if count == 0:
        return nav
    return replace(nav, obstacles=replace(nav.obstacles, count=count, mix=True))
