"""navlearn ros2-sim's robot without Zenoh: the episode it starts is navlearn evaluate's, its
kinematics, collisions, command timeout and lidar."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.policies import load_policy
from services.drive.config import SimConfig
from services.drive.sim import Scene, SimRobot, eval_scene, scene
from worlds.maps import GridMap


@pytest.mark.parametrize("k", [0, 7])
def test_unseen_k_starts_where_navlearn_evaluate_starts(k):
    es = make_eval_set("unseen", k + 1, seed=0)
    record = evaluate(load_policy("pretrained/nnql"), es).episodes["unseen"][k]
    scene = eval_scene(k, 0)
    np.testing.assert_allclose(scene.start, record.trajectory[0])
    cell = record.task.grid.cell_size
    assert scene.goal == ((record.task.goal[1] + 0.5) * cell, (record.task.goal[0] + 0.5) * cell)


def room() -> Scene:
    blocked = np.zeros((6, 8), bool)
    blocked[:, 6] = True  # a wall at x in [6, 7)
    return Scene(GridMap(blocked, 1.0), (1.5, 2.5, 0.0), None, "room")


def test_unicycle_motion_collision_and_command_timeout():
    robot = SimRobot(room(), SimConfig(cmd_timeout=0.5, scan_noise=0.0))
    t = 0.0
    for _ in range(50):  # 1 m/s for 1 s, the command renewed every step
        robot.command(1.0, 0.0, t)
        t += 0.02
        robot.advance(0.02, t)
    assert robot.pose()[0] == pytest.approx(2.5) and robot.path_length == pytest.approx(1.0)
    for _ in range(100):  # the command is not renewed: it expires after 0.5 s
        t += 0.02
        robot.advance(0.02, t)
    assert robot.pose()[0] == pytest.approx(3.0, abs=0.05) and not robot.collided
    for _ in range(200):  # into the wall at x = 6: stops there (disc of 0.25 m), for good
        robot.command(1.0, 0.0, t)
        t += 0.02
        robot.advance(0.02, t)
    assert robot.collided and 5.7 <= robot.pose()[0] <= 5.75 and robot.status()["collided"]


def test_lidar_reads_the_wall_ahead_and_inf_where_nothing_is_in_range():
    config = SimConfig(scan_beams=360, scan_range=6.0, scan_noise=0.0)
    robot = SimRobot(room(), config)
    ranges = robot.scan()
    ahead = int(np.argmin(np.abs(robot.angles)))
    assert ranges.dtype == np.float32 and ranges[ahead] == pytest.approx(4.5, abs=1e-5)
    behind = int(np.argmin(np.abs(np.abs(robot.angles) - math.pi)))
    assert ranges[behind] == pytest.approx(1.5, abs=1e-5)  # the map's border
    assert not np.isinf(ranges).any()
    robot.config = SimConfig(scan_beams=360, scan_range=2.0, scan_noise=0.0)
    assert np.isinf(robot.scan()[ahead])


def test_a_map_file_starts_at_its_centre_or_at_start_and_refuses_a_start_in_a_wall(tmp_path):
    path = tmp_path / "box.txt"
    path.write_text("######\n#....#\n#....#\n#.#..#\n#....#\n######\n")
    assert scene(SimConfig(map=str(path))).start == (3.0, 3.0, 0.0)
    assert scene(SimConfig(map=str(path), start=(1.5, 1.5, 0.3))).start == (1.5, 1.5, 0.3)
    with pytest.raises(ValueError, match="inside a wall"):
        scene(SimConfig(map=str(path), start=(2.5, 3.5, 0.0)))
    with pytest.raises(ValueError, match="outside"):
        scene(SimConfig(map=str(path), start=(9.0, 1.0, 0.0)))
