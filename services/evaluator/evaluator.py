"""The evaluator service: every new policy version measured on held-out maps, reported and plotted.

It follows ``weights/<model>`` like an actor (asking the learner's queryable for
the newest weights on start), runs the shared evaluation (agents.evaluation) on
fixed, seeded sets - unseen generated maps, the same with moving obstacles - with
the greedy policy, publishes an EvalReport on ``eval/<id>``, appends a JSON line
to ``evaluations.jsonl`` and redraws ``learning_curve.png`` (success and path
ratio to A* against policy version and wall time since the run's first launch; a
resumed run starts a new segment, marked, with no line across the gap). Evaluation takes seconds, so
versions that arrive meanwhile are skipped: it always takes the newest.
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

from agents.evaluation import evaluate, make_eval_set, make_map_eval_set
from agents.evaluation.env_returns import evaluate_env, table
from agents.evaluation.plots import REFERENCE, plot_evaluations
from agents.evaluation.policies import load_policy
from agents.nnql.policy import NNQLPolicy
from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import EvalReport
from services.common.process import Scalars
from services.common.transport import ZenohSettings, declare_alive, open_session
from services.common.waiting import WaitLog
from services.common.warmup import COMPILE_NOTE
from services.common.weights import WeightsReceiver
from services.evaluator.config import EvaluatorConfig
from services.evaluator.keep_best import KeepBest
from worlds.config import OBSERVATIONS, NavConfig
from worlds.own_env import EnvConfig, env_spaces

log = logging.getLogger("navlearn.evaluator")
CURVE_FILE = "learning_curve.png"
LINES_FILE = "evaluations.jsonl"


def summary_scalars(metrics: dict[str, Any]) -> dict[str, float]:
    """TensorBoard scalars from EvalResult.to_dict()["metrics"]: eval/<family>/<figure>."""
    scalars = {}
    for family, m in metrics.items():
        if isinstance(m.get("return"), dict):  # a Gymnasium --env (agents.evaluation.env_returns)
            scalars[f"eval/{family}/return"] = m["return"]["mean"]
            scalars[f"eval/{family}/length"] = m["length"]
        for name in ("success", "collision_static", "collision_dynamic", "timeout"):
            if isinstance(m.get(name), dict):
                scalars[f"eval/{family}/{name}"] = m[name]["value"]
        for name in ("spl", "path_ratio", "time_to_goal", "min_clearance_mean"):
            if m.get(name) is not None:
                scalars[f"eval/{family}/{name}"] = m[name]
    return scalars


class Evaluator:
    """Takes the newest weights, evaluates them, reports, records and plots."""

    def __init__(
        self,
        config: EvaluatorConfig,
        session,
        run: str,
        eval_sets: list,
        limits: Limits,
        where: str = "",
        env: EnvConfig | None = None,
    ) -> None:
        """``where``: the router endpoints, named while waiting for the first weights; ``env``: a
        Gymnasium env evaluated instead of navlearn's held-out maps (``eval_sets`` then unused)."""
        self.config = config
        self.env = env or EnvConfig()
        observation = config.observation if self.env.own_world else None
        self.nav = OBSERVATIONS[config.observation]
        self.session = session
        self.run_name = run
        self.eval_sets = eval_sets
        self.receiver = WeightsReceiver(session, run, config.model, limits, observation, self.env.signature())
        self.receivers = {config.model: self.receiver}
        self.first_weights = WaitLog(
            log,
            "waiting for the first weights of %s from the learner on run %r via %s (%.0f s so far)",
            config.model,
            run,
            where,
        )
        for model in config.compare:
            if model not in self.receivers:
                self.receivers[model] = WeightsReceiver(
                    session, run, model, limits, observation, self.env.signature()
                )
        self.lasts: dict[str, tuple[str, int]] = {}  # model -> (learner sender, version) last evaluated
        self.key = keys.evaluation(run, config.id)
        self.out = Path(config.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.points = self._load_points()
        self.scalars = Scalars(config.tensorboard)
        self.seq = 0
        self.last: tuple[str, int] | None = None  # (learner sender, version) last evaluated
        self.launch = config.launched or time.time()
        """time zero of this launch's segment of the learning curve"""
        self.keep_best = (
            KeepBest(config.best_policy, config.eval_seed, self.env.record()) if config.best_policy else None
        )
        """the best-evaluated version of --model, saved (None without --best-policy)"""

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
        policy = NNQLPolicy(weights, architecture, mode="greedy", version=version)
        start = time.perf_counter()
        if not self.env.own_world:
            metrics = evaluate_env(policy, self.env, self.config.episodes, seed=self.config.eval_seed)
            seconds = time.perf_counter() - start
            log.info("version %d evaluated in %.1f s: %s", version, seconds, table(metrics))
            return metrics
        result = evaluate(policy, self.eval_sets, config=self.nav)  # what the actors observe
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
            "launch": self.launch,
            "learner": sender,
            "model": model,
            "metrics": metrics,
        }
        self.points.append(point)
        with open(self.out / LINES_FILE, "a") as fh:
            fh.write(json.dumps(point) + "\n")
        plot_evaluations(self.points, self.out / CURVE_FILE)
        prefix = "" if model == self.config.model else f"{model}/"
        self.scalars.add({prefix + k: v for k, v in summary_scalars(metrics).items()}, version)

    def evaluate_reference(self, path: str) -> None:
        """Evaluate a saved policy (the imitation one) once; it is drawn as a horizontal line."""
        policy = load_policy(path)
        result = evaluate(policy, self.eval_sets)
        log.info("reference policy %s evaluated\n%s", path, result.table())
        metrics = result.to_dict(with_episodes=False)["metrics"]
        point = {"policy_version": policy.version, "time": time.time(), "launch": self.launch,
                 "learner": "", "model": REFERENCE,
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
                if model == self.config.model and self.keep_best is not None:
                    self.keep_best.offer(message, metrics)  # before the report `up` waits for
                self.report(message.sender, message.version, metrics, model)
                done += 1
            if idle:
                if self.last is None:
                    self.first_weights.tick()
                stop.wait(0.2)
        return 0

    def close(self) -> None:
        for receiver in self.receivers.values():
            receiver.close()
        self.scalars.close()


def run_evaluator(
    config: EvaluatorConfig, settings: ZenohSettings, stop: threading.Event, env: EnvConfig | None = None
) -> int:
    """Process set-up: the fixed evaluation sets (or a Gymnasium ``env``'s seeded episodes), the Zenoh
    session, the loop."""
    env = env or EnvConfig()
    if env.own_world:
        start = time.perf_counter()
        log.info("evaluator %s: building the evaluation sets (%s)", config.id, COMPILE_NOTE)
        eval_sets = [make_eval_set(f, config.episodes, seed=config.eval_seed) for f in config.families]
        if config.maps:
            eval_sets.append(make_map_eval_set(config.maps, config.episodes, seed=config.eval_seed))
        seconds = time.perf_counter() - start
        log.info("evaluation sets %s ready in %.1f s", ", ".join(s.family for s in eval_sets), seconds)
        limits = Limits(n_actions=NavConfig().robot.n_actions)
    else:
        if config.imitation:
            raise ValueError(f"--imitation is a policy of navlearn's world; with --env {env.env} drop it")
        eval_sets = []
        obs_dim, n_actions = env_spaces(env)
        limits = Limits(n_actions=n_actions, max_obs_dim=max(obs_dim, Limits.max_obs_dim))
        what = env.signature()
        log.info("evaluator %s: %d greedy episodes of %s per version", config.id, config.episodes, what)
    session = open_session(settings, stop=stop)
    if session is None:
        return 0
    where = settings.where()
    with (
        session,
        contextlib.closing(
            Evaluator(config, session, settings.run, eval_sets, limits, where, env)
        ) as evaluator,
        declare_alive(session, settings.run, "evaluator", config.id),
    ):
        log.info(
            "evaluator %s up: %d episodes per family, run %s via %s",
            config.id,
            config.episodes,
            settings.run,
            where,
        )
        code = evaluator.run(stop)
    log.info("evaluator stopped")
    return code
