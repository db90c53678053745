"""The evaluator service's settings (`navlearn evaluator` flags), apart so the CLI parser builds fast."""

from __future__ import annotations

from dataclasses import dataclass

from worlds.config import observation_field


@dataclass
class EvaluatorConfig:
    """The evaluator service: which versions, which held-out sets, where results go."""

    id: str = "evaluator"
    """evaluator id (key eval/<id>, token alive/evaluator/<id>)"""
    model: str = "nnql"
    """model whose weights are evaluated (weights/<model>)"""
    families: tuple[str, ...] = ("unseen", "dynamic")
    """evaluation sets (agents.evaluation): unseen (held-out generated maps), dynamic (the same with
    moving discs), movingai (the arena map's scenarios)"""
    maps: str = ""
    """map files evaluated beside --families, as a map spec (a map_server .yaml, a MovingAI .map, an
    ASCII map, a directory, with key=value options; worlds.tasks): their scenarios or pairs drawn
    from --eval-seed, never the training pool's; empty: none"""
    episodes: int = 50
    """episodes per family (the same fixed, seeded tasks for every version)"""
    eval_seed: int = 0
    """seed of the evaluation sets (never overlaps training maps): 0 the test episodes, 1 the validation
    ones (agents.evaluation.selection), which --best-policy should choose by"""
    observation: str = observation_field()
    """what the evaluated robots observe (worlds.config.OBSERVATIONS): the learner's and actors'"""
    every_versions: int = 0
    """evaluate a version only if it is at least this many updates past the last one evaluated
    (0: any newer version)"""
    out: str = "runs/default/eval"
    """directory for evaluations.jsonl and learning_curve.png"""
    tensorboard: str = ""
    """directory for TensorBoard scalars (eval/<family>/success, spl, path_ratio); empty: none"""
    launched: float = 0.0
    """Unix time the run was launched, time zero of the learning curve (navlearn up sets it); 0: when
    this evaluator starts. Each launch of a resumed run starts a new segment of the curve"""
    max_evals: int = 0
    """stop after this many evaluations (0: run until stopped)"""
    compare: tuple[str, ...] = ()
    """more models evaluated beside --model on the same sets (e.g. nirl): each follows weights/<name>"""
    imitation: str = ""
    """a saved imitation policy directory (navlearn imitate train), evaluated once as a reference"""
    best_policy: str = ""
    """keep-best: a directory where the best-evaluated version of --model is saved as a policy, replaced
    each time a version scores at least as well (success, then SPL; on a Gymnasium env success where it
    says one, else mean return); `navlearn up` makes it the run's policy. Empty: none"""
