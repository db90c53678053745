"""One method's runs against another set of its runs on the same episodes (issue 15 part 8): McNemar's
exact test per demonstration set and episode family, the seeds both files ran pooled.

`bench/nirl.py --report` pairs methods within one file; this pairs two files of the same method, e.g.
a new setting's NIRL lines against an earlier part's (the same test episodes: seed 0's sets of
``--episodes`` per family, whatever the training did).

    python nirl_paired.py --a results/nirl/nirl_runs_part8.jsonl \\
        --b results/nirl/nirl_runs_part7.jsonl

Archived with the runs it made (results/nirl/); run it from the repository root with
``PYTHONPATH=. python results/nirl/scripts/nirl_paired.py``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from bench._nirl_report import FAMILIES, SETS, mcnemar, paired


def lines(path: Path, method: str, label: str) -> dict[tuple[str, str, int], dict]:
    """The last line of ``method`` per (demo set, seed) in a runs file (a re-run replaces its line),
    keyed ``(label, set, seed)`` as ``_nirl_report.paired`` reads cells."""
    rows = {}
    for line in path.read_text().splitlines():
        row = json.loads(line)
        if row["method"] == method:
            rows[(label, row["set"], row["seed"])] = row
    return rows


def main() -> int:
    raw = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=raw)
    parser.add_argument("--a", type=Path, required=True, help="runs file of the first setting")
    parser.add_argument("--b", type=Path, required=True, help="runs file of the setting it is compared with")
    parser.add_argument("--method", default="nirl", help="the method whose lines are paired (default nirl)")
    args = parser.parse_args()
    latest = lines(args.a, args.method, "a") | lines(args.b, args.method, "b")
    cells = {}
    for demo_set in SETS:
        seeds = sorted(seed for (label, s, seed) in latest if label == "a" and s == demo_set
                       and ("b", s, seed) in latest)  # fmt: skip
        for family in FAMILIES:
            if not seeds:
                continue
            x, y = paired(latest, ("a", demo_set), ("b", demo_set), family)
            only_a, only_b, p = mcnemar(x, y)
            rate_a, rate_b = sum(x) / len(x), sum(y) / len(y)
            print(f"{demo_set} {family}: {rate_a:.1%} vs {rate_b:.1%}, only a {only_a} / only b {only_b}, "
                  f"p = {p:.2g} (seeds {seeds}, n = {len(x)})")  # fmt: skip
            cells[f"{demo_set}/{family}"] = {"a": rate_a, "b": rate_b, "only_a": only_a, "only_b": only_b,
                                             "p": p, "n": len(x), "seeds": seeds}  # fmt: skip
    print(json.dumps({"bench": "nirl_paired", "a": str(args.a), "b": str(args.b), "cells": cells}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
