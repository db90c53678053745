"""What the robot perceives (worlds.perception): sector minima, its own map, the own-map subgoal,
option validation and the geodesic reward."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest

from worlds.config import NavConfig, ObservationConfig, RewardConfig, RobotConfig, SensorConfig
from worlds.env import NavigationEnv
from worlds.maps import GridMap, Task
from worlds.perception import FREE, SEEN_BLOCKED, UNKNOWN, frame_layout
from worlds.sensors import cast_rays

EXACT = RobotConfig(trans_noise=0.0, rot_noise=0.0, heading_choices=1)  # heading 0 at the start
QUIET = SensorConfig(noise_std=0.0)


def grid_with(blocked_cells, size=10) -> GridMap:
    blocked = np.zeros((size, size), dtype=bool)
    for r, c in blocked_cells:
        blocked[r, c] = True
    return GridMap(blocked)


def test_sector_minima_see_a_corner_between_beams():
    # robot at (1.5, 1.5) facing +x; cell (row 2, col 4) = [4, 5] x [2, 3]. The 0 and 45 degree beams
    # pass below and above it; the 15 degree ray of sector 0-degrees hits its left face at
    # 2.5 / cos(15 deg), the 25 degree ray of the 45-degree sector at 2.5 / cos(25 deg).
    task = Task(grid_with([(2, 4)]), (1, 1), (8, 8))
    beams = NavigationEnv(NavConfig(robot=EXACT, sensors=replace_sensors(n_beams=8)))
    obs, info = beams.reset(seed=0, options={"task": task})
    assert info["pose"][2] == 0.0
    assert obs[4] == pytest.approx(1.0) and obs[5] == pytest.approx(1.0)  # the cell hides between beams
    sectors = NavigationEnv(NavConfig(robot=EXACT, sensors=replace_sensors(n_beams=8, n_rays=72)))
    obs, _ = sectors.reset(seed=0, options={"task": task})
    assert obs[4] == pytest.approx(2.5 / math.cos(math.radians(15)) / 6.0, abs=1e-6)
    assert obs[5] == pytest.approx(2.5 / math.cos(math.radians(25)) / 6.0, abs=1e-6)
    # sector -45 degrees: rays at -25 .. -65 degrees meet the border y = 0, the steepest first
    assert obs[3] == pytest.approx(1.5 / math.sin(math.radians(65)) / 6.0, abs=1e-6)


def replace_sensors(**kwargs) -> SensorConfig:
    return SensorConfig(noise_std=0.0, **kwargs)


def _segment_touches_cell(x0, y0, x1, y1, r, c) -> bool:
    """Does the segment meet the square [c, c+1] x [r, r+1] (Liang-Barsky clipping, 1e-9 slack)?"""
    t0, t1 = 0.0, 1.0
    dx, dy = x1 - x0, y1 - y0
    for p, q in ((-dx, x0 - c), (dx, c + 1 - x0), (-dy, y0 - r), (dy, r + 1 - y0)):
        if p == 0:
            if q < -1e-9:
                return False
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t - 1e-9)
        else:
            t1 = min(t1, t + 1e-9)
    return t0 <= t1


def test_own_map_from_a_scripted_trajectory():
    rows = [(r, 6) for r in range(2, 9)] + [(5, 2), (5, 3)]
    grid = grid_with(rows, size=12)
    config = NavConfig(robot=EXACT, sensors=SensorConfig(n_beams=8, n_rays=32, noise_std=0.0),
                       observation=ObservationConfig(patch_size=4))  # fmt: skip
    env = NavigationEnv(config)
    _, info = env.reset(seed=0, options={"task": Task(grid, (1, 1), (10, 10))})
    poses = [info["pose"]]
    for action in (2, 2, 3, 2, 2, 1, 2, 2):
        _, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
        poses.append(info["pose"])
    occ = env.batch.perception.occ[0, :12, :12]
    visits = env.batch.perception.visits[0, :12, :12]
    angles = config.sensors.ray_angles
    expected_blocked, segments = set(), []
    for x, y, theta in poses:
        ranges = cast_rays(grid, x, y, theta, angles, 6.0)[0]
        for k, (a, d) in enumerate(zip(angles, ranges, strict=True)):
            ex, ey = x + d * math.cos(theta + a), y + d * math.sin(theta + a)
            if k % 4 == 2:  # the middle ray of each sector of 4 marks free cells
                segments.append((x, y, ex, ey))
            if d < 6.0:
                hx, hy = x + (d + 1e-6) * math.cos(theta + a), y + (d + 1e-6) * math.sin(theta + a)
                if 0 <= hx < 12 and 0 <= hy < 12:
                    expected_blocked.add((int(hy), int(hx)))
    seen_blocked = {tuple(rc) for rc in np.argwhere(occ == SEEN_BLOCKED)}
    assert seen_blocked == expected_blocked
    assert all(grid.blocked[rc] for rc in seen_blocked)
    for r, c in np.argwhere(occ == FREE):
        assert not grid.blocked[r, c]
        assert any(_segment_touches_cell(*s, r, c) for s in segments), f"cell {(r, c)} was reached by no ray"
    assert (occ == UNKNOWN).sum() > 0  # the far side of the wall was never seen
    cells = [(int(y), int(x)) for x, y, _ in poses]
    assert visits.sum() == len(poses)
    for rc in set(cells):
        assert visits[rc] == cells.count(rc)


def _run(grid: GridMap, config: NavConfig, actions) -> tuple[list[np.ndarray], np.ndarray | None]:
    env = NavigationEnv(config)
    obs, _ = env.reset(seed=3, options={"task": Task(grid, (8, 2), (8, 13))})
    frames = [obs]
    for action in actions:
        obs, _, terminated, truncated, _ = env.step(action)
        assert not (terminated or truncated)
        frames.append(obs)
    occ = env.batch.perception.occ
    return frames, occ[0, : grid.height, : grid.width].copy() if occ.size else None


def test_own_map_subgoal_cannot_peek_at_unseen_cells():
    # a wall at col 9 with one gap, out of the robot's sight (more than 6 m away all along):
    # at row 15 on one map, at row 0 on the other. Planning on the true map takes the gap, so its
    # waypoint differs between the two maps; planning on the robot's own map cannot tell them apart.
    def wall_with_gap(gap_row: int) -> GridMap:
        return grid_with([(r, 9) for r in range(16) if r != gap_row], size=16)

    below, above = wall_with_gap(15), wall_with_gap(0)
    sensors = SensorConfig(n_beams=12, n_rays=48, noise_std=0.0)
    actions = [2, 2, 2, 2]
    own = NavConfig(
        robot=EXACT, sensors=sensors, observation=ObservationConfig(subgoal="own_map", plan_length=True)
    )
    frames_a, occ_a = _run(below, own, actions)
    frames_b, occ_b = _run(above, own, actions)
    for occ in (occ_a, occ_b):
        assert (occ[[0, 15], 9] == UNKNOWN).all()
    for a, b in zip(frames_a, frames_b, strict=True):
        np.testing.assert_array_equal(a, b)
    known = NavConfig(robot=EXACT, sensors=sensors, observation=ObservationConfig(subgoal="known_map"))
    start, stop = frame_layout(known)["subgoal"]
    sub_below = _run(below, known, actions)[0][0][start:stop]
    sub_above = _run(above, known, actions)[0][0][start:stop]
    assert sub_below[1] > 0.3 > -0.3 > sub_above[1]  # sin of the bearing: towards +y, towards -y


def test_own_map_subgoal_leads_around_a_seen_wall():
    # a wall between robot and goal, seen from the start: the waypoint is not straight at the goal
    wall = [(r, 5) for r in range(0, 8)]
    grid = grid_with(wall, size=10)
    config = NavConfig(robot=EXACT, sensors=SensorConfig(n_beams=24, n_rays=96, noise_std=0.0),
                       observation=ObservationConfig(subgoal="own_map", subgoal_distance=2.5))  # fmt: skip
    env = NavigationEnv(config)
    obs, _ = env.reset(seed=0, options={"task": Task(grid, (2, 2), (2, 8))})
    goal, sub = obs[24:27], obs[27:30]
    goal_bearing = math.atan2(goal[1], goal[2])
    sub_bearing = math.atan2(sub[1], sub[2])
    assert abs(goal_bearing) < 0.1  # the goal is straight ahead (+x) ...
    assert sub_bearing > 0.5  # ... the waypoint leads towards +y, round the wall's open end (row 8+)


def _segment_clearance(grid: GridMap, a, b) -> float:
    """The least distance (m) from the segment a -> b to a blocked cell of ``grid`` (cells of 1 m)."""
    least = math.inf
    for t in np.linspace(0.0, 1.0, 200):
        px, py = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
        for r, c in np.argwhere(grid.blocked):
            dx, dy = max(c - px, 0.0, px - c - 1), max(r - py, 0.0, py - r - 1)
            least = min(least, math.hypot(dx, dy))
    return least


def _waypoints(
    grid: GridMap, goal, clearance: float
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """(start centre, waypoint) of the known-map subgoal from every free cell of ``grid`` far enough
    from ``goal``, read back from the observation (distance squashed by the 6 m range, bearing)."""
    sensors = SensorConfig(n_beams=24, n_rays=96, noise_std=0.0)
    config = NavConfig(
        robot=EXACT,
        sensors=sensors,
        observation=ObservationConfig(subgoal="known_map", subgoal_clearance=clearance),
    )
    at = frame_layout(config)["subgoal"][0]
    env = NavigationEnv(config)
    pairs = []
    for r, c in np.argwhere(~grid.blocked):
        if math.hypot(r - goal[0], c - goal[1]) < 3:
            continue
        obs, info = env.reset(seed=0, options={"task": Task(grid, (int(r), int(c)), goal)})
        x, y, theta = info["pose"]
        squashed, sin_b, cos_b = obs[at : at + 3]
        d = 6.0 * squashed / (1.0 - squashed)
        bearing = theta + math.atan2(sin_b, cos_b)
        pairs.append(((x, y), (x + d * math.cos(bearing), y + d * math.sin(bearing))))
    return pairs


def test_subgoal_clearance_keeps_the_waypoint_off_a_doors_jambs():
    # two rooms joined by a door 2 cells wide in a wall at row 6: from cells beside the door the
    # waypoint 2.5 m along the path lies through it, and the straight line to it brushes a jamb
    wall = [(6, c) for c in range(12) if c not in (5, 6)]
    grid = grid_with(wall, size=12)
    goal = (2, 9)
    plain = [_segment_clearance(grid, a, b) for a, b in _waypoints(grid, goal, 0.0)]
    assert sum(p < 0.25 for p in plain) >= 5  # heading straight for it would scrape a jamb (the radius)
    kept = [_segment_clearance(grid, a, b) for a, b in _waypoints(grid, goal, 0.4)]
    assert len(kept) == len(plain) and min(kept) >= 0.4 - 1e-3  # every line keeps its clearance


def _grid_path_length(passable: np.ndarray, start, goal) -> float:
    """Dijkstra on 8-connected cells, diagonals only between two passable side cells (cells of 1 m)."""
    dist = {start: 0.0}
    todo = [(0.0, start)]
    while todo:
        d, (r, c) = heapq.heappop(todo)
        if (r, c) == goal:
            return d
        if d > dist[(r, c)]:
            continue
        for dr, dc in [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)]:
            nr, nc = r + dr, c + dc
            if not (0 <= nr < passable.shape[0] and 0 <= nc < passable.shape[1]) or not passable[nr, nc]:
                continue
            if dr and dc and not (passable[r, nc] and passable[nr, c]):
                continue
            nd = d + (math.sqrt(2) if dr and dc else 1.0)
            if nd < dist.get((nr, nc), math.inf):
                dist[(nr, nc)] = nd
                heapq.heappush(todo, (nd, (nr, nc)))
    return math.inf


def test_plan_length_is_the_own_map_path_to_the_goal():
    # a wall between robot and goal, seen from the start: the observed length is the shortest path
    # round what the robot has seen (unknown cells free), longer than the straight line; with
    # nothing seen in the way it is the straight grid path
    wall = [(r, 5) for r in range(0, 8)]
    config = NavConfig(robot=EXACT, sensors=SensorConfig(n_beams=24, n_rays=96, noise_std=0.0),
                       observation=ObservationConfig(subgoal="own_map", plan_length=True))  # fmt: skip
    at = frame_layout(config)["plan_length"][0]
    assert frame_layout(config)["subgoal"][1] == at  # right after the subgoal

    def observed(obs):
        squashed = float(obs[at])
        return squashed * 6.0 / (1.0 - squashed)  # squashed like the goal distance, by max_range

    env = NavigationEnv(config)
    obs, _ = env.reset(seed=0, options={"task": Task(grid_with([], size=10), (2, 2), (2, 8))})
    assert observed(obs) == pytest.approx(6.0, abs=1e-4)
    obs, _ = env.reset(seed=0, options={"task": Task(grid_with(wall, size=10), (2, 2), (2, 8))})
    occ = env.batch.perception.occ[0, :10, :10]
    assert (occ[:8, 5] == SEEN_BLOCKED).sum() >= 3  # the robot saw the wall
    expected = _grid_path_length(occ != SEEN_BLOCKED, (2, 2), (2, 8))
    assert expected > 6.5
    assert observed(obs) == pytest.approx(expected, abs=1e-4)
    for action in (2, 2, 1):  # and step by step, from each cell the robot reaches
        obs, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
        x, y, _ = info["pose"]
        occ = env.batch.perception.occ[0, :10, :10]
        assert observed(obs) == pytest.approx(
            _grid_path_length(occ != SEEN_BLOCKED, (int(y), int(x)), (2, 8)), abs=1e-4
        )


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: ObservationConfig(frame_stack=0), "observation.frame_stack"),
        (lambda: ObservationConfig(patch_size=-1), "observation.patch_size"),
        (lambda: ObservationConfig(subgoal="oracle"), "observation.subgoal"),
        (lambda: ObservationConfig(subgoal_distance=0.0), "observation.subgoal_distance"),
        (lambda: ObservationConfig(subgoal_clearance=-0.1), "observation.subgoal_clearance"),
        (lambda: SensorConfig(n_beams=24, n_rays=12), "sensors.n_rays"),
        (lambda: SensorConfig(n_beams=24, n_rays=50), "sensors.n_rays"),
        (lambda: RewardConfig(geodesic_progress=-0.1), "rewards.geodesic_progress"),
        (lambda: ObservationConfig(plan_length=True), "observation.plan_length"),
        (lambda: ObservationConfig(subgoal="own_map", plan_length="yes"), "observation.plan_length"),
    ],
)
def test_bad_option_values_name_the_field(make, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make()


def test_geodesic_reward_is_negative_deeper_into_a_pocket():
    # a pocket open towards -x (rows 2-4, cols 2-5), the goal behind its back wall: driving +x gets
    # closer in a straight line but further along the path out of the pocket and round it
    walls = [(r, 6) for r in range(1, 6)] + [(1, c) for c in range(2, 7)] + [(5, c) for c in range(2, 7)]
    task = Task(grid_with(walls), (3, 3), (3, 8))

    def two_steps_ahead(rewards: RewardConfig) -> float:
        env = NavigationEnv(NavConfig(robot=EXACT, sensors=QUIET, rewards=rewards))
        env.reset(seed=0, options={"task": task})
        return env.step(2)[1] + env.step(2)[1]  # from (3.5, 3.5) to (4.5, 3.5): cell (3, 3) -> (3, 4)

    assert two_steps_ahead(RewardConfig(step=0.0, progress=1.0)) == pytest.approx(1.0)
    assert two_steps_ahead(RewardConfig(step=0.0, progress=0.0, geodesic_progress=1.0)) < -0.4
