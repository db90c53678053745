"""Paired comparison of two policies evaluated on the same episodes.

Two policies run on the same fixed evaluation sets (same tasks, same env seeds, so the same
start headings, noise and moving discs) give *paired* outcomes, and the right test for a
difference in success is McNemar's, not two independent intervals (DESIGN.md, "Evaluation").
Only the discordant episodes carry information: ``a_only`` solved by A and not by B, ``b_only``
the reverse. Under "equally good", each discordant episode is A's with probability 1/2, so the
exact two-sided p-value is the binomial test of ``a_only`` out of ``a_only + b_only`` at 1/2
(McNemar 1947; the exact form, not the chi-square approximation, which is poor with few
discordant pairs).

Each row of a :class:`Comparison` is one evaluation set (``unseen``, ``dynamic``, ...) as a
whole (map family ``all``) or one of its map families (``rects``, ``discs``, ``rooms``; none
for a set of one map family, such as ``movingai``): both success rates with 95% Wilson
intervals, the four cells of the paired table, McNemar's p, SPL of each, and the path-length
ratio to A* of each on the episodes *both* solved (each policy's own successes would compare
paths on different, easier or harder, episodes).

    from agents.evaluation import compare, evaluate, make_eval_set
    sets = [make_eval_set(f, 500) for f in ("unseen", "dynamic")]
    c = compare(evaluate(policy_a, sets), evaluate(policy_b, sets), names=("nnql", "heuristic"))
    print(c.table()); report = c.to_dict()
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import binomtest

from agents.evaluation.metrics import Rate, json_fields, path_ratio, rate, spl
from agents.evaluation.runner import EpisodeRecord, EvalResult
from worlds.outcomes import Outcome

ALL_FAMILIES = "all"
"""the map-family label of the row over a whole evaluation set"""


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """Two-sided exact McNemar p-value from the discordant counts (1.0 when there are none)."""
    if a_only < 0 or b_only < 0:
        raise ValueError(f"discordant counts must be non-negative, got a_only={a_only}, b_only={b_only}")
    if a_only + b_only == 0:
        return 1.0
    return float(binomtest(int(a_only), int(a_only + b_only), 0.5, alternative="two-sided").pvalue)


@dataclass(frozen=True)
class PairedRow:
    """Two policies on the same ``episodes``."""

    episodes: int
    success_a: Rate
    success_b: Rate
    both: int
    """episodes both solved"""
    a_only: int
    """episodes A solved and B did not"""
    b_only: int
    neither: int
    p_value: float
    """exact two-sided McNemar p-value of A and B having the same success rate"""
    spl_a: float
    spl_b: float
    path_ratio_a: float
    """A's mean travelled / A* length on the episodes both solved (nan when none)"""
    path_ratio_b: float

    def to_dict(self) -> dict[str, object]:
        return json_fields(self)


def paired_row(
    success_a: np.ndarray,
    success_b: np.ndarray,
    shortest: np.ndarray,
    taken_a: np.ndarray,
    taken_b: np.ndarray,
) -> PairedRow:
    """The paired figures from per-episode arrays: success of each policy, A* length (m) and
    the length each policy travelled (m)."""
    a, b = np.asarray(success_a, dtype=bool), np.asarray(success_b, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"success_a and success_b must pair up, got shapes {a.shape} and {b.shape}")
    both = a & b
    a_only, b_only = int((a & ~b).sum()), int((~a & b).sum())
    return PairedRow(
        episodes=len(a),
        success_a=rate(int(a.sum()), len(a)),
        success_b=rate(int(b.sum()), len(b)),
        both=int(both.sum()),
        a_only=a_only,
        b_only=b_only,
        neither=int((~a & ~b).sum()),
        p_value=mcnemar_exact(a_only, b_only),
        spl_a=spl(a, shortest, taken_a),
        spl_b=spl(b, shortest, taken_b),
        path_ratio_a=path_ratio(both, shortest, taken_a),
        path_ratio_b=path_ratio(both, shortest, taken_b),
    )


