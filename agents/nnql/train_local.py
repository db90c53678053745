"""`navlearn train --local`: NNQL in one process - a vector env, the rollout, the learner.

The same classes the distributed services use (``VectorRollout`` on the actor side,
``NNQLLearner`` on the learner side), wired in-process: every step of N robots goes
into the replay buffer, the update-to-data ratio decides how many updates follow, and
the behaviour policy takes the new weights and exploration right away (no policy lag).
It is also the baseline of the learner overhead benchmark (``TrainResult`` rates).
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from agents.evaluation.env_returns import evaluate_env
from agents.evaluation.env_returns import table as env_table
from agents.evaluation.runner import EvalResult, evaluate, make_eval_set
from agents.evaluation.selection import TEST_SEED, VALIDATION_SEED, score
from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.policy import NNQLPolicy
from agents.nnql.ratelimit import RateLimiter
from agents.nnql.rollout import EpisodeEnd, VectorRollout
from agents.nnql.train_config import LocalTrainConfig
from worlds.config import LEARNING_NAV, NavConfig, observation_settings, with_moving_discs
from worlds.own_env import EnvConfig, describe_env, make_vector_env
from worlds.vector_env import NavigationVectorEnv

CURVE_EVERY = 2_000
"""robot-steps between learning-curve points"""


@dataclass
class TrainResult:
    """What a run produced: rates for the overhead benchmark, curve points, final evaluation."""

    env_steps: int
    updates: int
    wall_time: float
    env_steps_per_s: float
    updates_per_s: float
    update_time: float
    """seconds spent inside learner updates (sample + loss + step)"""
    curve: list[dict[str, float]] = field(default_factory=list)
    selected_version: int | None = None
    """policy version (updates) of the saved weights when keep_best chose them"""
    final_eval: dict[str, Any] | None = None
    """FamilyMetrics.to_dict() of the final greedy evaluation of the saved weights (test set, seed 0)"""
    final_table: str = ""
    out: str | None = None
    learner: NNQLLearner | None = field(default=None, repr=False)
    """the trained learner (not serialised)"""
    policy: NNQLPolicy | None = field(default=None, repr=False)
    """the policy with the saved weights (keep_best's choice, else the last; not serialised)"""

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("learner", "policy")}


def evaluate_policy(
    policy: NNQLPolicy,
    episodes: int,
    seed: int,
    nav: NavConfig | None = None,
    dynamic: int = 0,
    sizes: tuple[int, ...] = (16,),
) -> EvalResult:
    """Greedy evaluation on the shared held-out "unseen" set (agents.evaluation) at each of ``sizes``
    (the first named "unseen", the others "unseen@N"), plus ``dynamic`` episodes of its "dynamic" set
    (the first size) when positive -> EvalResult."""
    sets = [_sized(make_eval_set("unseen", episodes, seed=seed, size=n), k, n) for k, n in enumerate(sizes)]
    if dynamic > 0:
        sets.append(make_eval_set("dynamic", dynamic, seed=seed, size=sizes[0]))
    return evaluate(policy.greedy(), sets, config=nav)


def _sized(eval_set, k: int, size: int):
    return eval_set if k == 0 else replace(eval_set, family=f"{eval_set.family}@{size}")


def unseen_success(report: EvalResult) -> float:
    """The mean success over the "unseen" sets of every size in ``report``."""
    names = [name for name in report.metrics if name.split("@")[0] == "unseen"]
    return float(np.mean([report.metrics[name].success.value for name in names]))


def training_nav(run: LocalTrainConfig, nav: NavConfig | None = None) -> NavConfig:
    """The task trained on: ``nav`` (default :data:`worlds.config.LEARNING_NAV`) with the disc mix of
    ``run.moving_discs`` (default 0..6), a given ``nav`` included (`train --local` passes its observation
    flags' nav); a caller that wants ``nav`` as it is sets ``moving_discs=0``."""
    return with_moving_discs(nav or LEARNING_NAV, run.moving_discs)


