"""The evaluator service: every new policy version measured on held-out maps, reported and plotted.

It follows ``weights/<model>`` like an actor (asking the learner's queryable for
the newest weights on start), runs the shared evaluation (agents.evaluation) on
fixed, seeded sets - unseen generated maps, the same with moving obstacles - with
the greedy policy, publishes an EvalReport on ``eval/<id>``, appends a JSON line
to ``evaluations.jsonl`` and redraws ``learning_curve.png`` (success and path
ratio to A* against policy version and wall time). Evaluation takes seconds, so
versions that arrive meanwhile are skipped: it always takes the newest.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import EvalReport
from services.common.process import Scalars, connect
from services.common.transport import ZenohSettings, declare_alive
from services.common.weights import WeightsReceiver, split_architecture
from services.evaluator.config import EvaluatorConfig

log = logging.getLogger("navlearn.evaluator")
CURVE_FILE = "learning_curve.png"
LINES_FILE = "evaluations.jsonl"
REFERENCE = "reference"
"""model field of points that evaluate a fixed saved policy (the imitation policy) once"""


def summary_scalars(metrics: dict[str, Any]) -> dict[str, float]:
    """TensorBoard scalars from EvalResult.to_dict()["metrics"]: eval/<family>/<figure>."""
    scalars = {}
    for family, m in metrics.items():
        for name in ("success", "collision_static", "collision_dynamic", "timeout"):
            if isinstance(m.get(name), dict):
                scalars[f"eval/{family}/{name}"] = m[name]["value"]
        for name in ("spl", "path_ratio", "time_to_goal", "min_clearance_mean"):
            if m.get(name) is not None:
                scalars[f"eval/{family}/{name}"] = m[name]
    return scalars


def plot_curve(points: list[dict[str, Any]], path: Path) -> Path:
    """Success rate (95% band) and path ratio to A* per family, against policy version and wall time."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    start = min(p["time"] for p in points)
    families = sorted({f for p in points for f in p["metrics"]})
    models = sorted({p.get("model", "") for p in points if p.get("model") != REFERENCE})
    series = [(m, f) for m in models for f in families]
    references = [p for p in points if p.get("model") == REFERENCE]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.4), sharey="row")
    for col, (xlabel, xof) in enumerate(
        (
            ("policy version (updates)", lambda p: p["policy_version"]),
            ("wall time (min)", lambda p: (p["time"] - start) / 60),
        )
    ):
        for model, family in series:
            rows = sorted(
                (xof(p), p["metrics"][family])
                for p in points
                if family in p["metrics"] and p.get("model", "") == model
            )
            if not rows:
                continue
            label = f"{model} {family}".strip() if len(models) > 1 else family
            xs = [x for x, _ in rows]
            success = [m["success"] for _, m in rows]
            (line,) = axes[0, col].plot(xs, [s["value"] for s in success], "o-", ms=3, label=label)
            axes[0, col].fill_between(
                xs,
                [s["low"] for s in success],
                [s["high"] for s in success],
                color=line.get_color(),
                alpha=0.2,
            )
            ratio = [(x, m["path_ratio"]) for x, m in rows if m.get("path_ratio") is not None]
            if ratio:
                axes[1, col].plot(*zip(*ratio, strict=True), "o-", ms=3, color=line.get_color(), label=label)
        for reference in references:  # a fixed policy (imitation): one horizontal line per family
            for family, metrics in reference["metrics"].items():
                label = f"{reference.get('name', REFERENCE)} {family}"
                axes[0, col].axhline(metrics["success"]["value"], ls="--", lw=1, color="gray", label=label)
                if metrics.get("path_ratio") is not None:
                    axes[1, col].axhline(metrics["path_ratio"], ls="--", lw=1, color="gray")
        axes[0, col].set(ylim=(0, 1.02), ylabel="success rate" if col == 0 else None)
        axes[1, col].set(xlabel=xlabel, ylabel="path length / A*" if col == 0 else None)
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle(f"{', '.join(models).upper() or 'policies'} on held-out maps (greedy policy)")
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(path)
    return path


