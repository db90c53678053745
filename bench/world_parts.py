"""Where the robot world's time goes at the learning observation (issue 14's 200k target): the
parts of a step and of a reset, each timed on realistic batches, per CPU second of this process.

* **step**: :class:`~worlds.vector_env.NavigationVectorEnv` (``LEARNING_NAV``, one thread) stepped
  with random or goal-seeking actions; per robot-step the whole ``env.step``, the compiled kernel
  call (:func:`worlds.kernel.step_all`: motion, 96 exact rays, noise, resets) and the compiled
  perception call (:func:`worlds.perceive.perceive_step`: own map, subgoal A*, geodesic reward,
  terminal and first frames), the rest being Python glue (and the policy, for goal-seeking);
  how many episodes end and how many own-map searches run per robot-step.
* **reset**: every robot reset at once, many times: the kernel's reset and the first frame, the
  latter also without the geodesic reward and without the subgoal.
* **searches alone**: numba loops over work recorded from a rollout, caches warm: the 96 rays of a
  pose (one by one, each ray's direction and reciprocals computed at the head of its traversal as
  :func:`worlds.sensors.cast_from` does, or side by side as the kernel casts them: every direction,
  then every reciprocal, then the traversals), the own-map A* (:func:`worlds.own_map.waypoint`) of
  a search, the geodesic Dijkstra of a reset settled out to the start (:mod:`worlds.geodesic`).

The machine is shared, so every figure is the minimum over ``--chunks`` chunks (of 100 env steps,
or one pass over the recorded work): the least disturbed one. Figures in microseconds.

    python -m bench.world_parts --robots 256 --policies random   # human lines, then one JSON object
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time

import numpy as np
from numba import njit

from bench.env_throughput import make_policy
from worlds import batch as batch_module
from worlds.config import LEARNING_NAV, NavConfig
from worlds.geodesic import field_distance, move_masks, new_fields, start_field
from worlds.gridsearch import new_work
from worlds.own_map import waypoint
from worlds.sensors import cast_along, cast_from, ray_origin, reciprocal
from worlds.vector_env import NavigationVectorEnv


def _timed(fn, clock: list[float]):
    """``fn`` wrapped to add its CPU time to ``clock[0]``."""

    def wrapper(*args):
        t = time.process_time()
        out = fn(*args)
        clock[0] += time.process_time() - t
        return out

    return wrapper


def step_parts(config: NavConfig, n: int, kind: str, chunks: int, seed: int) -> dict:
    """Per robot-step: env.step, kernel call, perception call (minimum over chunks of 100 steps)."""
    env = NavigationVectorEnv(n, config, threads=1)
    obs, _ = env.reset(seed=seed)
    b, kernel_clock, percept_clock = env.batch, [0.0], [0.0]
    policy = make_policy(config, kind)
    actions = np.random.default_rng(seed).integers(config.robot.n_actions, size=(256, n))
    act = (lambda t, o: actions[t % 256]) if policy is None else (lambda t, o: policy(o))
    step_all = batch_module.kernel.step_all
    batch_module.kernel.step_all = _timed(step_all, kernel_clock)
    b.perception.observe_step = _timed(b.perception.observe_step, percept_clock)
    try:
        for t in range(3):
            obs, *_ = env.step(act(t, obs))
        best, s, ended, searches0 = None, 0, 0, b.perception.searches.astype(np.int64).sum()
        for _ in range(chunks):
            kernel_clock[0] = percept_clock[0] = 0.0
            t0 = time.process_time()
            for _ in range(100):
                obs, _, terminated, truncated, _ = env.step(act(s, obs))
                ended += int(np.count_nonzero(terminated | truncated))
                s += 1
            row = [(time.process_time() - t0), kernel_clock[0], percept_clock[0]]
            best = row if best is None or row[0] < best[0] else best
        searches = b.perception.searches.astype(np.int64).sum() - searches0  # (no wrap in a short run)
    finally:
        batch_module.kernel.step_all = step_all
    per = 1e6 / (100 * n)
    total, kern, perc = (v * per for v in best)
    return {
        "robots": n,
        "policy": kind,
        "us_per_robot_step": total,
        "kernel": kern,
        "perception": perc,
        "glue_and_policy": total - kern - perc,
        "robot_steps_per_cpu_s": 1e6 / total,
        "episodes_per_robot_step": ended / (s * n),
        "searches_per_robot_step": searches / (s * n),
    }


def reset_parts(config: NavConfig, n: int, chunks: int, seed: int) -> dict:
    """Per robot reset: the kernel's reset and the first frame (with every part, without the geodesic
    reward, without the subgoal), minimum over chunks of 20 resets of all robots."""
    variants = {
        "first_frame": config,
        "first_frame_without_geodesic": dataclasses.replace(
            config, rewards=dataclasses.replace(config.rewards, geodesic_progress=0.0)
        ),
        "first_frame_without_subgoal": dataclasses.replace(
            config, observation=dataclasses.replace(config.observation, subgoal="none")
        ),
    }
    out, reset_some = {}, batch_module.kernel.reset_some
    for name, cfg in variants.items():
        env = NavigationVectorEnv(n, cfg, threads=1)
        env.reset(seed=seed)
        b, kernel_clock, percept_clock = env.batch, [0.0], [0.0]
        batch_module.kernel.reset_some = _timed(reset_some, kernel_clock)
        b._perceive_fresh = _timed(b._perceive_fresh, percept_clock)
        try:
            everyone, best = np.arange(n), None
            for _ in range(chunks):
                kernel_clock[0] = percept_clock[0] = 0.0
                for _ in range(20):
                    b.reset(everyone)
                row = (kernel_clock[0] * 1e6 / (20 * n), percept_clock[0] * 1e6 / (20 * n))
                best = row if best is None else (min(best[0], row[0]), min(best[1], row[1]))
        finally:
            batch_module.kernel.reset_some = reset_some
        out[name] = best[1]
        if name == "first_frame":
            out["kernel_reset"] = best[0]
    return out


@njit(cache=False)
def _rays(field, moff, mh, mw, mcell, poses, maps, beam_c, beam_s, max_range, out):
    for i in range(poses.shape[0]):
        m = maps[i]
        off, height, width, cell = moff[m], mh[m], mw[m], mcell[m]
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        idx, col, row, px, py = ray_origin(field, off, height, width, cell, poses[i, 0], poses[i, 1])
        for k in range(beam_c.shape[0]):
            dx, dy = c * beam_c[k] - s * beam_s[k], s * beam_c[k] + c * beam_s[k]
            r = (
                cast_from(field, off, width, idx, col, row, px, py, dx, dy, max_range / cell)
                if idx >= 0
                else 0.0
            )
            out[i, k] = r


@njit(cache=False)
def _rays_side_by_side(field, moff, mh, mw, mcell, poses, maps, beam_c, beam_s, max_range, out, work):
    """:func:`_rays` the kernel's way: every direction, then every reciprocal, then the traversals."""
    ray_dx, ray_dy, inv_dx, inv_dy = work
    for i in range(poses.shape[0]):
        m = maps[i]
        off, height, width, cell = moff[m], mh[m], mw[m], mcell[m]
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        idx, col, row, px, py = ray_origin(field, off, height, width, cell, poses[i, 0], poses[i, 1])
        for k in range(beam_c.shape[0]):
            ray_dx[k], ray_dy[k] = c * beam_c[k] - s * beam_s[k], s * beam_c[k] + c * beam_s[k]
        for k in range(beam_c.shape[0]):
            inv_dx[k], inv_dy[k] = reciprocal(ray_dx[k]), reciprocal(ray_dy[k])
        for k in range(beam_c.shape[0]):
            r = 0.0
            if idx >= 0:
                r = cast_along(field, off, width, idx, col, row, px, py, ray_dx[k], ray_dy[k], inv_dx[k],
                               inv_dy[k], max_range / cell)  # fmt: skip
            out[i, k] = r


