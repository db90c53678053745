"""``navlearn/Navigation-v0``: one unicycle robot driving to a goal on a grid map."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from worlds.batch import NavBatch
from worlds.config import NavConfig
from worlds.maps import Task
from worlds.obstacles import DiscObstacles
from worlds.outcomes import Outcome
from worlds.perception import observation_bounds
from worlds.render import render_rgb
from worlds.rng import seed_state
from worlds.tasks import DEFAULT_MAPS, TaskSampler, as_sampler


def observation_space(config: NavConfig) -> spaces.Box:
    low, high = observation_bounds(config)
    return spaces.Box(low, high, dtype=np.float32)


class NavigationEnv(gym.Env):
    """A unicycle robot with range sensors drives to a goal cell on an occupancy grid
    (Xia 2015, ch. 2.5).

    ## Description
    Each episode puts the robot at the centre of a start cell with a random heading and asks
    it to reach the centre of a goal cell. The heading is drivable: when no action is
    collision-free from the drawn heading (a start in a dead end facing the walls), the nearest
    heading that has one is used instead; a given task whose start has none is rejected with a
    ValueError, a drawn one is redrawn. Maps come from a map spec (see
    :mod:`worlds.tasks`, default ``"mixed:16"``: 16x16 generated maps of random rectangles,
    discs or rooms) through a fixed pool of tasks; start and goal are free and connected.
    Optional moving discs (``config.obstacles``) bounce off walls or patrol between two
    waypoints. Motion and range readings carry Gaussian noise (configurable, zero allowed).

    ## Action Space
    ``Discrete(n_actions)`` (default 5): action ``k`` turns the robot by
    ``linspace(-max_turn, max_turn, n_actions)[k]`` (default -90, -45, 0, 45, 90 degrees),
    then drives ``step`` metres (default 0.5) straight ahead. ``step`` also takes ``n_actions``, outside
    the space: the turn-around (``RobotConfig.turn_around``, half a turn in place, no drive), which only
    the reading shield takes (:mod:`agents.shield`).

    ## Observation Space
    ``Box(n_beams + 3,)`` float32:

    | index          | observation                                                   | min | max |
    |----------------|---------------------------------------------------------------|-----|-----|
    | 0..n_beams-1   | range of beam k / max_range (beams evenly over the fov)         | 0   | 1   |
    | n_beams        | goal distance d, squashed: d / (d + max_range)                  | 0   | 1   |
    | n_beams + 1    | sin of the goal bearing relative to the heading                 | -1  | 1   |
    | n_beams + 2    | cos of the goal bearing relative to the heading                 | -1  | 1   |

    Beam k points at ``beam_angles[k]`` from the heading (with a 360-degree fov: -180 +
    k * 360 / n_beams degrees); the bearing grows towards +y (clockwise on a picture).
    With ``sensors.n_rays`` > ``n_beams`` reading k is the minimum over the rays of its sector
    (e.g. 24 sectors of 4 rays each), so no corner hides between readings.

    ``config.observation`` (:class:`worlds.config.ObservationConfig`) appends to this frame a
    subgoal from the robot's own map (distance and bearing, 3 values), the previous action
    (one-hot) and a patch of the robot's own map, and stacks the last ``frame_stack`` frames,
    newest first (:mod:`worlds.perception`; ``worlds.perception.frame_layout`` says where each
    part sits). The default is the table above. Policies learn with
    :data:`worlds.config.LEARNING_NAV`.

    ## Rewards
    Every step ``rewards.step`` (-0.01) plus ``rewards.progress`` (0.1) per metre gained
    towards the goal (plus ``rewards.geodesic_progress`` per metre gained along the shortest
    path round the walls, 0 by default); ``rewards.goal`` (+1) on reaching it; ``rewards.collision`` (-1) on a
    collision (no progress term then). See :class:`worlds.config.RewardConfig`.

    ## Episode End
    Terminated when the robot centre ends a step within ``goal_tolerance`` (0.5 m) of the goal
    (outcome GOAL), or when its disc, swept along the step, touches a blocked cell or the map
    border (COLLISION_STATIC; the robot stays where it was) or a moving disc
    (COLLISION_DYNAMIC). Truncated (TIMEOUT) after the episode's step limit, ``info["step_limit"]``:
    ``max(max_steps, ceil(step_factor * L / step))`` with ``L`` the grid A* path length from start
    to goal (200 steps at least, 4 times the path's steps; :func:`worlds.config.step_limit`).
    ``info["outcome"]`` holds the :class:`worlds.outcomes.Outcome` (RUNNING meanwhile),
    ``info["pose"]`` (x, y, theta), ``info["path_length"]`` (m) and ``info["steps"]``;
    ``reset`` also returns ``info["task"]``.

    ## Arguments
    - ``config``: a :class:`worlds.config.NavConfig` (robot, sensors, rewards, obstacles,
      limits); ``None`` for the defaults.
    - ``maps``: a map spec string or a callable ``(rng) -> Task``.
    - ``render_mode``: ``None`` or ``"rgb_array"``.

    ``reset(seed=..., options={"task": Task, "obstacles": DiscObstacles})`` drives the given
    task and/or discs instead of drawing them.

    ## Example
    >>> import gymnasium as gym, worlds
    >>> env = gym.make("navlearn/Navigation-v0", maps="rooms:16")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape
    (11,)
    >>> obs, reward, terminated, truncated, info = env.step(2)
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        config: NavConfig | None = None,
        maps: str | TaskSampler = DEFAULT_MAPS,
        render_mode: str | None = None,
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.config = config or NavConfig()
        self.sampler = as_sampler(maps)
        self.render_mode = render_mode
        self.batch = NavBatch(1, self.config, [self.sampler])
        self.action_space = spaces.Discrete(self.config.robot.n_actions)
        self.observation_space = observation_space(self.config)
        self._seeded = False
        self._trajectory: list[tuple[float, float]] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None or not self._seeded:
            self.batch.seed([0], [seed_state(self.np_random)])
            self._seeded = True
        options = options or {}
        task: Task | None = options.get("task")
        discs: DiscObstacles | None = options.get("obstacles")
        self.batch.reset([0], None if task is None else [task], None if discs is None else [discs])
        self._trajectory = [(float(self.batch.x[0]), float(self.batch.y[0]))]
        info = self._info()
        info["task"] = self.batch.task(0)
        return self.batch.obs[0].copy(), info

    def step(self, action):
        if not self._trajectory:
            raise RuntimeError("call reset() before step()")
        if self.batch.outcome[0] != Outcome.RUNNING:
            raise RuntimeError("the episode has ended; call reset()")
        self.batch.step(np.asarray([action]), autoreset=False)
        self._trajectory.append((float(self.batch.x[0]), float(self.batch.y[0])))
        return (
            self.batch.obs[0].copy(),
            float(self.batch.reward[0]),
            bool(self.batch.terminated[0]),
            bool(self.batch.truncated[0]),
            self._info(),
        )

    def _info(self) -> dict[str, Any]:
        b = self.batch
        return {
            "pose": np.array([b.x[0], b.y[0], b.theta[0]]),
            "path_length": float(b.path_length[0]),
            "outcome": int(b.outcome[0]),
            "steps": int(b.steps[0]),
            "step_limit": b.episode_step_limit(0),
        }

    def render(self):
        if self.render_mode != "rgb_array":
            return None

        return render_rgb(self.batch, 0, self._trajectory)
