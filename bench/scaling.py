"""Time to target against the number of actor processes (#18), on this machine.

For each actor count (1, 2, 4 by default) a fresh run of the real services, started as
`navlearn up` starts them (services.ops.up.Child: ``python -m services.cli ...``, logs in the
run's directory): a learner hosting the Zenoh router on a free 127.0.0.1 port, N actors of
--envs robots each connecting to it, and an evaluator measuring the greedy policy on --episodes
held-out maps of the validation set (--eval-seed 1; the test set is seed 0) every
--eval-every updates. The learner's settings are the defaults, the same in every run. The
robot world is compiled once before the first run (services.common.warmup), so no run pays
for it.

Time zero of a run is the first transition the learner receives (as `navlearn up` counts its
budget). From the evaluator's evaluations.jsonl: the seconds (and updates) until the success
pooled over the last --window evaluations first reaches each --thresholds value (one evaluation
of 500 episodes has a 95% interval of about +-4 points, so near a plateau a single one crosses
a threshold by chance). A run stops when that pooled success reaches --target, or after --cap
seconds. From the learner's status and /proc: its updates/s and its utilisation (CPU seconds /
wall seconds over the run), and the CPU share of the actors and the evaluator, i.e. where the
2 cores went. ``--recorded FILE`` runs nothing: it judges other --thresholds on the curves an
earlier run printed.

    python -m bench.scaling --actors 1 2 4 --cap 480   # human lines, one JSON object on the last line
    python -m bench.scaling --actors 1 4 1 4 --cap 60  # interleaved rounds
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from agents.evaluation.metrics import wilson_interval
from bench._common import machine_load, process_cpu, settings
from services.common.transport import TransportError, free_port, open_session
from services.common.warmup import compile_world
from services.evaluator.evaluator import LINES_FILE
from services.ops.status import query_status
from services.ops.up import Child
from services.ops.up_config import UpConfig

POLL_S = 2.0
"""seconds between two looks at the learner's status, the processes' CPU and the evaluations"""
FIRST_POLL_S = 0.2
"""the same until the first transition arrives (it is time zero)"""
START_TIMEOUT_S = 600.0
"""a run whose learner has received nothing by then has failed to start"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--actors",
        type=int,
        nargs="+",
        default=[1, 2, 4],
        help="actor process counts, one run each, in order",
    )
    p.add_argument("--envs", type=int, default=UpConfig.envs, help="robots per actor")
    p.add_argument("--maps", default=UpConfig.maps, help="training map spec of the actors")
    p.add_argument("--cap", type=float, default=480.0, help="seconds of training per run at most")
    p.add_argument("--target", type=float, default=0.8, help="validation success that ends a run")
    p.add_argument(
        "--thresholds", type=float, nargs="+", default=[0.5, 0.6, 0.7, 0.8], help="success levels timed"
    )
    p.add_argument("--family", default="unseen", help="evaluation family (agents.evaluation)")
    p.add_argument("--episodes", type=int, default=500, help="evaluation episodes per version")
    p.add_argument("--eval-seed", type=int, default=1, help="evaluation set seed (1: validation)")
    p.add_argument("--eval-every", type=int, default=1000, help="updates between evaluated versions")
    p.add_argument("--window", type=int, default=3, help="evaluations pooled to judge a threshold")
    p.add_argument(
        "--recorded", default="", help="run nothing: judge --thresholds again on this earlier output's curves"
    )
    p.add_argument("--out", default="", help="keep the runs' directories here (default: a temporary one)")
    return p.parse_args(argv)


def curve(lines: list[dict[str, Any]], family: str) -> list[dict[str, Any]]:
    """The evaluator's points (evaluations.jsonl rows of the NNQL model), in report order: time,
    version, successes ``count`` of ``n`` episodes, ``success`` with its 95% Wilson interval."""
    points = []
    for line in lines:
        metrics = line.get("metrics", {}).get(family)
        if not metrics or line.get("model") not in (None, "nnql"):
            continue
        success = metrics["success"]
        points.append(
            {
                "time": line["time"],
                "version": line["policy_version"],
                "count": success["count"],
                "n": success["n"],
                "success": success["value"],
                "low": round(success["low"], 3),
                "high": round(success["high"], 3),
            }
        )
    return sorted(points, key=lambda p: p["time"])


def pooled(points: list[dict[str, Any]]) -> dict[str, float]:
    """Success over all the episodes of ``points`` with its 95% Wilson interval."""
    count, n = sum(p["count"] for p in points), sum(p["n"] for p in points)
    low, high = wilson_interval(count, n)
    return {"success": round(count / n, 4), "low": round(low, 3), "high": round(high, 3)}


def crossings(
    points: list[dict[str, Any]], start: float, thresholds: list[float], window: int
) -> dict[str, Any]:
    """For each threshold, the first evaluation (report order) at which the success pooled over it
    and the ``window - 1`` evaluations before it reaches the threshold: seconds since ``start``
    (unix time), policy version (updates), the pooled success and its 95% Wilson interval. A
    single evaluation near a plateau crosses a threshold by chance; pooling a few holds it to the
    level the policy keeps. None where it was never reached."""
    out: dict[str, Any] = {}
    for threshold in thresholds:
        hit = None
        for i, point in enumerate(points):
            mean = pooled(points[max(0, i + 1 - window) : i + 1])
            if i + 1 >= window and mean["success"] >= threshold:
                hit = {"s": round(point["time"] - start, 1), "version": point["version"], **mean}
                break
        out[f"{threshold:g}"] = hit
    return out