@njit(cache=False)
def _searches(plans, no_levels, height, width, cell, xs, ys, goals, along, work, exam, out):
    for k in range(plans.shape[0]):
        out[k] = waypoint(plans[k], *no_levels, height, width, cell, xs[k], ys[k], goals[k, 0], goals[k, 1],
                          along, work, exam, k + 1)[0]  # fmt: skip


@njit(cache=False)
def _settles(moves, moff, mh, mw, mcell, maps, goals, xs, ys, geo, out):
    for k in range(maps.shape[0]):
        m = maps[k]
        stride = mw[m] + 2
        start_field(moves, moff[m], stride, (goals[k, 0] + 1) * stride + goals[k, 1] + 1, geo, 0, True)
        out[k] = field_distance(moves, moff[m], mh[m], mw[m], geo, 0, mcell[m], xs[k], ys[k])


def _best(fn, args, chunks: int, count: int) -> float:
    fn(*args)  # compile
    best = math.inf
    for _ in range(chunks):
        t = time.process_time()
        fn(*args)
        best = min(best, time.process_time() - t)
    return best * 1e6 / count


def searches_alone(config: NavConfig, n: int, chunks: int, seed: int) -> dict:
    """Recorded from 60 random-action steps of ``n`` robots: poses (96 rays each), own-map searches
    (grid, robot, goal) and resets (map, goal, start); each replayed in a numba loop."""
    env = NavigationVectorEnv(n, config, threads=1)
    env.reset(seed=seed)
    b, p = env.batch, env.batch.perception
    rng = np.random.default_rng(seed)
    poses, maps, plans, search_at, resets = [], [], [], [], []
    for _ in range(60):
        before = p.searches.copy()
        env.step(rng.integers(config.robot.n_actions, size=n))
        poses.append(b.pose())
        maps.append(b.map_index.copy())
        for i in np.flatnonzero((p.searches != before) & ~b.done):  # searched from the current pose
            plans.append(p.plan[i].copy())
            search_at.append((b.x[i], b.y[i], b.goal_cell[i, 0], b.goal_cell[i, 1]))
        for i in np.flatnonzero(b.done):  # a new episode: its first frame settled its field to the start
            resets.append((b.map_index[i], b.goal_cell[i, 0], b.goal_cell[i, 1], b.x[i], b.y[i]))
    field, moff, mh, mw, mcell = b.bank.kernel_maps()
    if not (np.all(mh == mh[0]) and np.all(mw == mw[0])):
        raise ValueError("searches_alone replays own-map grids of one map size")
    poses, maps = np.concatenate(poses), np.concatenate(maps)
    rays = np.empty((len(poses), len(b.beam_c)))
    at, rs = np.array(search_at), np.array(resets)
    plans = np.stack(plans)
    goals, found = at[:, 2:4].astype(np.int64), np.empty(len(at), np.int64)
    work, exam = new_work(plans.shape[1]), np.zeros(plans.shape[1], np.int32)
    moves, geo, dist = move_masks(field, moff, mh, mw), new_fields(1, plans.shape[1]), np.empty(len(rs))
    h, w, cell, along = int(mh[0]), int(mw[0]), float(mcell[0]), config.observation.subgoal_distance
    ray_args = (field, moff, mh, mw, mcell, poses, maps, b.beam_c, b.beam_s, config.sensors.max_range, rays)
    side_rays = np.empty_like(rays)
    side_args = (*ray_args[:-1], side_rays, tuple(np.empty(len(b.beam_c)) for _ in range(4)))
    # 1 m cells: no inflation (worlds.own_map.waypoint's wide, near and reach, empty)
    no_levels = (np.zeros(0, np.uint8), np.zeros((0, 0), np.int32), np.zeros(0))
    search_args = (plans, no_levels, h, w, cell, at[:, 0], at[:, 1], goals, along, work, exam, found)
    settle_args = (
        moves,
        moff,
        mh,
        mw,
        mcell,
        rs[:, 0].astype(np.int64),
        rs[:, 1:3].astype(np.int64),
        rs[:, 3],
        rs[:, 4],
        geo,
        dist,
    )
    return {
        "rays_per_pose": len(b.beam_c),
        "us_per_pose_rays_one_by_one": _best(_rays, ray_args, chunks, len(poses)),
        "us_per_pose_rays_side_by_side": _best(_rays_side_by_side, side_args, chunks, len(poses)),
        "rays_identical": rays.tobytes() == side_rays.tobytes(),
        "searches_recorded": len(at),
        "us_per_search": _best(_searches, search_args, chunks, len(at)),
        "resets_recorded": len(rs),
        "us_per_reset_settle": _best(_settles, settle_args, chunks, len(rs)),
    }


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=int, default=256)
    parser.add_argument("--policies", nargs="+", choices=["random", "goal"], default=["random", "goal"])
    parser.add_argument("--chunks", type=int, default=8, help="chunks per figure (its minimum is reported)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    config, load_before = LEARNING_NAV, os.getloadavg()
    steps = [step_parts(config, args.robots, kind, args.chunks, args.seed) for kind in args.policies]
    for row in steps:
        print(
            f"{row['policy']:6s} actions, {args.robots} robots: {row['us_per_robot_step']:.2f} us per "
            f"robot-step ({row['robot_steps_per_cpu_s']:,.0f} per CPU s): kernel {row['kernel']:.2f}, "
            f"perception {row['perception']:.2f}, glue/policy {row['glue_and_policy']:.2f}; episodes "
            f"{row['episodes_per_robot_step']:.3f}, searches {row['searches_per_robot_step']:.3f} per "
            "robot-step"
        )
    resets = reset_parts(config, args.robots, args.chunks, args.seed)
    print("per reset (us): " + ", ".join(f"{k} {v:.2f}" for k, v in resets.items()))
    alone = searches_alone(config, args.robots, args.chunks, args.seed)
    print(
        f"alone, caches warm: {alone['rays_per_pose']} rays {alone['us_per_pose_rays_one_by_one']:.2f} us "
        f"per pose one by one, {alone['us_per_pose_rays_side_by_side']:.2f} side by side (identical: "
        f"{alone['rays_identical']}), "
        f"own-map A* {alone['us_per_search']:.2f} us per search ({alone['searches_recorded']} recorded), "
        f"geodesic Dijkstra to the start {alone['us_per_reset_settle']:.2f} us per reset "
        f"({alone['resets_recorded']})"
    )
    print(
        json.dumps(
            {
                "bench": "world_parts",
                "nav": "learning",
                "robots": args.robots,
                "chunks": args.chunks,
                "load_average_before": load_before,
                "load_average_after": os.getloadavg(),
                "steps": steps,
                "reset_us": resets,
                "alone_us": alone,
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
