"""First run: how long the robot world takes to compile on a cold numba cache, and to load warm.

`navlearn up` compiles the world once (services.common.warmup.compile_world) before it starts
its processes; before, every process compiled it at the same time while the training clock
ran. Each round runs compile_world in a fresh Python process with NUMBA_CACHE_DIR pointed at
a new empty directory (cold), then again in another fresh process on that cache (warm), and
reports the seconds compile_world took in each (imports excluded) with the load average.

    python bench/first_run.py --rounds 2     # human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CHILD = (
    "import json; from services.common.warmup import compile_world; "
    "seconds, compiled = compile_world({maps!r}); print(json.dumps([seconds, compiled]))"
)


def timed(cache: str, maps: str) -> tuple[float, bool]:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    done = subprocess.run(
        [sys.executable, "-c", CHILD.format(maps=maps)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=900,
    )
    seconds, compiled = json.loads(done.stdout.strip().splitlines()[-1])
    return float(seconds), bool(compiled)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="cold + warm pairs")
    parser.add_argument("--maps", default="mixed:16", help="map spec compiled for")
    args = parser.parse_args()
    cold, warm = [], []
    for round_ in range(args.rounds):
        with tempfile.TemporaryDirectory(prefix="navlearn-numba-") as cache:
            load = os.getloadavg()[0]
            seconds, compiled = timed(cache, args.maps)
            assert compiled, "a cold cache compiled nothing: NUMBA_CACHE_DIR was not honoured"
            cold.append(seconds)
            again, compiled_again = timed(cache, args.maps)
            assert not compiled_again, "the warm run compiled again: the cache was not used"
            warm.append(again)
            print(f"round {round_ + 1}: cold {seconds:.1f} s, warm {again:.2f} s (load {load:.1f})")
    print(
        json.dumps(
            {
                "bench": "first_run",
                "maps": args.maps,
                "cold_s": [round(x, 1) for x in cold],
                "warm_s": [round(x, 2) for x in warm],
                "load_average_1min": round(os.getloadavg()[0], 2),
                "cpus": os.cpu_count(),
            }
        )
    )


if __name__ == "__main__":
    main()
