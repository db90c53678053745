"""The drive's input path on real recorded lidar: the held-out rosbag2 recordings through the wire
decoder, the scan geometry check, the resampling and the observation builder.

For each recording in /work/shared/data/holdout/rosbag2 (held-out: figures only, nothing tuned on
them) it prints one JSON line: LaserScans decoded, re-encoded byte for byte, accepted by
``check_geometry``, readings that REP 117 reads as no measurement / no return, the mean share of the
policy's 24 sectors that see something, and the builder's time per scan (decode + resample +
observation, median over the recording). The pose comes from the recording's odometry when it has
some (else it stays at the origin); the goal is 3 m ahead of the first pose.

    python -m bench.ros2_replay
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.drive import wire
from services.drive.scan import ScanRefused, check_geometry, readings, scan_rays
from worlds.config import OBSERVATIONS
from worlds.live import LiveObserver, Workspace

HOLDOUT = Path("/work/shared/data/holdout/rosbag2")


def replay(bag: Path, observation: str) -> dict:
    from rosbags.rosbag2 import Reader

    nav = OBSERVATIONS[observation]
    live, pose, started = LiveObserver(nav), (0.0, 0.0, 0.0), False
    scans = identical = accepted = no_measure = no_return = total = 0
    seeing, times = [], []
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.msgtype in (wire.LASER_SCAN, wire.ODOMETRY)]
        for conn, _, raw in reader.messages(connections=conns):
            begin = time.perf_counter()
            message = wire.decode(raw, conn.msgtype)
            if conn.msgtype == wire.ODOMETRY:
                p = message.pose.pose
                pose = (p.position.x, p.position.y, wire.yaw_of(p.orientation))
                continue
            scans += 1
            identical += wire.encode(message, conn.msgtype) == bytes(raw)
            values = readings(message, nav.sensors.max_range)
            no_measure += int(np.isnan(values).sum())
            no_return += int((values >= nav.sensors.max_range).sum())
            total += len(values)
            try:
                check_geometry(message, nav, conn.topic)
            except ScanRefused:
                continue
            accepted += 1
            rays = scan_rays(message, nav.sensors.ray_angles, nav.sensors.max_range)
            if not started:
                goal = (pose[0] + 3.0, pose[1])
                live.start(Workspace.around(pose[:2], goal, 6.0, 1.0), goal)
                obs = live.observe(rays, pose)
                started = True
            else:
                obs = live.observe(rays, pose, 2)
            times.append(time.perf_counter() - begin)
            seeing.append(float((obs[: nav.sensors.n_beams] < 1.0).mean()))
    return {
        "bag": bag.name,
        "observation": observation,
        "scans": scans,
        "reencoded_identical": identical,
        "geometry_accepted": accepted,
        "readings": total,
        "no_measurement": no_measure,
        "no_return_or_beyond_range": no_return,
        "sectors_seeing_something": round(float(np.mean(seeing)), 4) if seeing else None,
        "ms_per_scan_median": round(1000 * float(np.median(times[1:] or times)), 3) if times else None,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--observation", default="learning", choices=sorted(OBSERVATIONS))
    args = parser.parse_args(argv)
    for bag in sorted(p for p in HOLDOUT.iterdir() if p.is_dir()):
        print(json.dumps(replay(bag, args.observation)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
