"""services.drive.motion against a simulated unicycle: each action ends where the world's would,
at rest, within the speed and acceleration limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.drive.motion import ActionMotion, Limits, wrap
from worlds.config import RobotConfig
from worlds.robot import move


def execute(start, turn, step, limits, dt=0.05, lag=0):
    """Run one action on a unicycle that applies each command after ``lag`` ticks; returns the
    final pose, the commands and whether it timed out."""
    motion = ActionMotion(start, turn, step, limits)
    x, y, th = start
    queue, commands = [(0.0, 0.0)] * lag, []
    for _ in range(10_000):
        v, w, done = motion.command((x, y, th), dt)
        commands.append((v, w))
        queue.append((v, w))
        av, aw = queue.pop(0)
        th = wrap(th + aw * dt)
        x, y = x + av * dt * math.cos(th), y + av * dt * math.sin(th)
        if done:
            break
    return (x, y, th), np.array(commands), motion.timed_out


@pytest.mark.parametrize("action", range(RobotConfig().n_actions + 1))  # the shield's turn-around too
@pytest.mark.parametrize("lag", [0, 2])
def test_each_action_lands_where_the_world_puts_it(action, lag):
    robot, limits = RobotConfig(), Limits()
    start = (2.0, 3.0, 0.7)
    turn, step = robot.motion(action)
    (x, y, th), commands, timed_out = execute(start, turn, step, limits, lag=lag)
    wx, wy, wth = move(start[0], start[1], start[2], turn, step)
    assert not timed_out
    assert math.hypot(x - wx, y - wy) < 0.05 and abs(wrap(th - wth)) < 0.05
    v, w = commands[:, 0], commands[:, 1]
    assert (
        (v >= 0).all()
        and v.max() <= limits.max_linear + 1e-12
        and np.abs(w).max() <= limits.max_angular + 1e-12
    )
    dv, dw = np.abs(np.diff(v)), np.abs(np.diff(w))
    assert dv[:-1].max() <= limits.linear_accel * 0.05 + 1e-9  # the last command is the stop
    assert dw[:-1].max() <= limits.angular_accel * 0.05 + 1e-9
    assert tuple(commands[-1]) == (0.0, 0.0)


def test_a_blocked_robot_times_out_with_zero_velocity():
    motion = ActionMotion((0.0, 0.0, 0.0), 0.0, 0.5, Limits())
    for _ in range(1000):
        v, w, done = motion.command((0.0, 0.0, 0.0), 0.05)  # odometry never moves
        if done:
            break
    assert done and motion.timed_out and (v, w) == (0.0, 0.0)


def test_limits_are_checked():
    with pytest.raises(ValueError, match="max_linear"):
        Limits(max_linear=0.0)
