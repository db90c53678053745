"""LaserScan -> the policy's rays (services.drive.scan): REP 117 readings, resampling, refusals,
and the rosbag2 replay: real recorded scans through the observation builder."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from services.drive import wire
from services.drive.scan import ScanRefused, check_geometry, readings, scan_rays
from worlds.config import LEARNING_NAV, OBSERVATIONS
from worlds.live import LiveObserver, Workspace
from worlds.maps import GridMap
from worlds.perception import observation_bounds
from worlds.sensors import cast_rays

HOLDOUT = Path("/work/shared/data/holdout/rosbag2")
RAYS = LEARNING_NAV.sensors.ray_angles


def scan(ranges, angle_min=-math.pi, inc=None, lo=0.1, hi=10.0):
    inc = 2 * math.pi / len(ranges) if inc is None else inc
    return wire.laser_scan(ranges, angle_min, inc, lo, hi, 0, "laser")


def test_readings_follow_rep_117():
    values = readings(scan([1.0, np.inf, -np.inf, np.nan, 0.0, 0.05, 12.0, 20.0]), max_range=6.0)
    # a return; no return (free); too close; nothing; 0 and 0.05 below range_min: nothing; above
    # range_max: no return; and every reading clipped to the policy's range
    np.testing.assert_array_equal(values, [1.0, 6.0, 0.0, np.nan, np.nan, np.nan, 6.0, 6.0])


def test_rays_interpolate_on_surfaces_take_the_farther_at_edges_and_skip_bad_beams():
    ranges = np.full(720, np.inf, np.float32)  # 0.5 degree beams from -180: beam 360 points ahead
    ranges[340:381] = np.linspace(2.0, 3.0, 41)  # a surface from -10 to +10 degrees
    ranges[362] = np.nan  # no measurement: the ray through it interpolates its neighbours
    rays = scan_rays(scan(ranges), RAYS, 6.0)
    inside = np.abs(RAYS) < math.radians(9.5)
    expected = 2.0 + (np.degrees(RAYS[inside]) + 10.0) / 20.0
    np.testing.assert_allclose(rays[inside], expected, atol=1e-6)
    # just past the surface's edge (between a 2 m and an inf beam) the ray reads the farther: nothing
    assert (rays[np.abs(RAYS) > math.radians(10.5)] == 6.0).all()
    turned = scan_rays(scan(ranges), RAYS, 6.0, yaw_offset=math.pi / 2)  # sensor turned 90 deg left
    ahead = int(np.argmin(np.abs(RAYS - math.pi / 2 - math.radians(1.875))))
    assert turned[ahead] == pytest.approx(2.0 + (1.875 + 10.0) / 20.0, abs=1e-6)


def test_resampled_scan_matches_the_worlds_rays():
    """A 360-beam scan cast in a room, resampled, gives the world's own sector readings to within
    a few millimetres (interpolation between 1-degree beams)."""
    blocked = np.zeros((10, 12), bool)
    blocked[0, :] = blocked[-1, :] = blocked[:, 0] = blocked[:, -1] = True
    blocked[3:6, 7] = True
    grid = GridMap(blocked, 1.0)
    x, y, theta = 4.3, 5.1, 0.4
    beams = -math.pi + np.arange(360) * (2 * math.pi / 360)
    ranges = cast_rays(grid, x, y, theta, beams, 6.0)[0]
    ranges = np.where(ranges >= 6.0, np.inf, ranges)
    rays = scan_rays(scan(ranges, hi=6.0), RAYS, 6.0)
    truth = cast_rays(grid, x, y, theta, RAYS, 6.0)[0]
    sectors = lambda r: r.reshape(24, 4).min(axis=1)  # noqa: E731
    error = sectors(rays) - sectors(truth)
    assert np.abs(error).mean() < 0.01 and np.abs(error).max() < 0.05


@pytest.mark.parametrize(
    ("ranges", "angle_min", "inc", "lo", "hi", "says"),
    [
        ([], 0.0, 0.01, 0.1, 5.0, "no readings"),
        ([1.0] * 270, -3 * math.pi / 4, math.radians(1.0), 0.1, 5.0, "cannot feed this policy"),
        ([1.0] * 12, 0.0, math.radians(30.0), 0.1, 5.0, "cannot feed this policy"),
        ([1.0] * 360, 0.0, float("nan"), 0.1, 5.0, "place no beam"),
        ([1.0] * 360, 0.0, math.radians(1.0), 5.0, 5.0, "bound no reading"),
    ],
    ids=["empty", "270-degree", "sparse", "nan-increment", "empty-range"],
)
def test_unusable_geometry_is_refused_in_one_sentence(ranges, angle_min, inc, lo, hi, says):
    with pytest.raises(ScanRefused, match=says) as caught:
        check_geometry(scan(ranges, angle_min, inc, lo, hi), LEARNING_NAV, "/front/scan")
    message = str(caught.value)
    assert "/front/scan" in message and message.count(". ") == 0 and message.endswith(".")


def test_a_270_degree_scan_suits_a_270_degree_policy():
    from dataclasses import replace

    nav = replace(LEARNING_NAV, sensors=replace(LEARNING_NAV.sensors, fov=3 * math.pi / 2))
    check_geometry(scan([1.0] * 271, -3 * math.pi / 4, math.radians(1.0)), nav)


def _replay(bag: str, observation: str):
    """Every LaserScan of a recording through check_geometry, scan_rays and the observation builder
    (with the recording's odometry when it has some); returns the observations and the readings."""
    from rosbags.rosbag2 import Reader

    nav = OBSERVATIONS[observation]
    live, pose, out, rays_seen = LiveObserver(nav), (0.0, 0.0, 0.0), [], []
    with Reader(HOLDOUT / bag) as reader:
        conns = [c for c in reader.connections if c.topic in ("/scan", "/odom")]
        for conn, _, raw in reader.messages(connections=conns):
            message = wire.decode(raw, conn.msgtype)
            if conn.msgtype == wire.ODOMETRY:
                p = message.pose.pose
                pose = (p.position.x, p.position.y, wire.yaw_of(p.orientation))
                continue
            check_geometry(message, nav)
            rays = scan_rays(message, nav.sensors.ray_angles, nav.sensors.max_range)
            if not out:
                live.start(
                    Workspace.around(pose[:2], (pose[0] + 3.0, pose[1]), 6.0, 1.0), (pose[0] + 3.0, pose[1])
                )
                out.append(live.observe(rays, pose))
            else:
                out.append(live.observe(rays, pose, 2))
            rays_seen.append(rays)
    return np.array(out), np.array(rays_seen), nav


@pytest.mark.parametrize(("bag", "scans"), [("gazebo_tb3_walker", 102), ("mumble_rplidar_real", 147)])
@pytest.mark.parametrize("observation", ["learning", "plain"])
def test_rosbag2_replay_through_the_observation_builder(bag, scans, observation):
    obs, rays, nav = _replay(bag, observation)
    assert obs.shape == (scans, LiveObserver(nav).obs_dim)
    low, high = observation_bounds(nav)
    assert np.isfinite(obs).all() and (obs >= low - 1e-6).all() and (obs <= high + 1e-6).all()
    n = nav.sensors.n_beams
    # the robots saw walls: every scan has sectors below the range, and not every sector is blocked
    assert ((obs[:, :n] < 1.0).sum(axis=1) > 0).all()
    assert (rays >= 0.0).all() and (rays <= nav.sensors.max_range).all()