class Evaluator:
    """Takes the newest weights, evaluates them, reports, records and plots."""

    def __init__(self, config: EvaluatorConfig, session, run: str, eval_sets: list, limits: Limits) -> None:
        self.config = config
        self.session = session
        self.run_name = run
        self.eval_sets = eval_sets
        self.receiver = WeightsReceiver(session, run, config.model, limits)
        self.receivers = {config.model: self.receiver}
        for model in config.compare:
            if model not in self.receivers:
                self.receivers[model] = WeightsReceiver(session, run, model, limits)
        self.lasts: dict[str, tuple[str, int]] = {}  # model -> (learner sender, version) last evaluated
        self.key = keys.evaluation(run, config.id)
        self.out = Path(config.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.points = self._load_points()
        self.scalars = Scalars(config.tensorboard)
        self.seq = 0
        self.last: tuple[str, int] | None = None  # (learner sender, version) last evaluated

    def _load_points(self) -> list[dict[str, Any]]:
        path = self.out / LINES_FILE
        if not path.exists():
            return []
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]

    def due(self, sender: str, version: int, model: str | None = None) -> bool:
        last = self.last if model is None else self.lasts.get(model)
        if last is None or last[0] != sender:
            return True
        return version > last[1] and version - last[1] >= self.config.every_versions

    def evaluate(self, weights: dict, architecture: dict, version: int) -> dict[str, Any]:
        from agents.evaluation import evaluate
        from agents.nnql.policy import NNQLPolicy

        network, _exploration = split_architecture(architecture)
        policy = NNQLPolicy(weights, network, mode="greedy", version=version)
        start = time.perf_counter()
        result = evaluate(policy, self.eval_sets)
        metrics = result.to_dict(with_episodes=False)["metrics"]
        log.info("version %d evaluated in %.1f s\n%s", version, time.perf_counter() - start, result.table())
        return metrics

    def report(self, sender: str, version: int, metrics: dict[str, Any], model: str | None = None) -> None:
        model = model or self.config.model
        self.seq += 1
        message = EvalReport(
            sender=self.config.id,
            seq=self.seq,
            model=model,
            policy_version=version,
            metrics=metrics,
        )
        self.session.put(self.key, encode(message))
        point = {
            "policy_version": version,
            "time": time.time(),
            "learner": sender,
            "model": model,
            "metrics": metrics,
        }
        self.points.append(point)
        with open(self.out / LINES_FILE, "a") as fh:
            fh.write(json.dumps(point) + "\n")
        plot_curve(self.points, self.out / CURVE_FILE)
        prefix = "" if model == self.config.model else f"{model}/"
        self.scalars.add({prefix + k: v for k, v in summary_scalars(metrics).items()}, version)

    def evaluate_reference(self, path: str) -> None:
        """Evaluate a saved policy (the imitation one) once; it is drawn as a horizontal line."""
        from agents.evaluation import evaluate
        from agents.evaluation.policies import load_policy

        policy = load_policy(path)
        result = evaluate(policy, self.eval_sets)
        log.info("reference policy %s evaluated\n%s", path, result.table())
        metrics = result.to_dict(with_episodes=False)["metrics"]
        point = {"policy_version": policy.version, "time": time.time(), "learner": "", "model": REFERENCE,
                 "name": policy.model or Path(path).name, "metrics": metrics}  # fmt: skip
        self.points = [p for p in self.points if p.get("model") != REFERENCE] + [point]
        with open(self.out / LINES_FILE, "a") as fh:
            fh.write(json.dumps(point) + "\n")

    def run(self, stop: threading.Event) -> int:
        if self.config.imitation:
            self.evaluate_reference(self.config.imitation)
        for receiver in self.receivers.values():
            receiver.request_latest()
        done = 0
        while not stop.is_set() and not (self.config.max_evals and done >= self.config.max_evals):
            idle = True
            for model, receiver in self.receivers.items():
                received = receiver.take()
                if received is None:
                    continue
                idle = False
                message = received.message
                if not self.due(message.sender, message.version, model):
                    continue
                metrics = self.evaluate(message.tensors, message.architecture, message.version)
                self.lasts[model] = (message.sender, message.version)
                if model == self.config.model:
                    self.last = self.lasts[model]
                self.report(message.sender, message.version, metrics, model)
                done += 1
            if idle:
                stop.wait(0.2)
        return 0

    def close(self) -> None:
        for receiver in self.receivers.values():
            receiver.close()
        self.scalars.close()


def run_evaluator(config: EvaluatorConfig, settings: ZenohSettings, stop: threading.Event) -> int:
    """Process set-up: the fixed evaluation sets, the Zenoh session, the loop."""
    from agents.evaluation import make_eval_set
    from worlds.config import NavConfig

    start = time.perf_counter()
    eval_sets = [make_eval_set(family, config.episodes, seed=config.eval_seed) for family in config.families]
    log.info("evaluation sets %s ready in %.1f s", ", ".join(config.families), time.perf_counter() - start)
    session = connect(settings, stop)
    if session is None:
        return 0
    evaluator = Evaluator(
        config, session, settings.run, eval_sets, Limits(n_actions=NavConfig().robot.n_actions)
    )
    token = declare_alive(session, settings.run, "evaluator", config.id)
    log.info("evaluator %s up: %d episodes per family, run %s", config.id, config.episodes, settings.run)
    try:
        return evaluator.run(stop)
    finally:
        token.undeclare()
        evaluator.close()
        session.close()
        log.info("evaluator stopped")
