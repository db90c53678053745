"""The drive's observation builder is the world's: fed the world's rays and poses, it gives the
world's observations (worlds.live.LiveObserver), and workspaces put the goal at a cell centre."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from worlds.config import (
    LEARNING_NAV,
    LEARNING_PLAN_NAV,
    OBSERVATIONS,
    ObservationConfig,
)
from worlds.env import NavigationEnv
from worlds.generators import generate_task
from worlds.live import LiveObserver, Workspace
from worlds.tasks import TRAIN_SEEDS


def noiseless(nav):
    return replace(
        nav,
        robot=replace(nav.robot, trans_noise=0.0, rot_noise=0.0),
        sensors=replace(nav.sensors, noise_std=0.0),
    )


@pytest.mark.parametrize(
    "nav",
    [
        LEARNING_NAV,
        LEARNING_PLAN_NAV,
        OBSERVATIONS["plain"],
        replace(
            LEARNING_NAV,
            observation=ObservationConfig(
                subgoal="own_map", previous_action=True, frame_stack=2, patch_size=5, range_rate=True
            ),
        ),
    ],
    ids=["learning", "learning_plan", "plain", "everything"],
)
def test_live_observer_equals_the_world(nav):
    """Step the world with a seeded random policy; at every step the live builder, given the same
    rays and pose on the map's own grid, writes the world's observation bit for bit."""
    nav = noiseless(nav)
    rng = np.random.default_rng(3)
    for seed in range(3):
        task = generate_task(("rects", "discs", "rooms")[seed], 16, 16, TRAIN_SEEDS + 77 + seed)
        env = NavigationEnv(nav, maps="rooms:16")
        obs, info = env.reset(seed=seed, options={"task": task})
        grid = task.grid
        live = LiveObserver(nav)
        ws = Workspace(0.0, 0.0, grid.height, grid.width, grid.cell_size)
        goal = ((task.goal[1] + 0.5) * grid.cell_size, (task.goal[0] + 0.5) * grid.cell_size)
        live.start(ws, goal)
        got = live.observe(env.batch.rays[0], tuple(info["pose"]))
        np.testing.assert_array_equal(got, obs)
        for _ in range(40):
            action = int(rng.integers(nav.robot.n_actions))
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
            got = live.observe(env.batch.rays[0], tuple(info["pose"]), action)
            np.testing.assert_array_equal(got, obs)


def test_workspace_puts_the_goal_at_a_cell_centre_and_covers_both():
    ws = Workspace.around((1.3, -2.2), (7.9, 4.05), margin=3.0, cell=0.5)
    r, c = ws.cell_of(7.9, 4.05)
    assert math.isclose(ws.origin_x + (c + 0.5) * ws.cell, 7.9)
    assert math.isclose(ws.origin_y + (r + 0.5) * ws.cell, 4.05)
    for x, y in ((1.3 - 3, -2.2 - 3), (7.9 + 3, 4.05 + 3)):
        r, c = ws.cell_of(x, y)
        assert 0 <= r < ws.height and 0 <= c < ws.width


def test_workspace_refuses_a_goal_too_far():
    with pytest.raises(ValueError, match="exceeds"):
        Workspace.around((0.0, 0.0), (5000.0, 0.0), margin=1.0, cell=1.0)


def test_observe_needs_a_goal_and_the_action():
    live = LiveObserver(LEARNING_NAV)
    rays = np.full(len(LEARNING_NAV.sensors.ray_angles), 6.0)
    with pytest.raises(RuntimeError, match="before start"):
        live.observe(rays, (0.0, 0.0, 0.0))
    live.start(Workspace.around((0.0, 0.0), (3.0, 0.0), 2.0, 1.0), (3.0, 0.0))
    live.observe(rays, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="action"):
        live.observe(rays, (0.1, 0.0, 0.0))


@pytest.mark.parametrize("error", [0.01, 0.03])
def test_snapped_hits_give_the_worlds_own_map_from_noisy_ranges(error):
    """Ranges off by up to a few centimetres (noise), padded and snapped (``snap_hits``), write the
    world's own map with a third or less of the wrong cells the same ranges write unsnapped (a
    ray grazing a corner can still end in the wrong cell)."""
    from services.drive.scan import pad_returns

    nav = noiseless(replace(LEARNING_NAV, observation=ObservationConfig(subgoal="own_map", patch_size=5)))
    rng = np.random.default_rng(11)
    wrong = {"snapped": 0, "plain": 0}
    steps = 0
    for seed in range(12):
        task = generate_task("rooms", 16, 16, TRAIN_SEEDS + 91 + seed)
        env = NavigationEnv(nav, maps="rooms:16")
        _, info = env.reset(seed=seed, options={"task": task})
        grid = task.grid
        goal = ((task.goal[1] + 0.5) * grid.cell_size, (task.goal[0] + 0.5) * grid.cell_size)
        snapped, plain = LiveObserver(nav, snap_hits=True), LiveObserver(nav)
        ws = Workspace(0.0, 0.0, grid.height, grid.width, grid.cell_size)
        for live in (snapped, plain):
            live.start(ws, goal)
        action = -1
        for _ in range(30):
            exact = env.batch.rays[0]
            noisy = np.where(exact < 6.0, exact + rng.uniform(-error, error, exact.shape), exact)
            rays = pad_returns(noisy, 0.05, 6.0)
            snapped.observe(rays, tuple(info["pose"]), action)
            plain.observe(rays, tuple(info["pose"]), action)
            world_map = env.batch.perception.occ[0]
            wrong["snapped"] += int((snapped.perception.occ[0] != world_map).sum())
            wrong["plain"] += int((plain.perception.occ[0] != world_map).sum())
            steps += 1
            action = int(rng.integers(nav.robot.n_actions))
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
    # wrong cells of the own map, summed over the steps (a wrong cell counts at every step it stays):
    # measured 320 snapped against 1115 unsnapped over 134 steps
    assert steps > 100 and wrong["plain"] >= 3 * max(wrong["snapped"], 1), (wrong, steps)
