"""Shared evaluation (DESIGN.md "Evaluation"): fixed seeded evaluation sets, the metrics
the navigation literature reports, and plots of learned paths beside A*'s. Used by every
learner, the evaluator service and bench/.

    from agents.evaluation import make_eval_set, evaluate
    sets = [make_eval_set(f, 100, seed=0) for f in ("unseen", "dynamic", "movingai")]
    result = evaluate(policy, sets)          # policy: obs (n, d) float32 -> actions (n,) int64
    print(result.table()); report = result.to_dict()

    from agents.evaluation import compare       # two policies on the same episodes: McNemar, per family
    print(compare(result, evaluate(other, sets), names=("mine", "other")).table())
"""

from agents.evaluation.compare import Comparison, PairedRow, compare, mcnemar_exact
from agents.evaluation.metrics import FamilyMetrics, Rate
from agents.evaluation.plots import plot_learning_curves, plot_paths
from agents.evaluation.runner import (
    EVAL_FAMILIES,
    HEADLINE_EPISODES,
    EpisodeRecord,
    EvalResult,
    EvalSet,
    Policy,
    evaluate,
    make_eval_set,
    make_map_eval_set,
)

__all__ = [
    "EVAL_FAMILIES",
    "HEADLINE_EPISODES",
    "Comparison",
    "EpisodeRecord",
    "EvalResult",
    "EvalSet",
    "FamilyMetrics",
    "PairedRow",
    "Policy",
    "Rate",
    "compare",
    "evaluate",
    "make_eval_set",
    "make_map_eval_set",
    "mcnemar_exact",
    "plot_learning_curves",
    "plot_paths",
]
