"""services.drive.drive.Driver alone (no Zenoh, a fake clock and a unicycle): the watchdog, the
refusals, reaching and giving up, each ending in zero velocity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.drive import wire
from services.drive.drive import Driver, Inputs
from services.drive.motion import Limits
from worlds.config import LEARNING_NAV


class Straight:
    """A policy that always drives straight ahead (action 2 of 5), counting its calls."""

    calls = 0

    def nav_config(self):
        return LEARNING_NAV

    def __call__(self, obs):
        assert obs.shape == (1, 30) and np.isfinite(obs).all()
        self.calls += 1
        return np.array([2])


def open_scan(beams: int = 360):
    return wire.laser_scan(np.full(beams, np.inf), -math.pi, 2 * math.pi / beams, 0.1, 8.0, 0, "laser")


class Rig:
    """A Driver on a unicycle: ``run(seconds)`` ticks at 50 Hz, feeding odometry and a scan per tick."""

    def __init__(self, scan=None, policy=None, **kw):
        self.sent: list[tuple[float, float, float]] = []
        self.now, self.pose = 0.0, [0.0, 0.0, 0.0]
        self.inputs = Inputs()
        self.scan = open_scan() if scan is None else scan
        options = {"stale_after": 0.3, "cell": 1.0, "margin": 4.0, "goal_tolerance": 0.0, "max_actions": 0}
        self.driver = Driver(
            policy or Straight(), self.inputs, self.send, Limits(1.0, 3.0, 4.0, 12.0), **{**options, **kw}
        )
        self.scans_on = True

    def send(self, v, w):
        self.sent.append((self.now, v, w))
        self.v, self.w = v, w

    def run(self, seconds: float, dt: float = 0.02):
        self.v = self.w = 0.0
        for _ in range(int(seconds / dt)):
            self.now += dt
            self.pose[2] += self.w * dt
            self.pose[0] += self.v * dt * math.cos(self.pose[2])
            self.pose[1] += self.v * dt * math.sin(self.pose[2])
            self.inputs.on_odometry(tuple(self.pose), "odom", self.now)
            if self.scans_on:
                self.inputs.on_scan(self.scan, self.now)
            self.driver.tick(self.now)


def test_reaches_a_goal_ahead_and_stops():
    rig = Rig()
    rig.run(0.1)
    rig.inputs.on_goal((3.0, 0.0), "odom")
    rig.run(12.0)
    status = rig.driver.status(rig.now)
    assert status["state"] == "reached" and status["goals_reached"] == 1
    assert status["distance"] <= 0.5 and 4 <= status["actions"] <= 6
    assert rig.sent[-1][1:] == (0.0, 0.0) and max(v for _, v, _ in rig.sent) <= 1.0


class TurnAround(Straight):
    """A policy that always takes the robot's turn-around (what the reading shield takes when nothing
    is clear)."""

    def __call__(self, obs):
        super().__call__(obs)
        return np.array([LEARNING_NAV.robot.turn_around])


def test_the_turn_around_is_half_a_turn_in_place():
    policy = TurnAround()
    rig = Rig(policy=policy)
    rig.run(0.1)
    rig.inputs.on_goal((3.0, 0.0), "odom")
    rig.run(3.0)  # long enough for half a turn at 3 rad/s, with its ramps and final approach
    assert policy.calls >= 2  # the first action done, the next chosen
    w = np.array([w for _, _, w in rig.sent])
    first = w[: int(np.flatnonzero((w == 0) & (np.cumsum(w != 0) > 0))[0])]  # up to its final stop
    assert abs(abs(first.sum() * 0.02) - math.pi) < 0.05  # half a turn (the rig ticks at 50 Hz)
    assert all(v == 0.0 for _, v, _ in rig.sent)  # never a forward speed: it turned in place
    assert math.hypot(rig.pose[0], rig.pose[1]) < 1e-9


class ScanStraight(Straight):
    """A policy that reads the scans too (agents.shield.ScanPolicy, as a shielded one with its disc
    tracker): records the rays and the episode starts the driver hands it, drives straight ahead."""

    def __init__(self) -> None:
        self.seen: list[tuple[np.ndarray, bool]] = []

    def __call__(self, obs):
        raise AssertionError("a scan policy is driven through its scan actor")

    def scan_actor(self, n):
        assert n == 1

        def act(obs, rays, fresh):
            assert obs.shape == (1, 30) and rays.shape == (1, len(LEARNING_NAV.sensors.ray_angles))
            self.seen.append((rays[0].copy(), bool(fresh[0])))
            return np.array([2])

        return act


def test_a_scan_policy_gets_the_scans_rays_and_each_goals_start():
    wall = np.full(360, np.inf)
    wall[170:191] = 1.5  # something 1.5 m ahead (the scan starts behind the robot, at -pi)
    policy = ScanStraight()
    rig = Rig(scan=wire.laser_scan(wall, -math.pi, 2 * math.pi / 360, 0.1, 8.0, 0, "laser"), policy=policy)
    rig.run(0.1)
    rig.inputs.on_goal((3.0, 0.0), "odom")
    rig.run(2.0)
    assert len(policy.seen) >= 2 and [f for _, f in policy.seen[:2]] == [True, False]  # a goal starts afresh
    rays = policy.seen[0][0]
    angles, max_range = np.abs(LEARNING_NAV.sensors.ray_angles), LEARNING_NAV.sensors.max_range
    assert np.allclose(rays[angles < 0.05], 1.5, atol=0.1)  # the LaserScan, resampled to the world's rays
    assert (rays[angles > 0.4] == max_range).all()
    rig.inputs.on_goal((-3.0, 0.0), "odom")  # a new goal: the tracker forgets the last one's discs
    rig.run(0.5)
    assert any(f for _, f in policy.seen[2:])


def test_warm_up_goes_through_the_scan_actor_and_the_first_goal_still_starts_afresh():
    policy = ScanStraight()
    rig = Rig(policy=policy)
    rig.driver.warm_up()
    assert [f for _, f in policy.seen] == [True]  # the tracker's loops loaded before any goal
    rig.run(0.1)
    rig.inputs.on_goal((3.0, 0.0), "odom")
    rig.run(2.0)
    assert [f for _, f in policy.seen[1:3]] == [True, False]


def test_watchdog_stops_within_a_tick_of_the_scan_going_stale_and_drives_on():
    rig = Rig()
    rig.run(0.1)
    rig.inputs.on_goal((6.0, 0.0), "odom")
    rig.run(1.0)
    assert any(v > 0 for _, v, _ in rig.sent)
    rig.scans_on, off = False, rig.now
    rig.run(1.0)
    zero = next(t for t, v, w in rig.sent if t > off + 0.3 and v == 0.0 and w == 0.0)
    assert zero - off <= 0.3 + 0.021  # stale after 0.3 s, the next 50 Hz tick sends zero
    assert all(v == 0.0 and w == 0.0 for t, v, w in rig.sent if t >= zero)
    assert rig.driver.status(rig.now)["stale"] == ["scan"] and rig.driver.state == "stale"
    rig.scans_on = True
    rig.run(0.5)
    assert rig.driver.state == "driving" and rig.sent[-1][1] > 0


def test_a_scan_the_policy_cannot_use_is_refused_in_one_sentence_and_the_robot_stays():
    sparse = wire.laser_scan(np.full(8, 2.0), -math.pi, math.pi / 4, 0.1, 8.0, 0, "laser")
    rig = Rig(scan=sparse)
    rig.inputs.on_goal((3.0, 0.0), "odom")
    rig.run(1.0)
    status = rig.driver.status(rig.now)
    assert status["scans_refused"] >= 1 and "cannot feed this policy" in status["detail"]
    assert status["detail"].endswith(".") and status["detail"].count(". ") == 0
    assert all(v == 0.0 and w == 0.0 for _, v, w in rig.sent) and rig.pose == [0.0, 0.0, 0.0]


def test_a_goal_in_another_frame_is_refused():
    rig = Rig()
    rig.run(0.1)
    rig.inputs.on_goal((3.0, 0.0), "map")
    rig.run(0.5)
    status = rig.driver.status(rig.now)
    assert status["state"] == "goal refused" and "'map'" in status["detail"] and "TF" in status["detail"]
    assert not any(v for _, v, _ in rig.sent)


def test_gives_up_after_max_actions():
    rig = Rig(max_actions=2)
    rig.run(0.1)
    rig.inputs.on_goal((9.0, 0.0), "odom")
    rig.run(6.0)
    status = rig.driver.status(rig.now)
    assert status["state"] == "gave up" and status["actions"] == 2 and rig.sent[-1][1:] == (0.0, 0.0)


def test_halt_sends_zero_at_once():
    rig = Rig()
    rig.run(0.1)
    rig.inputs.on_goal((6.0, 0.0), "odom")
    rig.run(1.0)
    rig.driver.halt()
    assert rig.sent[-1][1:] == (0.0, 0.0)


def test_status_lists_input_ages():
    rig = Rig()
    rig.run(0.2)
    ages = rig.driver.status(rig.now + 1.0)["input_age_s"]
    assert ages["scan"] == pytest.approx(1.0, abs=0.03) and ages["odometry"] == pytest.approx(1.0, abs=0.03)


class Recorder(Straight):
    """Drives straight ahead, keeping every observation it is given."""

    def __init__(self):
        self.seen: list[np.ndarray] = []

    def __call__(self, obs):
        super().__call__(obs)
        self.seen.append(obs[0].copy())
        return np.array([2])


def wall_scan(distance: float, beams: int = 360):
    """A wall across the robot's left, ``distance`` metres out (beams 60-120 degrees)."""
    angles = -math.pi + np.arange(beams) * (2 * math.pi / beams)
    side = (angles > math.radians(60)) & (angles < math.radians(120))
    ranges = np.where(side, distance / np.sin(np.where(side, angles, 1.0)), np.inf)
    return wire.laser_scan(ranges, -math.pi, 2 * math.pi / beams, 0.05, 8.0, 0, "laser")


