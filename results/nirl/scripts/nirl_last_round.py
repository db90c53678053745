"""The last round (or the last rounds' average) of NIRL runs that kept another (issue 15 part 7): what
the same run tests without ``--keep-best`` (and with ``--average-last``).

`bench/nirl.py --keep-best --save-runs` tests the round that validated best and saves every round's
weights (``weights_history.safetensors``). Validation only reads the greedy policy, so a run without
``--keep-best`` trains the same rounds and tests the last one: this evaluates that last round on the
same test episodes and appends a copy of each run's line with its figures (``keep_best`` false,
``last_round_of`` naming the saved run) to ``--out``, where ``python -m bench.nirl --report`` reads it.
With ``--average-last F`` the policy is the Q-network's weights averaged over that fraction of the
rounds at the end (``NIRLRun.average_last``; ``averaged_rounds`` on the line). ``--validation``
evaluates on the validation seed's episodes instead of the run's test episodes (how part 7 chose
``--average-last``; the lines then say ``"split": "validation"``).

    python nirl_last_round.py --runs runs11/own200k_0.jsonl [...] \\
        --out results/nirl/nirl_runs_part7.jsonl

Archived with the runs it made (results/nirl/); run it from the repository root with
``PYTHONPATH=. python results/nirl/scripts/nirl_last_round.py``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.policies import GreedyMLPPolicy
from agents.nirl.config import NIRLRun
from agents.nirl.weights import HISTORY_FILE, WeightHistory
from bench._common import machine_load
from bench._nirl_options import POLICY_RUNS
from bench._nirl_report import FAMILIES
from bench.nirl import NAVS, VALIDATION_SEED, figures


def last_round_policy(run_dir: Path, average_last: float = 0.0) -> tuple[GreedyMLPPolicy, int, int]:
    """The greedy policy of the last round in ``run_dir``'s weight history (or of the average over the
    last ``average_last`` of its rounds), that round and how many rounds it averages."""
    history = WeightHistory.load(run_dir / HISTORY_FILE)  # record 0: the warm start, then one per round
    averaged = max(1, NIRLRun(average_last=average_last).averaged_rounds(len(history) - 1))
    config = json.loads((run_dir / "config.json").read_text())
    return GreedyMLPPolicy(history.averaged("policy", averaged), config), history.iterations[-1], averaged


def main() -> int:
    raw = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=raw)
    parser.add_argument("--runs", nargs="+", required=True, help="bench/nirl.py runs files with kept rounds")
    parser.add_argument("--out", required=True, help="JSON lines file the last-round lines are appended to")
    parser.add_argument("--average-last", type=float, default=0.0, metavar="FRACTION",
                        help="average the Q-network over this fraction of the rounds at the end")  # fmt: skip
    parser.add_argument(
        "--validation", action="store_true", help=f"evaluate on validation seed {VALIDATION_SEED} episodes"
    )
    args = parser.parse_args()
    written = []
    for path in args.runs:
        for line in Path(path).read_text().splitlines():
            row = json.loads(line)
            if row["method"] != "nirl" or not row.get("keep_best"):
                continue
            run_dir = Path(f"{POLICY_RUNS}/{row['split']}-{row['set']}-{row['seed']}")
            policy, last, averaged = last_round_policy(run_dir, args.average_last)
            split = "validation" if args.validation else row["split"]
            seed = VALIDATION_SEED if split == "validation" else 0
            sets = [make_eval_set(f, row["episodes"], seed=seed) for f in FAMILIES]
            out = {k: v for k, v in row.items() if k not in ("selected_iteration", "load")} | {"split": split}
            tested = figures(evaluate(policy, sets, NAVS[row["nav"]]))
            out |= {"keep_best": False, "last_round_of": str(run_dir), "last_round": last, "test": tested}
            out |= {"kept_round": row["selected_iteration"], "load": machine_load()}
            if averaged > 1:
                out["averaged_rounds"] = averaged
            with open(args.out, "a") as fh:
                fh.write(json.dumps(out) + "\n")
            summary = {f: out["test"][f]["success"] for f in FAMILIES}
            kept = {f: row["test"][f]["success"] for f in FAMILIES}
            print(f"{row['set']} seed {row['seed']}: last round {last} ({averaged} averaged) {summary}, "
                  f"kept round {row['selected_iteration']} {kept}", flush=True)  # fmt: skip
            written.append({"set": row["set"], "seed": row["seed"], "last": summary, "kept": kept})
    print(json.dumps({"runs": written}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