@dataclass(frozen=True)
class Comparison:
    """Policy A against policy B; ``rows[set][map family]`` with family ``all`` first."""

    names: tuple[str, str]
    rows: dict[str, dict[str, PairedRow]]

    def to_dict(self) -> dict:
        return {
            "a": self.names[0],
            "b": self.names[1],
            "sets": {s: {f: row.to_dict() for f, row in fams.items()} for s, fams in self.rows.items()},
        }

    def table(self) -> str:
        """A fixed-width text table, one row per evaluation set and map family."""

        def pct(r: Rate) -> str:
            return f"{100 * r.value:5.1f} [{100 * r.low:4.1f},{100 * r.high:5.1f}]"

        def num(v: float, fmt: str) -> str:
            return format(v, fmt) if math.isfinite(v) else "-"

        a, b = self.names
        lines = [
            f"A = {a}",
            f"B = {b}",
            "A only / B only: episodes one solved and the other did not; p: exact McNemar (two-sided); "
            "len/A*: on the episodes both solved",
        ]
        head = (
            f"{'set':<9} {'family':<8} {'n':>4}  {'A success % [95% CI]':<20} {'B success % [95% CI]':<20} "
            f"{'A only':>6} {'B only':>6} {'p':>8} {'SPL A':>5} {'SPL B':>5} {'both':>4} "
            f"{'len/A* A':>8} {'len/A* B':>8}"
        )
        lines += [head, "-" * len(head)]
        for set_name, fams in self.rows.items():
            for fam, r in fams.items():
                lines.append(
                    f"{set_name:<9} {fam:<8} {r.episodes:>4}  {pct(r.success_a):<20} {pct(r.success_b):<20} "
                    f"{r.a_only:>6} {r.b_only:>6} {r.p_value:>8.2g} {num(r.spl_a, '5.2f'):>5} "
                    f"{num(r.spl_b, '5.2f'):>5} {r.both:>4} {num(r.path_ratio_a, '8.3f'):>8} "
                    f"{num(r.path_ratio_b, '8.3f'):>8}"
                )
        return "\n".join(lines)


def _check_paired(set_name: str, eps_a: list[EpisodeRecord], eps_b: list[EpisodeRecord]) -> None:
    if len(eps_a) != len(eps_b):
        raise ValueError(
            f"set {set_name!r}: A has {len(eps_a)} episodes, B {len(eps_b)}; evaluate both on the same sets"
        )
    for k, (ea, eb) in enumerate(zip(eps_a, eps_b, strict=True)):
        key_a = (ea.task.map_id, ea.task.start, ea.task.goal, ea.seed)
        key_b = (eb.task.map_id, eb.task.start, eb.task.goal, eb.seed)
        if key_a != key_b:
            raise ValueError(
                f"set {set_name!r}, episode {k}: A ran (map, start, goal, seed) {key_a}, B {key_b}; "
                "evaluate both on the same sets (same family, episodes, seed and size)"
            )


def compare(result_a: EvalResult, result_b: EvalResult, names: Sequence[str] = ("A", "B")) -> Comparison:
    """Pair the episodes of two evaluations of the same sets (see the module docstring).
    Raises ValueError when a set is missing from ``result_b`` or its episodes differ."""
    if len(names) != 2:
        raise ValueError(f"names must hold two labels, got {list(names)}")
    missing = [s for s in result_a.episodes if s not in result_b.episodes]
    if missing:
        raise ValueError(f"sets {missing} were evaluated for A but not for B ({list(result_b.episodes)})")
    rows: dict[str, dict[str, PairedRow]] = {}
    for set_name, eps_a in result_a.episodes.items():
        eps_b = result_b.episodes[set_name]
        _check_paired(set_name, eps_a, eps_b)
        family = np.array([e.map_family for e in eps_a])
        a = np.array([e.outcome == Outcome.GOAL for e in eps_a], dtype=bool)
        b = np.array([e.outcome == Outcome.GOAL for e in eps_b], dtype=bool)
        shortest = np.array([e.shortest for e in eps_a])
        taken_a = np.array([e.path_length for e in eps_a])
        taken_b = np.array([e.path_length for e in eps_b])
        groups = [(ALL_FAMILIES, np.ones(len(eps_a), bool))]
        distinct = list(dict.fromkeys(family.tolist()))
        if len(distinct) > 1:  # one family (MovingAI's one map) would repeat the "all" row
            groups += [(f, family == f) for f in distinct]
        rows[set_name] = {
            name: paired_row(a[m], b[m], shortest[m], taken_a[m], taken_b[m]) for name, m in groups
        }
    return Comparison((str(names[0]), str(names[1])), rows)
