"""Modified A* over the robot lattice: plans are executable by the env's kinematics and
collision rule, keep away from walls, and avoid known moving discs."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from agents.evaluation.metrics import point_clearance
from agents.planning.astar import distance_field
from agents.planning.lattice import LatticeConfig, plan_lattice
from worlds.config import RobotConfig
from worlds.generators import generate_task
from worlds.maps import GridMap, Task, parse_ascii
from worlds.robot import collides, move

ROBOT = RobotConfig()


def _replay(grid: GridMap, pose, actions) -> np.ndarray:
    """Run ``actions`` through worlds.robot (no noise), asserting no collision; returns the poses."""
    poses = [np.asarray(pose, dtype=np.float64)]
    for a in actions:
        x, y, th = poses[-1]
        nx, ny, nth = move(x, y, th, ROBOT.turns[a], ROBOT.step)
        assert not collides(grid, x, y, nx, ny, ROBOT.radius)
        poses.append(np.array([nx, ny, nth], dtype=np.float64))
    return np.asarray(poses)


def _plan(task: Task, heading: float = 0.0, **kw):
    x, y = task.grid.cell_center(task.start)
    return plan_lattice(
        task.grid, (x, y, heading), task.goal, ROBOT.turns, ROBOT.step, ROBOT.radius, 0.5, **kw
    )


@pytest.mark.parametrize("family", ["rooms", "rects", "discs"])
def test_plans_execute_and_reach_the_goal(family):
    for seed in range(8):
        task = generate_task(family, 16, 16, seed)
        plan = _plan(task, heading=seed * math.pi / 4)
        assert plan.found, (family, seed)
        poses = _replay(task.grid, plan.poses[0], plan.actions)
        np.testing.assert_allclose(poses, plan.poses, atol=1e-9)
        gx, gy = task.grid.cell_center(task.goal)
        assert math.hypot(poses[-1, 0] - gx, poses[-1, 1] - gy) <= 0.5
        assert math.hypot(poses[-2, 0] - gx, poses[-2, 1] - gy) > 0.5 or len(plan.actions) == 1


def test_clearance_cost_keeps_the_path_away_from_walls():
    # An open room with a pillar: the shortest way hugs the pillar, the clearance cost does not.
    blocked = np.zeros((11, 17), dtype=bool)
    blocked[[0, -1], :] = blocked[:, [0, -1]] = True
    blocked[4:7, 8] = True  # the pillar, right on the straight line
    grid = GridMap(blocked)
    task = Task(grid, (5, 3), (5, 13))
    tight = _plan(task, config=LatticeConfig(clearance_weight=0.0))
    safe = _plan(task, config=LatticeConfig(clearance_weight=4.0))
    assert tight.found and safe.found
    tight_gap = point_clearance(grid, tight.poses[:, :2]).min()
    safe_gap = point_clearance(grid, safe.poses[:, :2]).min()
    assert safe_gap > tight_gap + 0.1
    assert tight.length <= safe.length


def test_known_discs_are_avoided():
    grid = GridMap(np.pad(np.zeros((6, 14), bool), 1, constant_values=True))
    task = Task(grid, (3, 2), (3, 12))
    straight = _plan(task)
    disc = np.array([[7.5, 3.5, 0.5]])  # right on the straight line
    around = _plan(task, discs=disc)
    assert straight.found and around.found
    assert np.abs(straight.poses[:, 1] - 3.5).max() < 1e-9
    centre_gap = np.hypot(around.poses[:, 0] - 7.5, around.poses[:, 1] - 3.5).min()
    assert centre_gap > 0.5 + ROBOT.radius
    assert around.length > straight.length


def test_no_plan_cases():
    grid, m = parse_ascii("#####\n#S#G#\n#####\n")
    plan = plan_lattice(
        grid, (*grid.cell_center(m["S"]), 0.0), m["G"], ROBOT.turns, ROBOT.step, ROBOT.radius, 0.5
    )
    assert not plan.found and len(plan.actions) == 0 and math.isinf(plan.cost)
    # starting inside a wall is not a plan either
    inside = plan_lattice(grid, (0.5, 0.5, 0.0), m["G"], ROBOT.turns, ROBOT.step, ROBOT.radius, 0.5)
    assert not inside.found and inside.expanded == 0


def test_collision_rule_matches_the_env():
    from agents.planning.lattice import _sweep_hits

    rng = np.random.default_rng(5)
    grid = GridMap(rng.random((10, 12)) < 0.25, cell_size=1.0)
    start = rng.uniform([0, 0], [12, 10], size=(3000, 2))
    heading = rng.uniform(-np.pi, np.pi, 3000)
    end = start + 0.5 * np.column_stack([np.cos(heading), np.sin(heading)])
    expected = collides(grid, start[:, 0], start[:, 1], end[:, 0], end[:, 1], ROBOT.radius)
    no_discs = np.zeros((0, 3))
    got = [
        _sweep_hits(grid.blocked, 1.0, no_discs, ROBOT.radius, *a, *b)
        for a, b in zip(start, end, strict=True)
    ]
    assert 0.2 < expected.mean() < 0.95  # both outcomes well represented
    np.testing.assert_array_equal(got, expected)


def test_plans_on_a_512_map_take_milliseconds():
    """The closed set holds only the bins a search reaches: on a 512 m map (67 M bins at 0.25 m x 16
    headings) a 40 m plan takes milliseconds of CPU (dense arrays over the map took about 2 s).
    Loose bound in CPU seconds, so a loaded machine does not fail it."""
    blocked = np.zeros((512, 512), dtype=bool)
    blocked[100:300, 250] = True  # a wall to go round
    grid = GridMap(blocked)
    goal = (200, 270)
    field = distance_field(grid, goal)
    plan_lattice(
        grid, (230.5, 200.5, 0.0), goal, ROBOT.turns, ROBOT.step, ROBOT.radius, 0.5, None, None, field
    )
    start = time.process_time()
    plan = plan_lattice(
        grid, (230.5, 200.5, 0.0), goal, ROBOT.turns, ROBOT.step, ROBOT.radius, 0.5, None, None, field
    )
    assert plan.found and plan.length > 20
    assert time.process_time() - start < 0.5
