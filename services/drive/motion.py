"""One discrete action as closed-loop motion on odometry, within speed and acceleration limits.

In the world an action turns the robot in place by ``turn`` and then drives it ``step`` metres
straight ahead (:mod:`worlds.robot`). A real robot takes velocities, not displacements, so
:class:`ActionMotion` turns the action into velocity commands from the poses odometry reports:

1. turn in place to ``start heading + turn``: the yaw rate is the largest that still stops on
   the target heading at the angular deceleration limit (``sqrt(2 a |error|)``), capped by the
   speed limit and by a proportional term that settles it;
2. drive ``step`` metres along that heading, measured as progress along it from where the turn
   ended: the speed profile is the same trapezoid, and a proportional yaw rate holds the heading;
3. stop (zero velocity): the action is done, the next observation is taken at rest.

Every command changes speed by at most ``accel * dt`` from the previous one. No clocks and no
threads here: the caller passes each pose and the time since its last call, so the controller is
tested alone (tests/test_drive_motion.py) against a simulated unicycle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    """Speed and acceleration limits of the robot, and when an action counts as executed."""

    max_linear: float = 0.3
    """largest forward speed (m/s)"""
    max_angular: float = 1.0
    """largest yaw rate (rad/s)"""
    linear_accel: float = 0.5
    """largest change of forward speed (m/s^2), speeding up and slowing down"""
    angular_accel: float = 2.0
    """largest change of yaw rate (rad/s^2)"""
    heading_tolerance: float = 0.02
    """the turn is done within this heading error (rad)"""
    distance_tolerance: float = 0.01
    """the drive is done within this distance of the step (m)"""
    gain: float = 3.0
    """proportional gain (1/s) of the final approach and of heading hold while driving"""

    def __post_init__(self) -> None:
        for name in ("max_linear", "max_angular", "linear_accel", "angular_accel", "gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"motion limit {name} must be a positive number, got {value}")

    def duration(self, turn: float, step: float) -> float:
        """A generous bound on one action's time (s): three times the time at full speed, plus the
        ramps, plus a second (an action taking longer is stopped and counted)."""
        ramps = self.max_linear / self.linear_accel + self.max_angular / self.angular_accel
        return 3.0 * (abs(turn) / self.max_angular + step / self.max_linear) + 2 * ramps + 1.0


def wrap(angle: float) -> float:
    """``angle`` wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _approach(error: float, max_speed: float, accel: float, gain: float) -> float:
    """The speed towards a target ``error`` away (signed): as fast as allowed while still able to
    stop on it at ``accel``, and proportional to the error near it."""
    size = min(max_speed, math.sqrt(2.0 * accel * abs(error)), gain * abs(error))
    return math.copysign(size, error)


def _ramp(previous: float, wanted: float, accel: float, dt: float) -> float:
    return min(max(wanted, previous - accel * dt), previous + accel * dt)


class ActionMotion:
    """The velocity commands of one action from ``start`` (x, y, theta): turn by ``turn``, then
    drive ``step`` (see the module docstring). ``command(pose, dt)`` -> (linear, angular, done)."""

    def __init__(self, start: tuple[float, float, float], turn: float, step: float, limits: Limits) -> None:
        self.limits = limits
        self.heading = wrap(start[2] + turn)
        self.step = step
        self.phase = "turn"
        self.origin = (start[0], start[1])
        self.linear = self.angular = 0.0
        self.elapsed = 0.0
        self.timeout = limits.duration(turn, step)
        self.timed_out = False

    def command(self, pose: tuple[float, float, float], dt: float) -> tuple[float, float, bool]:
        """The next command at ``pose``, ``dt`` seconds after the previous one; ``done`` once the
        action is executed (the command then is zero) or took longer than its time bound."""
        lim = self.limits
        self.elapsed += dt
        if self.elapsed > self.timeout:
            self.timed_out, self.phase = True, "done"
        error = wrap(self.heading - pose[2])
        if self.phase == "turn":
            if abs(error) <= lim.heading_tolerance and abs(self.angular) <= lim.angular_accel * dt:
                self.phase, self.origin = "drive", (pose[0], pose[1])
            else:
                wanted = _approach(error, lim.max_angular, lim.angular_accel, lim.gain)
                self.linear, self.angular = 0.0, _ramp(self.angular, wanted, lim.angular_accel, dt)
                return self.linear, self.angular, False
        if self.phase == "drive":
            c, s = math.cos(self.heading), math.sin(self.heading)
            remaining = self.step - ((pose[0] - self.origin[0]) * c + (pose[1] - self.origin[1]) * s)
            if remaining <= lim.distance_tolerance:
                self.phase = "done"
            else:
                wanted = _approach(remaining, lim.max_linear, lim.linear_accel, lim.gain)
                hold = max(-lim.max_angular, min(lim.max_angular, lim.gain * error))
                self.linear = _ramp(self.linear, max(wanted, 0.0), lim.linear_accel, dt)
                self.angular = _ramp(self.angular, hold, lim.angular_accel, dt)
                return self.linear, self.angular, False
        self.linear = self.angular = 0.0
        return 0.0, 0.0, True