Reward = Callable[[dict[str, np.ndarray]], np.ndarray]
"""a learned reward: a transition batch (``VectorRollout.step``'s fields) -> (N,) float32 rewards"""


def train_local(
    run: LocalTrainConfig,
    nnql: NNQLConfig | None = None,
    nav: NavConfig | None = None,
    reward: Reward | None = None,
    initial_weights: dict[str, np.ndarray] | None = None,
    env_config: EnvConfig | None = None,
) -> TrainResult:
    """Train NNQL for ``run.steps`` robot-steps in ``nav`` (default :data:`worlds.config.LEARNING_NAV`)
    with ``run.moving_discs`` applied to it; writes the outputs to ``run.out`` if set. ``reward``
    (NIRL's fixed learned reward, agents.nirl.policy_iteration) replaces the environment's reward in
    every batch before it reaches the replay; the env's reward then only feeds the logged returns.
    ``initial_weights`` (plain layout, ``networks.export_weights``) start the Q-network and its target
    instead of a fresh initialisation (NIRL's warm-started phase). ``env_config``: a Gymnasium env
    (worlds.own_env) instead of navlearn's world; validation and the final test are then its seeded
    episodes (agents.evaluation.env_returns), scored by success where it says one, else mean return."""
    nnql = nnql or NNQLConfig(seed=run.seed)
    nav = training_nav(run, nav)
    gym_env = env_config if env_config is not None and not env_config.own_world else None
    if gym_env is None:
        env = NavigationVectorEnv(run.envs, config=nav, maps=run.maps, seed=run.seed)
        observation = observation_settings(nav)
    else:
        env = make_vector_env(gym_env, run.envs)
        observation = None
    image = None if gym_env is None else describe_env(gym_env).image  # network auto: a CNN for an image
    obs_dim = int(np.prod(env.single_observation_space.shape))
    n_actions = int(env.single_action_space.n)
    learner = NNQLLearner(nnql, obs_dim, n_actions, device=run.device, observation=observation, image=image)
    nnql = learner.config  # network "auto" resolved: what the outputs record
    learner.env = None if gym_env is None else gym_env.record()
    if initial_weights is not None:
        learner.set_weights(initial_weights)
    policy = learner.policy(seed=run.seed)
    policy.explore_as(nnql, learner.version)
    rollout = VectorRollout(env, policy, with_next_action=nnql.sarsa)
    rollout.reset(seed=run.seed)
    # The learner service's rate logic, with no slack: one update per 1 / utd_ratio transitions once
    # the replay holds learning_starts (and a batch).
    limiter = RateLimiter(nnql.utd_ratio, max(nnql.learning_starts, nnql.batch_size), tolerance=1.0)
    env_ids = np.arange(run.envs, dtype=np.int32)  # the streams of n-step returns

    recent: deque[EpisodeEnd] = deque(maxlen=200)
    curve: list[dict[str, float]] = []
    metrics: dict[str, float] = {}
    update_time = 0.0
    next_point, next_eval = 0, run.eval_every if run.eval_every > 0 else run.steps + 1
    best: Candidate | None = None
    bar = _progress_bar(run)
    # the numpy policy's small matrix products on one BLAS thread (why: agents/evaluation/runner.py)
    blas = threadpool_limits(limits=1, user_api="blas")
    start = last_postfix = time.perf_counter()
    while rollout.steps < run.steps:
        batch, ended = rollout.step()
        if reward is not None:
            batch["reward"] = reward(batch)
        recent.extend(ended)
        limiter.inserted(learner.add({**batch, "env_ids": env_ids}))
        due = limiter.updates_allowed(len(learner.replay))
        if due:
            t0 = time.perf_counter()
            metrics = learner.update(due)
            limiter.updated(due)
            update_time += time.perf_counter() - t0
            policy.set_weights(learner.get_weights(), learner.version)
            policy.explore_as(nnql, learner.version)
        now = time.perf_counter()
        if rollout.steps >= next_point or rollout.steps >= run.steps:
            curve.append(_curve_point(rollout.steps, now - start, learner, recent, policy, metrics))
            next_point += CURVE_EVERY
        if next_eval <= rollout.steps < run.steps:
            if curve[-1]["env_steps"] != rollout.steps:
                curve.append(_curve_point(rollout.steps, now - start, learner, recent, policy, metrics))
            best = _validate(policy, run, nav, curve[-1], best, gym_env)
            next_eval += run.eval_every
        if bar is not None:
            bar.update(rollout.num_envs)
            if now - last_postfix > 1.0:
                bar.set_postfix_str(_postfix(curve[-1], learner.updates, update_time), refresh=False)
                last_postfix = now
    wall = time.perf_counter() - start
    blas.restore_original_limits()
    if bar is not None:
        bar.close()
    env.close()

    result = TrainResult(
        env_steps=rollout.steps,
        updates=learner.updates,
        wall_time=wall,
        env_steps_per_s=rollout.steps / wall,
        updates_per_s=learner.updates / update_time if update_time else 0.0,
        update_time=update_time,
        curve=curve,
        learner=learner,
        policy=policy,
    )
    if best is not None:  # keep_best: the final weights compete with the periodic ones
        best = _validate(policy, run, nav, curve[-1], best, gym_env)
        policy.set_weights(best.weights, best.version)
        result.selected_version = best.version
    if run.final_eval_episodes > 0 and gym_env is not None:
        tested = evaluate_env(policy.greedy(), gym_env, run.final_eval_episodes, seed=TEST_SEED)
        result.final_eval, result.final_table = tested[gym_env.env], env_table(tested)
    elif run.final_eval_episodes > 0:
        report = evaluate_policy(policy, run.final_eval_episodes, TEST_SEED, nav, sizes=run.eval_sizes)
        result.final_eval = report.to_dict(with_episodes=False)["metrics"]["unseen"]
        result.final_table = report.table()
    if run.out:
        result.out = str(write_outputs(Path(run.out), policy, result, run, nnql, nav))
    return result


