"""A numpy-batched vector env: N robots stepped by one compiled call per step."""

from __future__ import annotations

import os
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from worlds.batch import NavBatch
from worlds.config import NavConfig
from worlds.env import observation_space
from worlds.rng import seed_state
from worlds.tasks import DEFAULT_MAPS, TaskSampler, as_sampler

THREADS_VARIABLE = "NAVLEARN_ENV_THREADS"
"""environment variable with the default thread count of NavigationVectorEnv"""


class NavigationVectorEnv(VectorEnv):
    """``num_envs`` robots of :class:`worlds.env.NavigationEnv`, each on its own map (or a shared
    one), stepped together by the compiled kernel. Gymnasium ``VectorEnv`` API, autoreset mode
    ``SAME_STEP``: when a robot's episode ends, the returned observation is already its next
    episode's first one.

    - ``maps``: one spec or ``(rng) -> Task`` callable for every robot, or a list of them (one
      per robot). Robots drawing from the same spec share one task pool.
    - ``seed``: the seed of the first ``reset()`` when it gets none. Robot ``i`` of an env seeded
      ``s`` is the single env seeded ``s + i``: same tasks, noise and results (tested).
    - ``threads``: threads stepping ranges of robots at once (the compiled kernel releases the
      GIL). ``None`` reads the environment variable ``NAVLEARN_ENV_THREADS``, default 1:
      navlearn runs several actor processes per machine, which already use the cores, and
      threads only pay off on idle cores. Results do not depend on it (tested).
    - ``reset(seed=s | [s_0, ...], options={"tasks": [Task | None, ...], "obstacles":
      [DiscObstacles | None, ...], "reset_mask": bool array})``: given tasks/discs for some
      robots; ``reset_mask`` resets only the marked robots.

    ``step`` returns ``info`` empty unless an episode ended; then ``info["final_obs"]`` is an
    ``(num_envs, obs_dim)`` array holding the terminal observations (rows where
    ``info["_final_obs"]`` is True; a dense array instead of gymnasium's object array, indexable
    the same way), and ``info["final_info"]`` holds arrays ``outcome``, ``path_length``,
    ``steps``, ``pose``, ``start``, ``goal`` and ``map_index`` (see :meth:`final_task`).
    :meth:`poses` and :meth:`tasks` read the current state when needed.
    """

    metadata: ClassVar[dict] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int,
        config: NavConfig | None = None,
        maps: str | TaskSampler | list[str | TaskSampler] = DEFAULT_MAPS,
        seed: int | None = None,
        threads: int | None = None,
    ) -> None:
        self.num_envs = int(num_envs)
        self.config = config or NavConfig()
        specs = maps if isinstance(maps, list) else [maps] * self.num_envs
        if len(specs) != self.num_envs:
            raise ValueError(f"maps has {len(specs)} entries for {self.num_envs} robots")
        parsed: dict[int, TaskSampler] = {}  # parse each distinct spec once
        samplers = [parsed.setdefault(id(s), as_sampler(s)) for s in specs]
        if threads is None:
            threads = int(os.environ.get(THREADS_VARIABLE, "1"))
        self.batch = NavBatch(self.num_envs, self.config, samplers, threads)
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = spaces.Discrete(self.config.robot.n_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = None
        self._default_seed = seed
        self._seeded = False
        self._ready = False

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        options = options or {}
        mask = np.asarray(options.get("reset_mask", np.ones(self.num_envs, bool)), dtype=bool)
        if mask.shape != (self.num_envs,):
            raise ValueError(f"reset_mask must have shape ({self.num_envs},)")
        if seed is None and not self._seeded:
            seed = self._default_seed
        if isinstance(seed, int | np.integer):
            super().reset(seed=int(seed))
            seed = [int(seed) + i for i in range(self.num_envs)]
        if seed is not None or not self._seeded:
            seeds = list(seed) if seed is not None else [None] * self.num_envs
            if len(seeds) != self.num_envs:
                raise ValueError(f"need {self.num_envs} seeds, got {len(seeds)}")
            fresh = [s if s is not None else int(self.np_random.integers(2**62)) for s in seeds]
            states = [seed_state(seeding.np_random(s)[0]) for s in fresh]
            self.batch.seed(np.arange(self.num_envs), states)
            self._seeded = True
        indices = np.flatnonzero(mask)
        tasks = options.get("tasks")
        discs = options.get("obstacles")
        for name, given in (("tasks", tasks), ("obstacles", discs)):
            if given is not None and len(given) != self.num_envs:
                raise ValueError(f"options[{name!r}] needs one entry (or None) per robot")
        self.batch.reset(
            indices,
            None if tasks is None else [tasks[i] for i in indices],
            None if discs is None else [discs[i] for i in indices],
        )
        self._ready = True
        return self.batch.obs.copy(), {}

    def step(self, actions):
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        b = self.batch
        n_done = b.step(actions, autoreset=True)
        info: dict[str, Any] = {}
        if n_done:
            done = b.done.copy()
            info = {
                "final_obs": b.final_obs.copy(),
                "_final_obs": done,
                "final_info": {
                    "outcome": b.final_outcome.copy(),
                    "path_length": b.final_path_length.copy(),
                    "steps": b.final_steps.copy(),
                    "pose": b.final_pose.copy(),
                    "start": b.final_start.copy(),
                    "goal": b.final_goal.copy(),
                    "map_index": b.bank.emap[b.final_entry],
                },
                "_final_info": done,
            }
        return b.obs.copy(), b.reward.copy(), b.terminated.copy(), b.truncated.copy(), info

    def close_extras(self, **kwargs: Any) -> None:
        self.batch.close()

    def poses(self) -> np.ndarray:
        """Current (x, y, theta) of every robot, ``(num_envs, 3)``."""
        return self.batch.pose()

    def tasks(self) -> list:
        """The task each robot is driving now."""
        return [self.batch.task(i) for i in range(self.num_envs)]

    def final_task(self, i: int):
        """The task of robot ``i``'s episode that ended in the last step."""
        return self.batch.final_task(i)

    def grid(self, map_index: int):
        """The map with ``map_index`` (as in ``final_info["map_index"]``)."""
        return self.batch.bank.grids[int(map_index)]
