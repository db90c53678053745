"""Kinematics, swept-disc collisions, exact ray casting and moving discs, against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worlds.fields import gap_field, kernel_field
from worlds.generators import generate
from worlds.maps import parse_ascii
from worlds.obstacles import DiscObstacles, move_disc
from worlds.robot import collides, move, wrap_angle
from worlds.sensors import cast_rays, cast_rays_without_skipping

# 7 x 6, one blocked cell inside at (row 3, col 3)
ROOM = parse_ascii("#######\n#.....#\n#.....#\n#..#..#\n#.....#\n#######\n")[0]


def test_move_hand_computed_poses():
    x, y, th = move([1.0], [1.0], [0.0], [math.pi / 2], 0.5)
    assert (x[0], y[0], th[0]) == pytest.approx((1.0, 1.5, math.pi / 2))
    x, y, th = move([1.0], [1.0], [3 * math.pi / 4], [math.pi / 2], 0.5)  # heading wraps to -3pi/4
    assert th[0] == pytest.approx(-3 * math.pi / 4)
    assert (x[0], y[0]) == pytest.approx((1 - 0.5 / math.sqrt(2), 1 - 0.5 / math.sqrt(2)))
    x, y, th = move(np.zeros(3), np.zeros(3), np.zeros(3), np.array([-math.pi / 4, 0.0, math.pi / 4]), 1.0)
    np.testing.assert_allclose(x, [math.sqrt(0.5), 1.0, math.sqrt(0.5)])
    np.testing.assert_allclose(y, [-math.sqrt(0.5), 0.0, math.sqrt(0.5)])


def test_move_from_a_held_heading():
    """``held_headings``: the heading is turned to the nearest compass heading before the turn."""
    start = [0.03, math.pi / 4 - 0.3]
    x, _, th = move([0.0, 0.0], [0.0, 0.0], start, [math.pi / 4, 0.0], 1.0, held_headings=8)
    np.testing.assert_allclose(th, [math.pi / 4, math.pi / 4])
    np.testing.assert_allclose(x, [math.sqrt(0.5)] * 2)
    assert move([0.0], [0.0], [0.03], [math.pi / 4], 1.0)[2][0] == pytest.approx(math.pi / 4 + 0.03)


def test_move_noise():
    args = (np.zeros(1000), np.zeros(1000), np.zeros(1000), np.zeros(1000), 0.5)
    exact = move(*args)
    np.testing.assert_array_equal(exact[0], 0.5)
    a = move(*args, trans_noise=0.05, rot_noise=0.1, rng=np.random.default_rng(1))
    b = move(*args, trans_noise=0.05, rot_noise=0.1, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(a[0], b[0])
    assert np.std(a[2]) == pytest.approx(0.1, rel=0.1)
    assert np.std(np.hypot(a[0], a[1])) == pytest.approx(0.05, rel=0.1)
    with pytest.raises(ValueError, match="rng"):
        move(*args, trans_noise=0.1)
    assert wrap_angle(math.pi) == pytest.approx(-math.pi)


@pytest.mark.parametrize(
    ("start", "end", "hit"),
    [
        ((1.5, 1.5), (1.5, 1.0), True),  # into the top wall
        ((1.5, 1.5), (2.0, 1.5), False),  # along it, 0.5 m away
        ((1.26, 2.5), (1.26, 3.0), False),  # 0.01 m from the left wall
        ((1.24, 2.5), (1.24, 3.0), True),
        ((2.5, 2.6), (4.5, 2.6), False),  # passes 0.4 m above the blocked cell
        ((2.5, 2.8), (4.5, 2.8), True),  # 0.2 m: the sweep touches it
        ((2.6, 2.6), (2.8, 2.8), False),  # towards its corner, 0.283 m short
        ((2.6, 2.6), (2.85, 2.85), True),  # 0.212 m from the corner
        ((5.5, 4.5), (5.9, 4.5), True),  # the disc would cross the border x = 6 (a wall here too)
    ],
)
def test_swept_disc_collisions(start, end, hit):
    assert collides(ROOM, start[0], start[1], end[0], end[1], 0.25)[()] == hit


def test_collides_leaving_an_open_map():
    grid = parse_ascii("....\n....\n")[0]
    assert collides(grid, [0.5, 3.5], [0.5, 1.0], [0.5, 3.9], [0.2, 1.0], 0.25).tolist() == [True, True]
    assert not collides(grid, 2.0, 1.0, 2.4, 1.0, 0.25)


@pytest.mark.parametrize(
    ("x", "y", "angle", "expected"),
    [
        (1.5, 1.5, 0.0, 4.5),  # east to the wall at x = 6
        (1.5, 1.5, math.pi / 2, 3.5),  # south (+y) to the wall at y = 5
        (1.5, 1.5, math.pi, 0.5),
        (1.5, 1.5, -math.pi / 2, 0.5),
        (1.5, 1.5, math.pi / 4, 1.5 * math.sqrt(2)),  # diagonal through cell corners to (3, 3)
        (1.25, 4.5, -math.pi / 4, 3.5 * math.sqrt(2)),  # diagonal to the top wall at (4.75, 1)
        (1.5, 1.5, math.atan2(1, 2), 4.5 * math.sqrt(1.25)),  # slope 1/2 to the east wall at y = 3.75
    ],
)
def test_ray_casting_hand_computed(x, y, angle, expected):
    assert cast_rays(ROOM, x, y, 0.0, [angle], 20.0)[0, 0] == pytest.approx(expected, abs=1e-12)
    assert cast_rays_without_skipping(ROOM, x, y, 0.0, [angle], 20.0)[0, 0] == pytest.approx(
        expected, abs=1e-12
    )


def test_ray_casting_border_range_and_blocked_origin():
    open_map = parse_ascii("......\n......\n")[0]
    assert cast_rays(open_map, 0.5, 0.5, 0.0, [0.0, math.pi / 2], 20.0)[0].tolist() == pytest.approx(
        [5.5, 1.5]
    )
    assert cast_rays(ROOM, 1.5, 1.5, 0.0, [0.0], 3.0)[0, 0] == 3.0  # capped at max range
    assert cast_rays(ROOM, 3.5, 3.5, 0.0, [0.0], 3.0)[0, 0] == 0.0  # inside a blocked cell
    assert cast_rays(ROOM, -1.0, 1.5, 0.0, [0.0], 3.0)[0, 0] == 0.0  # outside the map


def test_ray_casting_sees_discs():
    discs = np.array([[4.5, 1.5, 0.5], [1.5, 3.0, 0.25]])
    ranges = cast_rays(ROOM, 1.5, 1.5, 0.0, [0.0, math.pi / 2, math.pi / 4], 20.0, discs=discs)[0]
    assert ranges == pytest.approx([2.5, 1.25, 1.5 * math.sqrt(2)])


@pytest.mark.parametrize("family", ["rects", "discs", "rooms", "maze"])
def test_skipping_empty_space_keeps_ranges_exact(family):
    grid = generate(family, 24, 32, seed=1)
    rng = np.random.default_rng(0)
    cells = grid.free_cells()[rng.integers(len(grid.free_cells()), size=400)]
    x, y = cells[:, 1] + rng.random(400), cells[:, 0] + rng.random(400)
    # random headings, and the exact axis/diagonal ones whose rays run along cell boundaries
    for theta in (rng.uniform(-np.pi, np.pi, 400), rng.integers(8, size=400) * np.pi / 4):
        angles = -np.pi + np.arange(8) * np.pi / 4
        fast = cast_rays(grid, x, y, theta, angles, 30.0)
        plain = cast_rays_without_skipping(grid, x, y, theta, angles, 30.0)
        np.testing.assert_allclose(fast, plain, atol=1e-9)


def test_gap_field_is_a_safe_lower_bound():
    grid = generate("rects", 16, 16, seed=2)
    gap = gap_field(grid)
    blocked = np.argwhere(grid.blocked)
    for r, c in grid.free_cells():
        dr = np.maximum(np.abs(blocked[:, 0] - r) - 1, 0)
        dc = np.maximum(np.abs(blocked[:, 1] - c) - 1, 0)
        border = min(r, c, grid.height - 1 - r, grid.width - 1 - c)
        assert gap[r, c] == pytest.approx(min(np.hypot(dr, dc).min(), border))
    field = kernel_field(grid)
    assert (
        field.shape == (18, 18) and (field[0] == 255).all() and (field[1:-1, 1:-1][grid.blocked] == 255).all()
    )


def test_bouncing_disc_reflects_off_walls():
    field = kernel_field(ROOM).ravel()
    args = (field, 0, ROOM.height, ROOM.width, 1.0)
    x, y, vx, vy = move_disc(*args, 1.5, 1.5, -0.5, 0.0, 0.3, False, 0.0, 0.0, 0.0, 0.0)
    assert (x, y, vx, vy) == (1.5, 1.5, 0.5, 0.0)  # x - r would cross the wall: reversed, stays
    x, y, vx, vy = move_disc(*args, 1.5, 1.5, 0.25, 0.25, 0.3, False, 0.0, 0.0, 0.0, 0.0)
    assert (x, y, vx, vy) == (1.75, 1.75, 0.25, 0.25)
    x, y, vx, vy = move_disc(*args, 2.5, 1.4, 0.0, -0.2, 0.3, False, 0.0, 0.0, 0.0, 0.0)
    assert (x, y, vx, vy) == (2.5, 1.4, 0.0, 0.2)


def test_patrolling_disc_turns_at_its_waypoints():
    field = kernel_field(ROOM).ravel()
    state = (1.5, 1.5, 0.4, 0.0)
    xs = []
    for _ in range(6):
        state = move_disc(field, 0, ROOM.height, ROOM.width, 1.0, *state, 0.3, True, 1.5, 1.5, 2.5, 1.5)
        xs.append(state[0])
    assert xs == pytest.approx([1.9, 2.3, 2.5, 2.1, 1.7, 1.5])


def test_disc_obstacles_validation():
    discs = DiscObstacles([[1, 2], [3, 4]], [[0, 0.1], [0.1, 0]], 0.3)
    assert len(discs) == 2 and discs.radius.tolist() == [0.3, 0.3]
    with pytest.raises(ValueError, match="velocity"):
        DiscObstacles([[1, 2]], [[0, 0], [1, 1]], 0.3)
    with pytest.raises(ValueError, match="positive"):
        DiscObstacles([[1, 2]], [[0, 0]], 0.0)
    with pytest.raises(ValueError, match="finite"):
        DiscObstacles([[np.nan, 2]], [[0, 0]], 0.3)
