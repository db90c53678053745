"""A LaserScan as the policy's rays: ROS's reading semantics, any beam geometry, one refusal.

A policy casts ``n_rays`` rays at fixed angles from its heading (``worlds.config.SensorConfig.
ray_angles``, 96 all round for the shipped one). A lidar has its own beam count, start angle,
increment and range limits. :func:`scan_rays` resamples: ray k reads the smallest valid reading of
the beams within half a ray spacing of its direction (so no obstacle falls between rays), or
the nearest beam's when none is that close. Readings follow REP 117 (sensor_msgs/LaserScan):

* a finite reading in ``[range_min, range_max]`` is a return at that range;
* ``+inf``, or a finite reading above ``range_max``: no return within range, read as the
  policy's ``max_range`` (nothing seen, as the world reads a free beam);
* ``-inf``: an object closer than ``range_min``, read as 0;
* ``NaN``, or a finite reading below ``range_min`` (drivers that write 0 for "no return"): no
  measurement; the ray takes its other beams, and with none ``max_range`` (as the world reads a
  dropped-out beam).

Beam i points at ``angle_min + i * angle_increment`` (``angle_max`` is not trusted: real drivers
write it inconsistently, see the held-out RPLIDAR recording), counter-clockwise from the sensor's
x axis (REP 103), plus ``yaw_offset`` for a sensor mounted turned on the robot. The scan's origin is
taken to be the robot's centre (no TF lookup). :func:`check_geometry` refuses, in one sentence, a
scan that leaves one of the policy's rays more than half a sector from every beam (a 270-degree
lidar under a 360-degree policy, a sparse sensor).
"""

from __future__ import annotations

import math

import numpy as np

from worlds.config import NavConfig


class ScanRefused(ValueError):
    """A scan whose geometry the policy cannot use; the message is one sentence saying why."""


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def beam_angles(scan, yaw_offset: float = 0.0) -> np.ndarray:
    """Each beam's direction from the robot's heading (rad, wrapped to [-pi, pi))."""
    n = len(scan.ranges)
    return _wrap(yaw_offset + scan.angle_min + np.arange(n) * float(scan.angle_increment))


def check_geometry(scan, config: NavConfig, topic: str = "/scan", yaw_offset: float = 0.0) -> None:
    """Raise :class:`ScanRefused` (one sentence) when ``scan`` cannot feed a policy of ``config``."""
    n, inc = len(scan.ranges), float(scan.angle_increment)
    lo, hi = float(scan.range_min), float(scan.range_max)
    where = f"the LaserScan on {topic}"
    if n == 0:
        raise ScanRefused(f"{where} has no readings, so the policy has nothing to see.")
    if not math.isfinite(inc) or (inc == 0.0 and n > 1) or not math.isfinite(float(scan.angle_min)):
        raise ScanRefused(
            f"{where} has angle_min {scan.angle_min} and angle_increment {inc}, which place no beam."
        )
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise ScanRefused(f"{where} has range_min {lo} and range_max {hi}, which bound no reading.")
    rays = config.sensors.ray_angles
    sector = config.sensors.fov / config.sensors.n_beams
    gaps = np.abs(_wrap(rays[:, None] - beam_angles(scan, yaw_offset)[None, :])).min(axis=1)
    worst = int(np.argmax(gaps))
    if gaps[worst] > sector / 2 + 1e-9:
        deg = math.degrees
        raise ScanRefused(
            f"{where} cannot feed this policy: its {n} beams from {deg(scan.angle_min):.0f} degrees every "
            f"{deg(inc):.2f} degrees leave the policy's ray at {deg(rays[worst]):.0f} degrees off heading "
            f"{deg(gaps[worst]):.0f} degrees from any beam, more than half a sector ({deg(sector / 2):.1f} "
            f"degrees) over its {deg(config.sensors.fov):.0f} degree field of view."
        )


def readings(scan, max_range: float) -> np.ndarray:
    """Each beam's reading by REP 117 (see the module docstring), clipped to ``[0, max_range]``;
    NaN where the beam measured nothing."""
    raw = np.asarray(scan.ranges, np.float64)
    lo, hi = float(scan.range_min), float(scan.range_max)
    out = np.full(raw.shape, np.nan)
    finite = np.isfinite(raw)
    inside = finite & (raw >= lo) & (raw <= hi)
    out[inside] = raw[inside]
    out[np.isposinf(raw) | (finite & (raw > hi))] = max_range
    out[np.isneginf(raw)] = 0.0
    return np.minimum(out, max_range)


def scan_rays(scan, ray_angles: np.ndarray, max_range: float, yaw_offset: float = 0.0) -> np.ndarray:
    """The policy's rays (metres along ``ray_angles`` from the heading) from a LaserScan whose
    geometry :func:`check_geometry` accepted (see the module docstring)."""
    values = readings(scan, max_range)
    diff = np.abs(_wrap(np.asarray(ray_angles)[:, None] - beam_angles(scan, yaw_offset)[None, :]))
    spacing = float(np.diff(np.sort(ray_angles)).min()) if len(ray_angles) > 1 else 2 * np.pi
    window = diff <= spacing / 2 + 1e-12
    nearest = np.zeros_like(window)
    nearest[np.arange(len(ray_angles)), diff.argmin(axis=1)] = True
    window |= nearest & ~window.any(axis=1, keepdims=True)  # no beam that close: the nearest one
    masked = np.where(window & ~np.isnan(values)[None, :], values[None, :], np.inf)
    rays = masked.min(axis=1)
    return np.where(np.isfinite(rays), rays, max_range)