@dataclass
class Candidate:
    """Weights scored on the validation set; the best one is what keep_best saves."""

    score: tuple[float, float]
    version: int
    weights: dict[str, np.ndarray]

    @staticmethod
    def better(best: Candidate | None, score: tuple[float, float], version: int, weights) -> Candidate:
        """keep_best's rule: ``best`` or the new weights (``weights()`` copies them) scored ``score``,
        whichever scores higher; ties go to the new, later weights."""
        if best is None or score >= best.score:
            return Candidate(score, version, weights())
        return best


def _validate(
    policy: NNQLPolicy,
    run: LocalTrainConfig,
    nav: NavConfig,
    point: dict[str, float],
    best: Candidate | None,
    gym_env: EnvConfig | None = None,
):
    """Evaluate on the validation set (a Gymnasium env's validation-seed episodes), note it on the curve
    point, return the better candidate."""
    if gym_env is not None:
        m = evaluate_env(policy.greedy(), gym_env, run.eval_episodes, seed=VALIDATION_SEED)[gym_env.env]
        point["eval_return"] = m["return"]["mean"]
        if "success" in m:
            point["eval_success"] = m["success"]["value"]
        kept = score({gym_env.env: m})
        return Candidate.better(best, kept, policy.version, policy.get_weights) if run.keep_best else None
    report = evaluate_policy(
        policy, run.eval_episodes, VALIDATION_SEED, nav, run.eval_dynamic_episodes, run.eval_sizes
    )
    metrics = report.metrics["unseen"]
    point["eval_success"] = unseen_success(report)
    for name, sized in report.metrics.items():
        if name.startswith("unseen@"):
            point[f"eval_success@{name.split('@')[1]}"] = sized.success.value
    solved, episodes = point["eval_success"] * run.eval_episodes, run.eval_episodes
    if run.eval_dynamic_episodes > 0:
        point["eval_dynamic_success"] = report.metrics["dynamic"].success.value
        solved += point["eval_dynamic_success"] * run.eval_dynamic_episodes
        episodes += run.eval_dynamic_episodes
    kept = (solved / episodes, metrics.spl)
    if not run.keep_best:
        return None
    return Candidate.better(best, kept, policy.version, policy.get_weights)