def test_a_smaller_robot_sees_its_scene_as_the_worlds_robot_and_drives_scaled_steps():
    """--robot-radius 0.105: the same scene shrunk by 0.105 / 0.25 gives the policy the same
    observations, and each step drives 0.21 m instead of 0.5 m (it reaches the shrunk goal in as many
    actions, where it stops)."""
    shrink = 0.105 / 0.25
    big, small = Recorder(), Recorder()
    rigs = [  # the lidar's hit margin is the robot's own metres: shrunk with it here
        Rig(scan=wall_scan(1.5), policy=big, hit_margin=0.05),
        Rig(scan=wall_scan(1.5 * shrink), policy=small, robot_radius=0.105, hit_margin=0.05 * shrink),
    ]
    for rig, goal in zip(rigs, (3.0, 3.0 * shrink), strict=True):
        rig.run(0.1)
        rig.inputs.on_goal((goal, 0.0), "odom")
        rig.run(12.0)
        assert rig.driver.status(rig.now)["state"] == "reached"
    assert len(big.seen) == len(small.seen) >= 4
    for a, b in zip(big.seen, small.seen, strict=True):
        np.testing.assert_allclose(a[:24], b[:24], atol=1e-6)  # the readings
        # the goal and subgoal: each action ends within the motion's own tolerance (the robot's
        # metres, not scaled), a centimetre on the small robot's 2 m to go
        np.testing.assert_allclose(a[24:], b[24:], atol=0.01)
    assert rigs[1].driver.status(rigs[1].now)["distance"] <= 0.5 * shrink  # the world's tolerance, shrunk
    assert rigs[1].pose[0] / len(small.seen) == pytest.approx(0.5 * shrink, abs=0.02)  # 0.21 m a step
    with pytest.raises(ValueError, match="--robot-radius must be a positive"):
        Rig(robot_radius=0.0)


def test_a_signal_inside_a_tick_leaves_nothing_but_zero_after_it():
    """The signal handler (``Driver.stop``) can run inside a tick after the motion has computed a
    moving command and before the tick sends it: that send must be zero too."""
    rig = Rig()
    rig.run(0.1)
    rig.inputs.on_goal((6.0, 0.0), "odom")
    rig.run(0.5)
    assert rig.driver.motion is not None and rig.sent[-1][1] > 0  # mid-action, moving
    motion = rig.driver.motion
    command = motion.command

    def interrupted(pose, dt):
        moving = command(pose, dt)
        assert moving[0] > 0  # the tick is about to send a forward speed ...
        rig.driver.stop()  # ... when the handler runs
        return moving

    motion.command = interrupted
    signalled = len(rig.sent)
    rig.run(0.02)
    after = rig.sent[signalled:]
    assert after and all(v == 0.0 and w == 0.0 for _, v, w in after)
    motion.command = command
    rig.run(0.5)  # the loop may tick once more before it sees the stop event: still zero
    assert all(v == 0.0 and w == 0.0 for _, v, w in rig.sent[signalled:])
