"""Keep-best: which of a run's evaluated policy versions is kept, and on which episodes it is chosen.

A learner's greedy policy swings from version to version (a Q-network that reached its target may
lose it a few hundred updates later), so a run keeps the version that scored best on the validation
episodes (:data:`VALIDATION_SEED`) rather than the last one, and reports it on the test episodes
(:data:`TEST_SEED`), which never choose anything. ``navlearn train --local`` and ``navlearn up`` (its
evaluator service) choose by the same rule, :func:`score`.
"""

from __future__ import annotations

import math
from typing import Any

VALIDATION_SEED = 1
"""evaluations that choose (keep-best's, periodic ones) play the held-out episodes of this seed"""
TEST_SEED = 0
"""the reported evaluation of a kept policy plays the episodes of this seed (`navlearn evaluate`'s)"""


def score(metrics: dict[str, dict[str, Any]]) -> tuple[float, float]:
    """Keep-best's figure of one evaluation (an EvalReport's metrics: family or env id -> figures):
    (success rate, SPL) pooled over navlearn's families by their episodes; on a Gymnasium env (whose
    figures have a ``return``) its success rate where the env says it, else its mean return, then its
    mean return. Higher is better, compared as a tuple."""
    weighted = [0.0, 0.0]
    episodes = 0
    for family in metrics.values():
        n = int(family["episodes"])
        if isinstance(family.get("return"), dict):  # agents.evaluation.env_returns
            mean = family["return"]["mean"]
            first = family["success"]["value"] if "success" in family else mean
            pair = (first, mean)
        else:  # agents.evaluation.metrics.FamilyMetrics.to_dict()
            spl = family.get("spl")
            pair = (family["success"]["value"], spl if spl is not None and math.isfinite(spl) else 0.0)
        weighted[0] += pair[0] * n
        weighted[1] += pair[1] * n
        episodes += n
    if episodes == 0:
        raise ValueError(f"no episodes to score in metrics of {sorted(metrics)}")
    return weighted[0] / episodes, weighted[1] / episodes
