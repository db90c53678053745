"""Fixed, seeded evaluation sets and the batched runner that measures a policy on them.

Evaluation sets (``make_eval_set``), all reproducible from ``(family, n_episodes, seed)``:

* ``unseen``: generated maps never used in training. Training maps (``worlds.tasks``)
  use generator seeds in ``[0, TRAIN_SEEDS)``; episode ``i`` of set seed ``s`` uses the map
  seed ``TRAIN_SEEDS + s * SEED_STRIDE + i``, so the two never meet. Families go round
  robin over ``families`` (default ``worlds.tasks.MIXED_FAMILIES``: rects, discs, rooms),
  ``size`` x ``size`` cells, start and goal from ``worlds.generators.generate_task``.
* ``dynamic``: the same maps and tasks with ``obstacles`` moving discs (default 4,
  bouncing) placed by the environment from the episode seed.
* ``movingai``: the MovingAI arena map (``/work/shared/data/movingai`` or ``path``) with
  its scenarios, ``n_episodes`` of them drawn without replacement from the set seed.
* a map spec naming files (``make_map_eval_set``; ``navlearn evaluate --map``): a user's map_server,
  MovingAI or ASCII maps (:mod:`worlds.tasks`), the scenarios they carry or pairs drawn by A*
  distance buckets from the set seed (never the training pool's seed).

Every episode also carries its environment seed (``s * SEED_STRIDE + i``), which fixes
the start heading, the noise and the moving discs.

Every episode also records its map family (``map_family``: the generator family, ``rects``,
``discs`` or ``rooms``, or the MovingAI map's name), for per-family splits
(:mod:`agents.evaluation.compare`). Headline figures use :data:`HEADLINE_EPISODES` episodes
per set.

``evaluate(policy, eval_set)`` runs each wave of up to ``max_batch`` episodes as one
``NavigationVectorEnv`` batch, robot ``i`` on task ``i`` (robots that finish early keep
driving auto-reset episodes that are ignored), records each first episode's trajectory
and returns an :class:`EvalResult`: per-family :class:`~agents.evaluation.metrics.FamilyMetrics`
and per-episode :class:`EpisodeRecord`. ``EvalResult.to_dict()`` is JSON-ready. Robot ``i``'s
episode depends only on its task and seed, never on the wave it runs in, so ``max_batch``
changes the speed, not the results (tested).

Speed: the policy is called on one ``(max_batch, obs_dim)`` batch per step with BLAS held to
one thread. Matrix products this small gain nothing from more threads, and on a machine whose
cores are busy OpenBLAS's waiting threads made each call of a 128x128 MLP many times slower
(``bench/evaluation.py`` times the policy call both ways; results/evaluation/). The limit is
process-wide (threadpoolctl) and lifted when ``evaluate`` returns, so a thread training with
torch's BLAS at the same moment in the same process runs on one BLAS thread meanwhile.

A ``Policy`` is any callable mapping an observation batch ``(n, obs_dim)`` float32 to
actions ``(n,)`` int64, greedy for evaluation (see ``agents.imitation.policy.load_policy``). A
policy that also reads the robots' scans and history (:class:`agents.shield.ScanPolicy`: a shielded
policy, whose disc tracker follows the discs from frame to frame, :mod:`agents.disc_tracker`) is
driven through its ``scan_actor``: each step it gets the observations, the rays the world cast (m)
and which robots start an episode.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from agents.evaluation.metrics import FamilyMetrics, point_clearance, summarize
from agents.planning.astar import astar
from agents.shield import ScanPolicy
from worlds.config import NavConfig, ObstacleConfig, check_observation, with_observation
from worlds.generators import generate_task
from worlds.maps import Task, clearance, load_movingai, load_scenarios
from worlds.outcomes import OUTCOME_NAMES
from worlds.tasks import MIXED_FAMILIES, TRAIN_SEEDS, TaskSampler, file_tasks, parse_map_spec, spec_options
from worlds.vector_env import NavigationVectorEnv

Policy = Callable[[np.ndarray], np.ndarray]
EVAL_FAMILIES = ("unseen", "dynamic", "movingai")
HEADLINE_EPISODES = 500
"""episodes per evaluation set for headline figures (a 95% Wilson interval of about +-1.3 points at 98%)"""
SEED_STRIDE = 1_000_003
"""seeds of set ``s`` start at ``s * SEED_STRIDE``: sets with different seeds never share an episode"""
MOVINGAI_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "movingai"


@dataclass(frozen=True)
class EvalSet:
    """A fixed list of tasks with their env seeds and the moving-disc settings."""

    family: str
    tasks: tuple[Task, ...]
    seeds: tuple[int, ...]
    shortest: np.ndarray
    """grid A* length (m) of each task"""
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)
    map_families: tuple[str, ...] = ()
    """map family of each task (generator family, or the MovingAI map's name)"""

    def __post_init__(self) -> None:
        if len(self.map_families) != len(self.tasks):
            raise ValueError(f"map_families has {len(self.map_families)} entries for {len(self.tasks)} tasks")

    def __len__(self) -> int:
        return len(self.tasks)


def make_eval_set(
    family: str,
    n_episodes: int,
    seed: int = 0,
    size: int = 16,
    families: Sequence[str] = MIXED_FAMILIES,
    obstacles: ObstacleConfig | None = None,
    path: str | Path | None = None,
) -> EvalSet:
    """The evaluation set ``family`` (``unseen``, ``dynamic`` or ``movingai``; see the module
    docstring). ``obstacles`` overrides the moving discs of ``dynamic`` (default 4 bouncing)."""
    if family not in EVAL_FAMILIES:
        raise ValueError(f"unknown evaluation family {family!r}; choose one of {', '.join(EVAL_FAMILIES)}")
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be positive, got {n_episodes}")
    base = seed * SEED_STRIDE
    if family == "movingai":
        root = Path(path) if path else MOVINGAI_DIR / "arena.map.scen"
        scen_path = root if root.suffix == ".scen" else root / "arena.map.scen"
        grid = load_movingai(scen_path.parent / scen_path.name.removesuffix(".scen"))
        scenarios = load_scenarios(scen_path, grid)
        picks = np.random.default_rng([seed, 7]).permutation(len(scenarios))
        if n_episodes > len(scenarios):
            raise ValueError(f"{scen_path} has {len(scenarios)} scenarios, asked for {n_episodes}")
        tasks = [Task(grid, scenarios[k].start, scenarios[k].goal, grid.name) for k in picks[:n_episodes]]
        map_families = [grid.name] * n_episodes
        discs = ObstacleConfig(count=0)
    else:
        map_families = [families[i % len(families)] for i in range(n_episodes)]
        tasks = [generate_task(f, size, size, TRAIN_SEEDS + base + i) for i, f in enumerate(map_families)]
        discs = (obstacles or ObstacleConfig(count=4)) if family == "dynamic" else ObstacleConfig(count=0)
    shortest = np.array([astar(t.grid, t.start, t.goal).length for t in tasks])
    if not np.isfinite(shortest).all():
        raise ValueError(f"evaluation set {family!r} holds a task without a grid path")
    seeds = tuple(base + i for i in range(n_episodes))
    return EvalSet(family, tuple(tasks), seeds, shortest, discs, tuple(map_families))


def make_map_eval_set(
    spec: str | TaskSampler,
    n_episodes: int,
    seed: int = 0,
    obstacles: ObstacleConfig | None = None,
    name: str | None = None,
) -> EvalSet:
    """An evaluation set on the map files of ``spec`` (a file, a directory, with ``key=value`` map
    options; :mod:`worlds.tasks`): ``n_episodes`` tasks split over the files, a file's own scenarios
    (MovingAI ``.scen``, ASCII S/G) in a seeded order, else pairs drawn with the seed ``TRAIN_SEEDS +
    seed`` (training pools use small seeds). ``obstacles``: moving discs (default none). The set is
    called ``name`` (default the first file's name, e.g. ``office``); each episode's map family is
    its map's name. ``spec`` may be the sampler :func:`worlds.tasks.parse_map_spec` made of it."""
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be positive, got {n_episodes}")
    sampler = spec if isinstance(spec, TaskSampler) else parse_map_spec(spec)
    if not sampler.maps:
        raise ValueError(f"{spec!r} names no map file (generated maps: use the unseen/dynamic sets)")
    tasks = file_tasks(sampler.maps, spec_options(sampler.spec), n_episodes, TRAIN_SEEDS + seed)[:n_episodes]
    shortest = np.array([astar(t.grid, t.start, t.goal).length for t in tasks])
    if not np.isfinite(shortest).all():
        raise ValueError(f"evaluation set {spec!r} holds a task without a grid path")
    base = seed * SEED_STRIDE
    seeds = tuple(base + i for i in range(len(tasks)))
    label = name or sampler.maps[0].grid.name + (
        "" if len(sampler.maps) == 1 else f"+{len(sampler.maps) - 1}"
    )
    discs = obstacles or ObstacleConfig(count=0)
    return EvalSet(label, tuple(tasks), seeds, shortest, discs, tuple(t.map_id for t in tasks))


@dataclass
class EpisodeRecord:
    """One evaluated episode."""

    task: Task
    seed: int
    outcome: int
    path_length: float
    steps: int
    shortest: float
    min_clearance: float
    trajectory: np.ndarray
    """poses ``(steps + 1, 3)``: x, y, theta"""
    map_family: str = ""
    """see :attr:`EvalSet.map_families`"""
    disc_tracks: np.ndarray | None = None
    """the moving discs ``(steps + 1, discs, 3)``: x, y, radius at each pose of ``trajectory`` (None
    without discs), so a picture of a dynamic episode shows what the robot had to avoid"""

    def to_dict(self, with_trajectory: bool = False) -> dict:
        out = {
            "map_id": self.task.map_id,
            "map_family": self.map_family,
            "start": list(self.task.start),
            "goal": list(self.task.goal),
            "seed": self.seed,
            "outcome": OUTCOME_NAMES[self.outcome],
            "path_length": round(self.path_length, 4),
            "steps": self.steps,
            "shortest": round(self.shortest, 4),
            "min_clearance": round(self.min_clearance, 4),
        }
        if with_trajectory:
            out["trajectory"] = np.round(self.trajectory, 3).tolist()
        return out


@dataclass
class EvalResult:
    """Metrics and episodes per evaluation family."""

    metrics: dict[str, FamilyMetrics] = field(default_factory=dict)
    episodes: dict[str, list[EpisodeRecord]] = field(default_factory=dict)

    def to_dict(self, with_episodes: bool = True, with_trajectories: bool = False) -> dict:
        out: dict = {"metrics": {name: m.to_dict() for name, m in self.metrics.items()}}
        if with_episodes:
            out["episodes"] = {
                name: [e.to_dict(with_trajectories) for e in eps] for name, eps in self.episodes.items()
            }
        return out

    def table(self) -> str:
        """The metrics as a fixed-width text table, one row per family."""

        def pct(rate) -> str:
            return f"{100 * rate.value:5.1f} [{100 * rate.low:4.1f},{100 * rate.high:5.1f}]"

        def num(v: float, fmt: str = "5.2f") -> str:
            return format(v, fmt) if math.isfinite(v) else "  -  "

        head = (
            f"{'family':<9} {'n':>4}  {'success % [95% CI]':<19} {'coll.static %':<19} "
            f"{'coll.dynamic %':<19} {'timeout %':<19} {'SPL':>5} {'len/A*':>6} {'steps':>6} {'clear.m':>7}"
        )
        rows = [head, "-" * len(head)]
        for name, m in self.metrics.items():
            rows.append(
                f"{name:<9} {m.episodes:>4}  {pct(m.success):<19} {pct(m.collision_static):<19} "
                f"{pct(m.collision_dynamic):<19} {pct(m.timeout):<19} {num(m.spl):>5} "
                f"{num(m.path_ratio, '6.3f'):>6} {num(m.time_to_goal, '6.1f'):>6} "
                f"{num(m.min_clearance_mean, '7.3f'):>7}"
            )
        return "\n".join(rows)


def fixed_sampler(tasks: Sequence[Task], key: str) -> TaskSampler:
    """A sampler over exactly ``tasks`` so the env's task pool holds nothing else."""
    pool = list(tasks)
    return TaskSampler(lambda rng: pool[int(rng.integers(len(pool)))], key, tasks=pool)


def _run_wave(policy: Policy, config: NavConfig, tasks: list[Task], seeds: list[int], key: str):
    """Robot ``i`` drives task ``i`` until its first episode ends. Returns per robot the final
    (outcome, path length, steps), the poses ``(steps + 1, 3)`` and the closest approach to a
    moving disc's edge (inf without discs)."""
    n = len(tasks)
    env = NavigationVectorEnv(n, config, maps=fixed_sampler(tasks, key))
    obs, _ = env.reset(seed=list(seeds), options={"tasks": list(tasks)})
    frames = [env.poses()]  # frames[t][i]: robot i's pose after t steps (final pose at its end)
    dynamic = config.obstacles.count > 0
    disc_gap = np.full(n, np.inf)
    tracks: list[list[np.ndarray]] = [[] for _ in range(n)]  # robot i's discs at each of its poses
    if dynamic:
        disc_gap = np.array([_disc_gap(env, i, frames[0][i]) for i in range(n)])
        for i in range(n):
            tracks[i].append(env.batch.discs(i).copy())
    running, fresh = np.ones(n, bool), np.ones(n, bool)
    outcome, length, steps = np.zeros(n, np.int64), np.zeros(n), np.zeros(n, np.int64)
    act = policy.scan_actor(n) if isinstance(policy, ScanPolicy) else None
    while running.any():
        actions = policy(obs) if act is None else act(obs, env.batch.rays, fresh)
        obs, _, _, _, info = env.step(np.asarray(actions, dtype=np.int64).reshape(n))
        fresh = info["_final_obs"] if info else np.zeros(n, bool)
        poses = env.poses()
        if info:
            ended = running & info["_final_obs"]
            final = info["final_info"]
            poses[ended] = final["pose"][ended]
            outcome[ended], length[ended] = final["outcome"][ended], final["path_length"][ended]
            steps[ended] = final["steps"][ended]
            running &= ~ended
        frames.append(poses)
        if dynamic:
            for i in np.flatnonzero(running):
                disc_gap[i] = min(disc_gap[i], _disc_gap(env, i, poses[i]))
            for i in np.flatnonzero(running | ended if info else running):
                # an ended robot's discs were already reset: its last frame repeats the one before
                tracks[i].append(tracks[i][-1] if info and ended[i] else env.batch.discs(i).copy())
    path = np.stack(frames, axis=1)  # (n, T + 1, 3)
    finals = [(int(outcome[i]), float(length[i]), int(steps[i])) for i in range(n)]
    discs = [np.stack(t[: steps[i] + 1]) if dynamic and len(t[0]) else None for i, t in enumerate(tracks)]
    return finals, [path[i, : steps[i] + 1] for i in range(n)], disc_gap, discs


def _disc_gap(env, i: int, pose: np.ndarray) -> float:
    """Distance from robot ``i``'s centre to the nearest moving disc's edge (inf without discs)."""
    discs = env.batch.discs(i)
    if len(discs) == 0:
        return math.inf
    return float((np.hypot(discs[:, 0] - pose[0], discs[:, 1] - pose[1]) - discs[:, 2]).min())


def evaluate(
    policy: Policy,
    eval_sets: EvalSet | Sequence[EvalSet],
    config: NavConfig | None = None,
    max_batch: int = 512,
) -> EvalResult:
    """Run ``policy`` on every episode of ``eval_sets`` and compute the metrics. ``config`` is
    the robot/sensor/reward setting the policy was trained with (default ``NavConfig()`` with the
    policy's ``observation`` settings when it records them); each set's moving-disc settings
    replace its ``obstacles``. A policy whose recorded observation differs from ``config``'s
    is a ValueError naming the field. BLAS runs on one thread meanwhile (see the module
    docstring)."""
    sets = [eval_sets] if isinstance(eval_sets, EvalSet) else list(eval_sets)
    saved = getattr(policy, "observation", None)
    base = config or NavConfig()
    if saved is not None and config is None:
        base = with_observation(base, saved)
    elif saved is not None:
        check_observation(saved, base)
    with threadpool_limits(limits=1, user_api="blas"):
        return _evaluate(policy, sets, base, max_batch)


def _evaluate(policy: Policy, sets: list[EvalSet], base: NavConfig, max_batch: int) -> EvalResult:
    result = EvalResult()
    for es in sets:
        cfg = replace(base, obstacles=es.obstacles)
        records: list[EpisodeRecord] = []
        for lo in range(0, len(es), max_batch):
            hi = min(lo + max_batch, len(es))
            tasks, seeds = list(es.tasks[lo:hi]), list(es.seeds[lo:hi])
            finals, trajectories, disc_gap, discs = _run_wave(
                policy, cfg, tasks, seeds, f"eval:{es.family}:{seeds[0]}"
            )
            for k, task in enumerate(tasks):
                outcome, length, steps = finals[k]
                traj = trajectories[k]
                static = point_clearance(task.grid, traj[:, :2], clearance(task.grid)).min()
                records.append(
                    EpisodeRecord(
                        task,
                        seeds[k],
                        outcome,
                        length,
                        steps,
                        float(es.shortest[lo + k]),
                        float(min(static, disc_gap[k])),
                        traj,
                        es.map_families[lo + k],
                        discs[k],
                    )
                )
        result.episodes[es.family] = records
        result.metrics[es.family] = summarize(
            outcomes=np.array([r.outcome for r in records]),
            shortest=np.array([r.shortest for r in records]),
            taken=np.array([r.path_length for r in records]),
            steps=np.array([r.steps for r in records]),
            min_clearance=np.array([r.min_clearance for r in records]),
        )
    return result