def highest_common(runs: list[dict[str, Any]], thresholds: list[float]) -> float | None:
    """The highest threshold that every run reached (None if some run reached none)."""
    common = [t for t in thresholds if all(run["reached"][f"{t:g}"] is not None for run in runs)]
    return max(common) if common else None


def common_summary(runs: list[dict[str, Any]], thresholds: list[float]) -> dict[str, Any]:
    """The highest threshold all runs reached, and each run's seconds and updates to it (in run
    order: an actor count may appear more than once)."""
    common = highest_common(runs, thresholds)
    to_common = []
    for run in runs:
        hit = run["reached"][f"{common:g}"] if common is not None else None
        to_common.append({"actors": run["actors"], "s": hit and hit["s"], "updates": hit and hit["version"]})
    return {"highest_common_threshold": common, "to_common": to_common}


def rejudge(recorded: dict[str, Any], thresholds: list[float], window: int) -> dict[str, Any]:
    """The thresholds judged again on the curves a finished run printed (``--recorded``): a level
    no run was stopped at can be timed without training again."""
    n = recorded["settings"]["episodes"]
    runs = []
    for run in recorded["runs"]:
        points = [
            {"time": p["s"], "version": p["version"], "count": round(p["success"] * n), "n": n}
            for p in run["curve"]
        ]
        runs.append({"actors": run["actors"], "reached": crossings(points, 0.0, thresholds, window)})
    return {
        "bench": "scaling",
        "rejudged": True,
        "window": window,
        "runs": runs,
        **common_summary(runs, thresholds),
    }


def learner_counts(status) -> tuple[int, int, float]:
    """Transitions received from all actors, updates run and the status' updates/s (0s before an answer)."""
    if status is None:
        return 0, 0, 0.0
    received = sum(v for k, v in status.counters.items() if k.startswith("transitions/"))
    return received, status.versions.get("nnql", 0), round(status.rates.get("updates_per_s", 0.0), 1)


