"""State and preallocated buffers of a batch of robots, stepped by :mod:`worlds.kernel`.

Both :class:`worlds.env.NavigationEnv` (one robot) and
:class:`worlds.vector_env.NavigationVectorEnv` (N robots) are thin layers over this
class, so their dynamics are the same code.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from worlds import kernel, perception
from worlds.bank import merged_bank, private_copy
from worlds.config import NavConfig, step_limit
from worlds.gridsearch import grid_search, new_work
from worlds.maps import Task
from worlds.obstacles import DiscObstacles
from worlds.tasks import TaskSampler


class NavBatch:
    """``n`` robots, robot ``i`` drawing its episodes from ``samplers[i]``'s task pool."""

    def __init__(self, n: int, config: NavConfig, samplers: list[TaskSampler], threads: int = 1) -> None:
        if n < 1:
            raise ValueError(f"need at least one robot, got {n}")
        if len(samplers) != n:
            raise ValueError(f"need one task sampler per robot: {len(samplers)} for {n} robots")
        self.n, self.config = n, config
        self.threads = max(1, min(int(threads), n))
        self._pool: ThreadPoolExecutor | None = None
        self.bank, pool_lo, pool_n = merged_bank(samplers, config.pool_size, config.pool_seed)
        self._bank_is_shared = True
        self.turns = np.asarray(config.robot.turns, dtype=np.float64)
        angles = config.sensors.ray_angles
        self.beam_c, self.beam_s = np.cos(angles), np.sin(angles)
        # the kernel's rays per stepping thread: directions and work rows for their absolute
        # directions and reciprocals (worlds.kernel._observe)
        work = [tuple(np.zeros(len(angles)) for _ in range(4)) for _ in range(self.threads)]
        self._beams = [(self.beam_c, self.beam_s, *rows) for rows in work]
        self.params = kernel.make_params(config)
        self.obs_dim = perception.observation_dim(config)
        base_dim = config.sensors.n_beams + 3
        f8, i8 = np.float64, np.int64
        self.x, self.y, self.theta, self.gx, self.gy = (np.zeros(n, f8) for _ in range(5))
        self.steps, self.ent, self.outcome = np.zeros(n, i8), np.zeros(n, i8), np.zeros(n, i8)
        self.step_limit = np.zeros(n, i8)  # each robot's step limit; minus max_steps until computed
        self._search: list[tuple] = []  # per stepping thread, the kernel's A* work arrays
        self._fit_search()
        self.map_index = np.zeros(n, i8)
        self.path_length, self.goal_dist = np.zeros(n, f8), np.zeros(n, f8)
        self.start_cell, self.goal_cell = np.zeros((n, 2), i8), np.zeros((n, 2), i8)
        self.rng = np.zeros(n, np.uint64)
        self.pool_lo, self.pool_n = pool_lo, pool_n
        self._alloc_discs(max(config.obstacles.count, 1))
        self.obs = np.zeros((n, self.obs_dim), np.float32)
        self.reward = np.zeros(n, f8)
        self.terminated, self.truncated = np.zeros(n, bool), np.zeros(n, bool)
        self.final_obs = np.zeros((n, self.obs_dim), np.float32)
        self.rays, self.final_rays = np.zeros((n, len(angles)), f8), np.zeros((n, len(angles)), f8)
        # the kernel writes the base observation (readings + goal); worlds.perception builds the
        # observation from it when the config asks for more, else the two are the same arrays
        self.perception = perception.Perception(n, config) if perception.needed(config) else None
        if self.perception is None:
            self.base_obs, self.base_final = self.obs, self.final_obs
        else:
            self.base_obs = np.zeros((n, base_dim), np.float32)
            self.base_final = np.zeros((n, base_dim), np.float32)
        self.final_outcome, self.final_steps, self.final_entry = (
            np.zeros(n, i8),
            np.zeros(n, i8),
            np.zeros(n, i8),
        )
        self.final_path_length, self.final_pose = np.zeros(n, f8), np.zeros((n, 3), f8)
        self.final_start, self.final_goal = np.zeros((n, 2), i8), np.zeros((n, 2), i8)
        self.done = np.zeros(n, bool)

    def _fit_search(self) -> None:
        """Work arrays for the kernel's step-limit A* (one set per stepping thread), as large as the
        bank's largest map."""
        cells = self.bank.max_cells
        if not self._search or self._search[0][0].shape[0] < cells:
            self._search = [new_work(cells) for _ in range(self.threads)]

    def _alloc_discs(self, capacity: int, keep: int = 0) -> None:
        old = getattr(self, "disc_arrays", None)
        arrays = [np.zeros((self.n, capacity), np.float64) for _ in range(5)]
        arrays.append(np.zeros((self.n, capacity), np.bool_))
        arrays += [np.zeros((self.n, capacity), np.float64) for _ in range(4)]
        count = np.zeros(self.n, np.int64)
        if old is not None and keep:
            for new, prev in zip(arrays, old[:10], strict=True):
                new[:, :keep] = prev[:, :keep]
            count[:] = old[10]
        self.disc_arrays = (*arrays, count)
        self.capacity = capacity

    # ----------------------------------------------------------------- kernel views
    def _robots(self) -> tuple:
        motion = (self.x, self.y, self.theta, self.gx, self.gy, self.steps, self.path_length, self.goal_dist)
        episode = (
            self.ent,
            self.start_cell,
            self.goal_cell,
            self.outcome,
            self.rng,
            self.pool_lo,
            self.pool_n,
        )
        return (*motion, *episode, self.map_index, self.step_limit)

    def _finals(self) -> tuple:
        return (self.base_final, self.final_rays, self.final_outcome, self.final_path_length,
                self.final_steps, self.final_pose, self.final_entry, self.final_start, self.final_goal,
                self.done)  # fmt: skip

    # ----------------------------------------------------------------- operations
    def seed(self, indices: np.ndarray, states: np.ndarray) -> None:
        """Set the random streams of robots ``indices`` (see :func:`worlds.rng.seed_state`)."""
        self.rng[np.asarray(indices)] = np.asarray(states, dtype=np.uint64)

    def reset(
        self,
        indices: np.ndarray,
        tasks: list[Task | None] | None = None,
        obstacles: list[DiscObstacles | None] | None = None,
    ) -> None:
        """Start new episodes for robots ``indices``: given tasks/discs where not None, drawn otherwise."""
        indices = np.asarray(indices, dtype=np.int64)
        forced = np.full(len(indices), -1, dtype=np.int64)
        if tasks is not None and any(t is not None for t in tasks):
            if self._bank_is_shared:
                self.bank, self._bank_is_shared = private_copy(self.bank), False
            chosen = [(k, t) for k, t in enumerate(tasks) if t is not None]
            in_use = np.concatenate([self.ent, self.final_entry])
            entries, remap = self.bank.add_tasks([t for _, t in chosen], in_use)
            if remap is not None:
                self.ent[:] = remap[self.ent]
                self.final_entry[:] = remap[self.final_entry]
            forced[[k for k, _ in chosen]] = entries
            self._fit_search()
        keep = np.zeros(len(indices), dtype=np.bool_)
        if obstacles is not None:
            needed = max((len(o) for o in obstacles if o is not None), default=0)
            if needed > self.capacity:
                self._alloc_discs(needed, keep=self.capacity)
            ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby, ocount = self.disc_arrays
            for k, disc in enumerate(obstacles):
                if disc is None:
                    continue
                i, m = indices[k], len(disc)
                keep[k] = True
                ox[i, :m], oy[i, :m] = disc.position.T
                ovx[i, :m], ovy[i, :m] = disc.velocity.T
                orad[i, :m] = disc.radius
                opat[i, :m] = disc.waypoints is not None
                if disc.waypoints is not None:
                    oax[i, :m], oay[i, :m] = disc.waypoints[:, 0].T
                    obx[i, :m], oby[i, :m] = disc.waypoints[:, 1].T
                ocount[i] = m
        drivable = np.ones(len(indices), dtype=np.bool_)
        kernel.reset_some(
            indices, forced, keep, self.bank.kernel_maps(), self.bank.kernel_entries(), self._robots(),
            self.disc_arrays, self.params, self.turns, self._beams[0], self.base_obs, self.rays, drivable,
            self._search[0],
        )  # fmt: skip
        if self.perception is not None:
            self._perceive_fresh(indices)
        stuck = [k for k in np.flatnonzero(~drivable) if forced[k] >= 0]
        if stuck:
            task = self.task(int(indices[stuck[0]]))
            r = self.config.robot
            raise ValueError(
                f"task start {task.start} on map {task.map_id or task.grid.name or '(unnamed)'!r} has no "
                f"collision-free action from any start heading (robot radius {r.radius} m, step {r.step} m)"
            )

    def step(self, actions: np.ndarray, autoreset: bool) -> int:
        """Step every robot with ``actions`` (n,) ints; returns how many episodes ended."""
        actions = np.asarray(actions, dtype=np.int64).reshape(self.n)
        if actions.min() < 0 or actions.max() > len(self.turns):
            raise ValueError(f"actions must be integers in [0, {len(self.turns)}]")
        if self.threads > 1:
            n_done = self._step_threaded(actions, autoreset)
        else:
            n_done = kernel.step_all(
                actions, autoreset, self.bank.kernel_maps(), self.bank.kernel_entries(), self._robots(),
                self.disc_arrays, self.params, self.turns, self._beams[0], self.base_obs, self.rays,
                self.reward, self.terminated, self.truncated, self._finals(), self._search[0],
            )  # fmt: skip
        if self.perception is not None:
            self._perceive_step(actions, autoreset)
        return n_done

    # ----------------------------------------------------------------- observation beyond the kernel's
    def _perceived(self) -> tuple:
        """The state :mod:`worlds.perceive` reads (after the kernel's step or reset)."""
        return (self.x, self.y, self.theta, self.gx, self.gy, self.goal_cell, self.map_index, self.base_obs,
                self.rays)  # fmt: skip

    def _perceive_fresh(self, indices: np.ndarray) -> None:
        """First frames of the episodes robots ``indices`` just started."""
        self.perception.observe_fresh(indices, self.bank.kernel_maps(), self._perceived(), self.obs)

    def _perceive_step(self, actions: np.ndarray, autoreset: bool) -> None:
        """The frames after a step (adding the geodesic reward); for robots that ended and were reset,
        the terminal frame (into final_obs) from the ended episode's memory, then a fresh one."""
        finals = (
            self.final_pose,
            self.final_goal,
            self.final_entry,
            self.base_final,
            self.final_rays,
            self.done,
        )
        self.perception.observe_step(
            actions, autoreset, self.bank.kernel_maps(), self.bank.emap, self._perceived(), finals, self.obs,
            self.final_obs, self.reward,
        )  # fmt: skip

    def _step_threaded(self, actions: np.ndarray, autoreset: bool) -> int:
        """Step ``self.threads`` ranges of robots at once: the calling thread and a pool of
        Python threads each run :func:`worlds.kernel.step_range` (which releases the GIL) on one
        range. Plain threads rather than a numba parallel loop: waiting threads sleep instead
        of spinning, which matters on machines whose cores are busy with other processes."""
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="navlearn-env")

        def arrays(k: int) -> tuple:  # thread k's arguments (its own ray work rows)
            return (
                actions, autoreset, self.bank.kernel_maps(), self.bank.kernel_entries(), self._robots(),
                self.disc_arrays, self.params, self.turns, self._beams[k], self.base_obs, self.rays,
                self.reward, self.terminated, self.truncated, self._finals(), self._search[k],
            )  # fmt: skip

        bounds = [self.n * k // self.threads for k in range(self.threads + 1)]
        others = [
            self._pool.submit(kernel.step_range, bounds[k], bounds[k + 1], *arrays(k))
            for k in range(1, self.threads)
        ]
        n_done = kernel.step_range(bounds[0], bounds[1], *arrays(0))
        return n_done + sum(f.result() for f in others)

    def close(self) -> None:
        """Stop the stepping threads (if any)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    # ----------------------------------------------------------------- reading state
    def pose(self) -> np.ndarray:
        return np.stack([self.x, self.y, self.theta], axis=1)

    def task(self, i: int) -> Task:
        """The task robot ``i`` is driving now (its start and goal may differ from its pool entry's)."""
        return self._task(int(self.ent[i]), self.start_cell[i], self.goal_cell[i])

    def final_task(self, i: int) -> Task:
        """The task of robot ``i``'s episode that ended in the last auto-reset step."""
        return self._task(int(self.final_entry[i]), self.final_start[i], self.final_goal[i])

    def _task(self, entry: int, start: np.ndarray, goal: np.ndarray) -> Task:
        return self.bank.entry_task(entry, (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1])))

    def episode_step_limit(self, i: int) -> int:
        """Robot ``i``'s step limit this episode (:func:`worlds.config.step_limit`). The kernel computes
        it only when an episode reaches ``max_steps``; asked earlier, it is computed here with the same
        A* and kept."""
        if self.step_limit[i] < 0:
            task = self.task(i)
            g, _, _ = grid_search(task.grid.blocked, task.start[0] * task.grid.width + task.start[1],
                                  task.goal[0] * task.grid.width + task.goal[1], True)  # fmt: skip
            length = g[task.goal[0] * task.grid.width + task.goal[1]] * task.grid.cell_size
            self.step_limit[i] = step_limit(self.config, float(length))
        return int(self.step_limit[i])

    def discs(self, i: int) -> np.ndarray:
        """Robot ``i``'s moving discs now, ``(k, 3)``: x, y, radius."""
        ox, oy, _, _, orad, *_, ocount = self.disc_arrays
        k = int(ocount[i])
        return np.stack([ox[i, :k], oy[i, :k], orad[i, :k]], axis=1)
