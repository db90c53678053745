"""``navlearn drive`` against ``navlearn evaluate``, paired: the same policy, maps, starts and goals.

For each of the first ``--episodes`` episodes of the ``unseen`` evaluation set (seed ``--seed``):

1. ``agents.evaluation.evaluate`` (what ``navlearn evaluate`` runs) gives the policy's outcome in
   the world, with its discrete steps; both sides act through the policy's reading shield
   (:mod:`agents.shield`), the default of ``navlearn evaluate`` and ``navlearn drive``;
2. the same episode through the ROS 2 wire: a Zenoh router (``navlearn router``), one
   ``navlearn drive`` for the whole run, and per episode a ``navlearn ros2-sim --map unseen:<k>``
   (the episode's map, start cell, start heading and goal); the goal is published as a
   geometry_msgs/PoseStamped and the outcome read from the two status keys
   (:class:`services.drive.trial.Trial`). The drive gives up after 200 actions (the world's step
   limit); the sim's lidar has 360 beams with 1 cm noise, the motion is continuous.

It prints one JSON line: episodes, successes in each, successes of the drive among the episodes
the world solved (the issue's criterion: at least 95%), outcome counts and wall time; with
``--out`` it also writes one line per episode to ``<out>/episodes.jsonl`` as each ends. Stopped
(Ctrl-C or SIGTERM), it stops the router, the drive and the sim it started, and keeps the episodes
written so far.

    python -m bench.ros2_drive --episodes 40 --out results/ros2
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.policies import load_policy
from bench._common import free_port, spawn, stop
from services.common.transport import ZenohSettings, open_session
from services.drive.trial import Trial
from tests.drive_helpers import FAST
from worlds.outcomes import OUTCOME_NAMES


def world_outcomes(policy_dir: str, episodes: int, seed: int) -> list[str]:
    """Outcome name of each episode in the world (``navlearn evaluate``'s runner)."""
    policy = load_policy(policy_dir)
    policy.use_shield(policy.nav_config())  # both sides act through the reading shield, their default
    result = evaluate(policy, make_eval_set("unseen", episodes, seed=seed))
    return [OUTCOME_NAMES[r.outcome] for r in result.episodes["unseen"]]


def _interrupt(signum: int, _frame) -> None:
    """SIGTERM unwinds like Ctrl-C, so the ``finally`` blocks stop the processes this run started."""
    raise KeyboardInterrupt(f"signal {signum}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=40, help="first episodes of the unseen set")
    parser.add_argument("--seed", type=int, default=0, help="evaluation set seed (navlearn evaluate --seed)")
    parser.add_argument("--policy", default="pretrained/nnql", help="saved policy directory")
    parser.add_argument(
        "--timeout",
        type=float,
        default=400.0,
        help="wall-clock limit per episode (s): 200 actions take about 300 s here",
    )
    parser.add_argument("--out", help="directory for episodes.jsonl and the logs")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, _interrupt)

    started = time.time()
    world = world_outcomes(args.policy, args.episodes, args.seed)
    out = Path(args.out) if args.out else Path("runs/ros2_drive")
    out.mkdir(parents=True, exist_ok=True)
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    episodes_file = open(out / "episodes.jsonl", "w")  # noqa: SIM115 (closed in the finally below)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    zenoh = ("--connect", endpoint, "--run", "bench")
    cli = ("-m", "services.cli")
    router = spawn(*cli, "router", "--listen", endpoint, log=open(logs / "router.log", "w"))  # noqa: SIM115
    drive = spawn(*cli, "drive", "--policy", args.policy, "--max-actions", "200", *FAST, *zenoh,
                  log=open(logs / "drive.log", "w"))  # fmt: skip  # noqa: SIM115
    rows = []
    try:
        session = open_session(ZenohSettings(connect=[endpoint], run="bench", connect_timeout=60))
        with session, Trial(session, "bench") as trial:
            for k in range(args.episodes):
                sim = spawn(*cli, "ros2-sim", "--map", f"unseen:{k}", "--eval-seed", str(args.seed),
                            "--odom-rate", "100", "--scan-rate", "20", *zenoh,
                            log=open(logs / f"sim_{k}.log", "w"))  # fmt: skip  # noqa: SIM115
                try:
                    result = trial.run_goal(timeout=args.timeout)
                except RuntimeError as exc:
                    result = {"outcome": "error", "error": str(exc)}
                finally:
                    stop(sim, timeout=20)
                row = {"episode": k, "world": world[k], "drive": result["outcome"], **result}
                rows.append(row)
                print(json.dumps(row), file=episodes_file, flush=True)
                print(json.dumps(row), file=sys.stderr, flush=True)
    finally:
        episodes_file.close()
        stop(drive, timeout=20)
        stop(router, timeout=20)
    world_ok = [r for r in rows if r["world"] == "goal"]
    both = [r for r in world_ok if r["drive"] == "success"]
    summary = {
        "bench": "ros2_drive",
        "policy": args.policy,
        "set": "unseen",
        "seed": args.seed,
        "episodes": len(rows),
        "world_success": len(world_ok),
        "drive_success": sum(r["drive"] == "success" for r in rows),
        "drive_success_where_world_succeeds": len(both),
        "ratio": round(len(both) / len(world_ok), 4) if world_ok else None,
        "drive_only_success": sum(r["drive"] == "success" and r["world"] != "goal" for r in rows),
        "drive_outcomes": dict(Counter(r["drive"] for r in rows)),
        "world_outcomes": dict(Counter(r["world"] for r in rows)),
        "median_wall_s_per_episode": sorted(r.get("wall_s", 0) for r in rows)[len(rows) // 2]
        if rows
        else None,
        "wall_s": round(time.time() - started, 1),
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