def read_lines(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    rows = []
    for line in path.read_text().splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:  # a line being written as we read
            break
    return rows


class ScalingRun:
    """Learner, ``n_actors`` actors and the evaluator of one run, with their CPU bookkeeping."""

    def __init__(self, n_actors: int, args: argparse.Namespace, root: Path, index: int = 0) -> None:
        """``index``: the run's place in the bench (an actor count may be run more than once)."""
        self.n_actors, self.args = n_actors, args
        self.run = f"scaling{index}x{n_actors}x{os.getpid()}"
        self.out = root / f"run-{index}-actors-{n_actors}"  # a fresh learner: no checkpoint to resume
        (self.out / "logs").mkdir(parents=True, exist_ok=True)
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
        self.env["PYTHONUNBUFFERED"] = "1"
        self.children: dict[str, Child] = {}
        self.launched = 0.0

    def start(self) -> None:
        a, common = self.args, ["--run", self.run]
        self.launched = time.time()
        self._spawn("learner", "learner", "--listen", self.endpoint, *common,
                    "--checkpoint-dir", str(self.out / "checkpoints"),
                    "--checkpoint-every", str(UpConfig.checkpoint_every))  # fmt: skip
        for i in range(self.n_actors):
            self._spawn(f"actor-{i + 1}", "actor", "--connect", self.endpoint, *common,
                        "--id", f"actor-{i + 1}", "--envs", str(a.envs), "--maps", a.maps,
                        "--seed", str(i))  # fmt: skip
        self._spawn("evaluator", "evaluator", "--connect", self.endpoint, *common,
                    "--families", a.family, "--episodes", str(a.episodes),
                    "--eval-seed", str(a.eval_seed), "--every-versions", str(a.eval_every),
                    "--out", str(self.out / "eval"))  # fmt: skip

    def _spawn(self, name: str, *argv: str) -> None:
        self.children[name] = Child(name, list(argv), self.out / "logs", self.env)

    def cpu(self) -> dict[str, float]:
        """CPU seconds so far of the learner, all actors together, and the evaluator."""
        per = {name: process_cpu(c.process.pid) for name, c in self.children.items() if c.alive()}
        actors = sum(v for k, v in per.items() if k.startswith("actor-"))
        return {"learner": per.get("learner", 0.0), "actors": actors, "evaluator": per.get("evaluator", 0.0)}

    def check_alive(self) -> None:
        for child in self.children.values():
            if not child.alive():
                raise SystemExit(f"{child.name} exited with {child.process.returncode}:\n{child.tail()}")

    def check_started(self, deadline: float) -> None:
        self.check_alive()
        if time.monotonic() > deadline:
            raise SystemExit(
                f"no transition reached the learner in {START_TIMEOUT_S:.0f} s; see {self.out}/logs"
            )

    def watch(self) -> dict[str, Any]:
        """Polls until the target is reached or the cap is spent; the run's figures."""
        a = self.args
        session, deadline = None, time.monotonic() + START_TIMEOUT_S
        while session is None:
            self.check_started(deadline)
            try:
                session = open_session(settings(self.endpoint, self.run), connect_timeout=1.0)
            except TransportError:
                time.sleep(1.0)
        first = None  # time.time(), time.monotonic(), CPU seconds and counts at the first transition received
        samples, points, received, updates, rate = [], [], 0, 0, 0.0
        with session:
            while True:
                if first is None:
                    self.check_started(deadline)
                self.check_alive()
                status = query_status(session, self.run, timeout=2.0)
                now, mono, cpu = time.time(), time.monotonic(), self.cpu()
                if status is not None:  # else the last answer's counts stand
                    received, updates, rate = learner_counts(status)
                if first is None and received > 0:
                    first = {"time": now, "mono": mono, "cpu": cpu, "updates": updates, "received": received}
                    print(f"  {self.n_actors} actor(s): first transition after {now - self.launched:.0f} s")
                if first is not None:
                    samples.append(
                        {"s": round(mono - first["mono"], 1), "updates": updates, "updates_per_s": rate}
                    )
                    points = curve(read_lines(self.out / "eval" / LINES_FILE), a.family)
                    there = crossings(points, first["time"], [a.target], a.window)[f"{a.target:g}"]
                    if mono - first["mono"] >= a.cap or there is not None:
                        break
                time.sleep(POLL_S if first else FIRST_POLL_S)
        wall = mono - first["mono"]
        used = {k: round((cpu[k] - first["cpu"][k]) / wall, 3) for k in cpu}
        reached = crossings(points, first["time"], a.thresholds, a.window)
        return {
            "actors": self.n_actors,
            "training_s": round(wall, 1),
            "first_transition_s": round(first["time"] - self.launched, 1),
            "target_reached": reached[f"{a.target:g}"] is not None,
            "reached": reached,
            "best_single_success": max((p["success"] for p in points), default=None),
            "best_pooled_success": max(
                (pooled(points[i : i + a.window])["success"] for i in range(len(points) - a.window + 1)),
                default=None,
            ),
            "updates": updates - first["updates"],
            "updates_per_s": round((updates - first["updates"]) / wall, 1),
            "transitions_per_s": round((received - first["received"]) / wall, 1),
            "learner_utilisation": used["learner"],
            "cores_used": {**used, "total": round(sum(used.values()), 3)},
            "evaluations": len(points),
            "curve": [
                {"s": round(p["time"] - first["time"], 1), "version": p["version"], "success": p["success"]}
                for p in points
            ],
            "status_samples": samples[:: max(1, len(samples) // 60)],
        }

    def stop(self) -> None:
        """Actors, then the learner, then the evaluator (as `navlearn up` orders them)."""
        order = [n for n in self.children if n.startswith("actor-")] + ["learner", "evaluator"]
        for name in order:
            self.children[name].terminate()
        for name in order:
            self.children[name].wait(60)


def one_run(n_actors: int, args: argparse.Namespace, root: Path, index: int) -> dict[str, Any]:
    load_start = machine_load()
    run = ScalingRun(n_actors, args, root, index)
    run.start()
    try:
        result = run.watch()
    finally:
        run.stop()
    result["load_start"], result["load_end"] = load_start, machine_load()
    return result


def report_line(run: dict[str, Any]) -> str:
    hits = ", ".join(
        f"{t}: " + ("-" if hit is None else f"{hit['s']:.0f} s ({hit['version']} updates)")
        for t, hit in run["reached"].items()
    )
    return (
        f"{run['actors']} actor(s): {run['training_s']:.0f} s trained, "
        f"best pooled success {run['best_pooled_success']}, "
        f"{run['updates_per_s']} updates/s, learner utilisation {run['learner_utilisation']:.2f}, "
        f"cores used {run['cores_used']['total']:.2f} (load {run['load_start'][0]}->{run['load_end'][0]}); "
        f"to threshold {hits}"
    )


def main() -> None:
    args = parse_args()
    args.thresholds = sorted({*args.thresholds, args.target})  # the target is always timed
    if args.recorded:
        recorded = json.loads(Path(args.recorded).read_text().strip().splitlines()[-1])
        print(json.dumps(rejudge(recorded, args.thresholds, args.window)))
        return
    seconds, compiled = compile_world(args.maps)
    print(f"robot world {'compiled' if compiled else 'loaded'} in {seconds:.0f} s")
    with tempfile.TemporaryDirectory(prefix="navlearn-scaling-") as tmp:
        root = Path(args.out or tmp)
        runs = []
        for index, n_actors in enumerate(args.actors):
            runs.append(one_run(n_actors, args, root, index))
            print(report_line(runs[-1]), flush=True)
    result = {
        "bench": "scaling",
        "settings": {k: v for k, v in vars(args).items() if k not in ("out", "recorded")},
        **common_summary(runs, args.thresholds),
        "runs": runs,
        "load_average_1min": machine_load()[0],
        "cpus": os.cpu_count(),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
