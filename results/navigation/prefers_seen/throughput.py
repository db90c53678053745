"""The world's cost of the own map's plan preferring seen cells (docs/navigation-by-size.md section 12):
robot-steps per CPU-second (``bench.map_sizes.throughput``: one thread, the goal-seeking heuristic
driving, mixed maps) with ``subgoal_prefers_seen`` off and on, alternating in one process, ROUNDS
rounds of SECONDS per size and setting; the ratio is on / off per round (the median reported).

    PYTHONPATH=. python results/navigation/prefers_seen/throughput.py [SECONDS] [ROUNDS]
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import replace

import numpy as np

from bench.map_sizes import throughput
from worlds.config import LEARNING_NAV


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 3.0
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    seen = LEARNING_NAV.observation
    navs = {
        on: replace(LEARNING_NAV, observation=replace(seen, subgoal_prefers_seen=on)) for on in (False, True)
    }
    for nav in navs.values():  # compile both before timing
        throughput(nav, 16, 0.2, seed=0)
    out: dict = {
        "bench": "prefers_seen_throughput",
        "seconds": seconds,
        "rounds": rounds,
        "load_average_before": os.getloadavg()[0],
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "sizes": {},
    }
    for size in (16, 32, 48, 64):
        rates = {False: [], True: []}
        for _ in range(rounds):
            for setting, nav in navs.items():
                rates[setting].append(throughput(nav, size, seconds, seed=0)["robot_steps_per_cpu_s"])
        ratios = [on / off for on, off in zip(rates[True], rates[False], strict=True)]
        out["sizes"][str(size)] = {
            "off_robot_steps_per_cpu_s": round(float(np.median(rates[False]))),
            "on_robot_steps_per_cpu_s": round(float(np.median(rates[True]))),
            "ratio_on_off": round(float(np.median(ratios)), 3),
        }
        print(json.dumps({"size": size, **out["sizes"][str(size)]}), flush=True)
    out["load_average_after"] = os.getloadavg()[0]
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