def _curve_point(steps, wall, learner, recent, policy, metrics) -> dict[str, float]:
    point = {
        "env_steps": float(steps),
        "wall_time": float(wall),
        "updates": float(learner.updates),
        "train_success": float(np.mean([e.solved for e in recent])) if recent else 0.0,
        "episode_return": float(np.mean([e.episode_return for e in recent])) if recent else 0.0,
        "temperature": policy.temperature,
        "epsilon": policy.epsilon,
    }
    point.update({k: v for k, v in metrics.items() if k.startswith("losses/")})
    return point


def _progress_bar(run: LocalTrainConfig):
    if not run.progress:
        return None
    from tqdm import tqdm

    return tqdm(total=run.steps, unit="step", unit_scale=True, desc="nnql", dynamic_ncols=True)


def _postfix(point: dict[str, float], updates: int, update_time: float) -> str:
    ups = updates / update_time if update_time else 0.0
    text = f"updates {updates} ({ups:.0f}/s) success {point['train_success']:.0%}"
    text += f" T {point['temperature']:.3f}"
    if "eval_success" in point:
        text += f" eval {point['eval_success']:.0%}"
    return text


def write_outputs(
    out: Path, policy: NNQLPolicy, result: TrainResult, run, nnql: NNQLConfig, nav: NavConfig
) -> Path:
    """Policy files, the learning curve (JSON lines + PNG) and a summary in ``out`` (with the moving
    discs the env really had, ``obstacles``)."""
    out.mkdir(parents=True, exist_ok=True)
    env = None if result.learner is None else result.learner.env
    where = {"maps": run.maps} if env is None else {"env": env}  # a Gymnasium env: what evaluate rebuilds
    policy.save(out, nnql_config=nnql.to_dict(), env_steps=result.env_steps, **where)
    with open(out / "curve.jsonl", "w") as fh:
        for point in result.curve:
            fh.write(json.dumps(point) + "\n")
    summary = {"run": asdict(run), "nnql": nnql.to_dict(), "obstacles": asdict(nav.obstacles)}
    summary.update(result.to_dict())
    summary.pop("curve")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    plot_curve(result, out / "curve.png")
    return out


def plot_curve(result: TrainResult, path: Path) -> None:
    """Success (training episodes, validation evaluations, final test) and TD loss vs robot-steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    curve = result.curve
    steps = [p["env_steps"] for p in curve]
    fig, (ax_s, ax_l) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax_s.plot(steps, [p["train_success"] for p in curve], label="training episodes (last 200)")
    evals = [(p["env_steps"], p["eval_success"]) for p in curve if "eval_success" in p]
    if evals:
        ax_s.plot(*zip(*evals, strict=True), "o-", label=f"greedy, validation maps (seed {VALIDATION_SEED})")
    if result.final_eval and "success" in result.final_eval:
        saved = [p["env_steps"] for p in curve if p["updates"] == result.selected_version] or [steps[-1]]
        test = result.final_eval["success"]["value"]
        ax_s.plot(saved[:1], [test], "*", ms=12, label=f"saved policy, test maps (seed {TEST_SEED})")
    ax_s.set(xlabel="robot-steps", ylabel="success rate", ylim=(0, 1.02), title="NNQL success")
    ax_s.legend(loc="lower right")
    ax_s.grid(alpha=0.3)
    if any("losses/td_loss" in p for p in curve):
        ax_l.plot(steps, [p.get("losses/td_loss", np.nan) for p in curve])
        ax_l.set_yscale("log")
    ax_l.set(xlabel="robot-steps", ylabel="TD loss", title="learner")
    ax_l.grid(alpha=0.3)
    for ax in (ax_s, ax_l):
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:.0f}k"))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
