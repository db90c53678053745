"""First run: how long the robot world takes to compile on a cold numba cache, and to load warm.

`navlearn up` compiles the world once (services.common.warmup.compile_world) before it starts
its processes; before, every process compiled it at the same time while the training clock
ran. Each round runs compile_world in a fresh Python process with NUMBA_CACHE_DIR pointed at
a new empty directory (cold), then again in another fresh process on that cache (warm), and
reports the seconds compile_world took in each (imports excluded) with the load average, and the
CPU seconds of the compiling process (the compile is one thread: on a shared machine its CPU
time compares trees better than the wall clock, which grows with the other processes' load).
With ``--up SECONDS`` it also runs ``navlearn up --duration SECONDS`` (the README's settings
otherwise: 2 actors x 8 robots) on another empty cache and reports the compile step, the
seconds from the processes' start to the first transition, and the seconds trained.

    python -m bench.first_run --rounds 2 --up 30   # human lines, then one JSON object on the last line

With ``--before DIR`` (another checkout, e.g. ``git archive main | tar -x -C DIR``) each round also
times a cold compile of that tree, alternating which goes first, so that both see the same load.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CHILD = (
    "import json, time; from services.common.warmup import compile_world; cpu = time.process_time(); "
    "seconds, compiled = compile_world({maps!r}); "
    "print(json.dumps([seconds, compiled, time.process_time() - cpu]))"
)


def timed(cache: str, maps: str, repo: Path = REPO) -> tuple[float, bool, float]:
    """compile_world of ``repo`` in a fresh process on numba cache ``cache``: (seconds, whether it
    compiled anything, CPU seconds of that process during compile_world)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(repo)}
    done = subprocess.run(
        [sys.executable, "-c", CHILD.format(maps=maps)],
        cwd=repo,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=900,
    )
    seconds, compiled, cpu = json.loads(done.stdout.strip().splitlines()[-1])
    return float(seconds), bool(compiled), float(cpu)


def cold_up(duration: float) -> dict:
    """`navlearn up --duration` on an empty numba cache: compile, first transition, training."""
    with tempfile.TemporaryDirectory(prefix="navlearn-up-") as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
        env["NUMBA_CACHE_DIR"] = str(Path(tmp) / "numba")
        out = Path(tmp) / "run"
        argv = [sys.executable, "-m", "services.cli", "up", "--run", f"firstrun{os.getpid()}",
                "--out", str(out), "--duration", str(duration)]  # fmt: skip
        load = os.getloadavg()[0]
        done = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True, timeout=1800)
        if done.returncode != 0:
            raise SystemExit(f"navlearn up failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
        compiled = re.search(r"robot world compiled in (\d+) s", done.stdout)
        summary = json.loads((out / "summary.json").read_text())
        learner = summary["last_status"]["learner"]
        return {
            "duration": duration,
            "compile_s": float(compiled.group(1)) if compiled else None,
            "first_transition_s": summary["first_transition_s"],
            "training_s": summary["training_s"],
            "wall_after_compile_s": summary["wall_time_s"],
            "final_version": summary["final_version"],
            "transitions": sum(a["transitions"] for a in learner["actors"].values()),
            "load_average_1min_at_start": round(load, 2),
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="cold + warm pairs")
    parser.add_argument("--maps", default="mixed:16", help="map spec compiled for")
    parser.add_argument("--before", default="", help="another checkout to time a cold compile of too")
    parser.add_argument("--up", type=float, default=0.0, help="also a cold `navlearn up` of this budget (s)")
    args = parser.parse_args()
    cold, warm, before = [], [], []
    for round_ in range(args.rounds):
        order = ["after", "before"] if round_ % 2 else ["before", "after"]
        for which in order if args.before else ["after"]:
            with tempfile.TemporaryDirectory(prefix="navlearn-numba-") as cache:
                load = os.getloadavg()[0]
                if which == "before":
                    seconds, compiled, cpu = timed(cache, args.maps, Path(args.before).resolve())
                    assert compiled, "a cold cache compiled nothing: NUMBA_CACHE_DIR was not honoured"
                    before.append((seconds, load, cpu))
                    line = (
                        f"round {round_ + 1}: before cold {seconds:.1f} s, {cpu:.1f} CPU s (load {load:.1f})"
                    )
                    print(line, flush=True)
                    continue
                seconds, compiled, cpu = timed(cache, args.maps)
                assert compiled, "a cold cache compiled nothing: NUMBA_CACHE_DIR was not honoured"
                cold.append((seconds, load, cpu))
                again, compiled_again, _ = timed(cache, args.maps)
                assert not compiled_again, "the warm run compiled again: the cache was not used"
                warm.append(again)
                line = f"round {round_ + 1}: cold {seconds:.1f} s, {cpu:.1f} CPU s, warm {again:.2f} s"
                line += f" (load {load:.1f})"
                print(line, flush=True)
    up = cold_up(args.up) if args.up else None
    if up:
        print(
            f"cold up: compiled in {up['compile_s']} s, first transition {up['first_transition_s']} s "
            f"after the processes started, {up['training_s']} s trained of {args.up:.0f}"
        )
    result = {
        "bench": "first_run",
        "maps": args.maps,
        "cold_s": [round(x, 1) for x, _, _ in cold],
        "cold_cpu_s": [round(x, 1) for _, _, x in cold],
        "cold_load_1min": [round(x, 2) for _, x, _ in cold],
        "before": str(args.before) if args.before else None,
        "before_cold_s": [round(x, 1) for x, _, _ in before],
        "before_cpu_s": [round(x, 1) for _, _, x in before],
        "before_load_1min": [round(x, 2) for _, x, _ in before],
        "warm_s": [round(x, 2) for x in warm],
        "up": up,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
