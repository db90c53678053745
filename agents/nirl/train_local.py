"""`navlearn nirl train`: NIRL in one process - demonstrations, a vector env, the learner.

Neural policy iteration, each round:
1. collect ``steps_per_iteration`` robot-steps with the current stochastic policy
   (softmax over Q, temperature decaying by iteration) into the experience replay;
2. ``NIRLLearner.iterate()``: soft policy evaluation under the reward the Q-function holds
   (IQ-Learn on 50/50 batches of MAP-refined demonstrations and own experience; or the
   configured core), then the reward network's fit;
3. the policy takes the new Q-network (policy improvement: softmax over Q), and the weights
   of both networks are recorded (iteration 0 of the history is the warm-started pair).
The environment's own reward is never used for learning; the greedy policy is evaluated
on held-out maps to draw the learning curve. With ``NIRLRun.tensorboard`` every iteration's
losses and the learned reward's scale (``nirl/learned_reward`` per demonstrated step,
``nirl/path_return`` over a demonstrated path of ``nirl/path_length`` steps,
``nirl/collision_value``) go to TensorBoard.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.runner import EvalResult, Policy, evaluate, make_eval_set
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.learner import NIRLLearner
from agents.nirl.losses import KEEP, RELABEL, REWEIGHT, Refinement
from agents.nirl.policy_iteration import policy_iteration
from agents.nirl.progress import ProgressPotential
from agents.nirl.refine_progress import refine_after_policy_iteration
from agents.nirl.weights import HISTORY_FILE, WeightHistory, plot_weight_changes
from agents.nnql.rollout import EpisodeEnd, VectorRollout
from agents.nnql.train_local import Candidate, TrainResult
from worlds.config import LEARNING_NAV, NavConfig, with_moving_discs
from worlds.vector_env import NavigationVectorEnv

VALIDATION_SEED = 1
"""periodic evaluations use the held-out set of this seed; the final one uses seed 0, the reported set"""


@dataclass
class NIRLResult:
    """What a run produced: the learner, its learning curve and final evaluation."""

    learner: NIRLLearner
    history: WeightHistory
    env_steps: int = 0
    wall_time: float = 0.0
    curve: list[dict[str, float]] = field(default_factory=list)
    final_eval: dict[str, Any] | None = None
    final_table: str = ""
    iq_steps: int = 0
    """robot-steps of the IQ-Learn rounds (all of them when there is no NNQL phase)"""
    policy_result: TrainResult | None = None
    """NIRLConfig.policy_steps > 0: NNQL's local trainer on the fixed learned reward (its policy is NIRL's)"""
    refinement: Refinement | None = None
    """... and ``refine``: MAP refinement of the demonstrations under that policy's prior and the progress
    evidence (agents.nirl.refine_progress), in the demonstration buffer's order"""
    refined_potential: ProgressPotential | None = None
    """the progress potential re-fitted on the refined demonstrations' steps to go"""
    demo_refinement: dict[str, Any] = field(default_factory=dict)
    """what the learner's own MAP refinement made of the demonstrations at the end (``refinement_summary``)"""
    selected_iteration: int | None = None
    """NIRLRun.keep_best: the own round whose Q-network the learner now holds (the best validated)"""
    averaged_rounds: int = 0
    """NIRLRun.average_last: how many own rounds at the end the learner's Q-network now averages"""

    def policy(self) -> Policy:
        """NIRL's final policy: the NNQL phase's kept one, else the learner's Q-network (greedy)."""
        if self.policy_result is not None:
            return self.policy_result.policy.greedy()
        return self.learner.policy()


def evaluate_greedy(
    learner: NIRLLearner, episodes: int, seed: int, nav: NavConfig | None = None
) -> EvalResult:
    """Greedy policy on the shared held-out "unseen" set -> agents.evaluation EvalResult."""
    return evaluate_policy(learner.policy(), episodes, seed, nav)


def evaluate_policy(policy: Policy, episodes: int, seed: int, nav: NavConfig | None = None) -> EvalResult:
    return evaluate(policy, make_eval_set("unseen", episodes, seed=seed), config=nav)


def train_nirl(
    demos: Sequence[Any],
    config: NIRLConfig | None = None,
    run: NIRLRun | None = None,
    nav: NavConfig | None = None,
    on_iteration: Callable[[dict[str, float], NIRLLearner], None] | None = None,
) -> NIRLResult:
    """Warm-start on ``demos`` (``agents.demos.Demo`` list, recorded in ``nav``'s observation,
    default :data:`worlds.config.LEARNING_NAV`), then ``config.iterations`` rounds of neural policy
    iteration (the learner on ``run.device``); with ``config.policy_steps`` only the IQ-Learn rounds
    (``fix_reward_after``), then NNQL's trainer on the fixed reward (agents.nirl.policy_iteration).
    ``on_iteration(point, learner)`` sees each round's curve point."""
    nav = nav or LEARNING_NAV
    config = config or NIRLConfig()
    run = run or NIRLRun()
    start = time.perf_counter()
    learner = NIRLLearner(config, nav, device=run.device)
    learner.add_demos(demos)
    learner.warm_start()
    history = WeightHistory()
    history.record(0, reward=learner.reward_weights(), policy=learner.get_weights())
    result = NIRLResult(learner, history)
    env = NavigationVectorEnv(
        run.envs, config=with_moving_discs(nav, run.moving_discs), maps=run.maps, seed=config.seed
    )
    policy = learner.policy(mode="boltzmann", temperature=config.temperature_at(0), seed=config.seed)
    rollout = VectorRollout(env, policy)
    rollout.reset(seed=config.seed)
    recent: deque[EpisodeEnd] = deque(maxlen=200)
    bar = _progress_bar(run, config)
    writer = _tensorboard(run)
    rounds = config.own_rounds()
    keep_best = run.keep_best and run.eval_every > 0 and not config.policy_steps
    best: Candidate | None = None
    for it in range(rounds):
        policy.set_weights(learner.get_weights(), learner.version)
        policy.temperature = config.temperature_at(it)
        collected = 0
        while collected < config.steps_per_iteration:
            batch, ended = rollout.step()
            learner.add_experience(batch)
            recent.extend(ended)
            collected += rollout.num_envs
        metrics = learner.iterate()
        history.record(learner.iteration, reward=learner.reward_weights(), policy=learner.get_weights())
        point = _curve_point(learner, rollout.steps, time.perf_counter() - start, recent, metrics)
        point["temperature"] = policy.temperature
        last = it + 1 == rounds and not config.policy_steps
        if keep_best and ((it + 1) % run.eval_every == 0 or last):  # the last round competes too
            kept, score = best, _validate(learner, run, nav, point)
            best = Candidate.better(best, score, learner.version, learner.get_weights)
            if best is not kept:
                result.selected_iteration = learner.iteration
        elif run.eval_every and (it + 1) % run.eval_every == 0 and not (last and run.final_eval_episodes):
            _validate(learner, run, nav, point)
        result.curve.append(point)
        if writer is not None:
            for name, value in point.items():
                if name.startswith(("losses/", "charts/", "nirl/")) or name.endswith("_success"):
                    writer.add_scalar(name, value, global_step=int(point["env_steps"]))
        if on_iteration is not None:
            on_iteration(point, learner)
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(_postfix(point))
    if bar is not None:
        bar.close()
    if writer is not None:
        writer.close()
    env.close()
    result.env_steps = result.iq_steps = rollout.steps
    averaged = 0 if config.policy_steps else run.averaged_rounds(rounds)
    if best is not None:  # keep_best: the learner (and so the saved policy) holds the best validated Q
        learner.q.set_weights(best.weights)
    elif averaged > 1:  # ... else the average of the last rounds' Q-networks
        result.averaged_rounds = averaged
        learner.q.set_weights(history.averaged("policy", averaged))
    if config.policy_steps:
        result.policy_result = policy_iteration(learner, config, run, nav)
        result.env_steps += result.policy_result.env_steps
        for point in result.policy_result.curve:
            result.curve.append(point | {"env_steps": point["env_steps"] + result.iq_steps, "phase": 1.0})
        if config.refine:
            q_values = result.policy_result.policy.q_values
            result.refinement, result.refined_potential = refine_after_policy_iteration(learner, q_values)
    if run.final_eval_episodes > 0:
        report = evaluate_policy(result.policy(), run.final_eval_episodes, 0, nav)
        result.final_eval = report.to_dict(with_episodes=False)["metrics"]["unseen"]
        result.final_table = report.table()
        if result.curve and "eval_success" not in result.curve[-1]:
            result.curve[-1]["eval_success"] = report.metrics["unseen"].success.value
    result.demo_refinement = refinement_summary(learner)
    result.wall_time = time.perf_counter() - start
    if run.out:
        write_outputs(Path(run.out), result, config, run)
    return result


def _validate(learner: NIRLLearner, run: NIRLRun, nav: NavConfig, point: dict) -> tuple[float, float]:
    """Evaluate the greedy Q-network on the validation set, note it on ``point``, return keep_best's
    score (success, then SPL)."""
    metrics = evaluate_greedy(learner, run.eval_episodes, VALIDATION_SEED, nav).metrics["unseen"]
    point["eval_success"], point["eval_spl"] = metrics.success.value, metrics.spl
    return metrics.success.value, metrics.spl


def _curve_point(learner, env_steps, wall, recent, metrics) -> dict[str, float]:
    point = {
        "iteration": float(learner.iteration),
        "env_steps": float(env_steps),
        "updates": float(learner.version),
        "wall_time": float(wall),
        "train_success": float(np.mean([e.solved for e in recent])) if recent else 0.0,
    }
    point.update({k: float(v) for k, v in metrics.items() if k.startswith(("losses/", "charts/", "nirl/"))})
    return point


def _tensorboard(run: NIRLRun):
    if not run.tensorboard:
        return None
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(run.tensorboard, flush_secs=10)


def _progress_bar(run: NIRLRun, config: NIRLConfig):
    if not run.progress:
        return None
    from tqdm import tqdm

    return tqdm(total=config.iterations, unit="iter", desc="nirl", dynamic_ncols=True)


def _postfix(point: dict[str, float]) -> str:
    text = (
        f"steps {point['env_steps']:.0f} train success {point['train_success']:.0%} "
        f"reward/step {point.get('nirl/learned_reward', float('nan')):.3f}"
    )
    if "charts/refine_relabel" in point:  # MAP refinement runs until the reward is fixed
        text += f" relabel {point['charts/refine_relabel']:.0%}"
    if "eval_success" in point:
        text += f" eval {point['eval_success']:.0%}"
    return text


def refinement_summary(learner: NIRLLearner) -> dict[str, Any]:
    """What MAP refinement made of the demonstrated steps at the end of a run: its prior (or off) and
    how many steps it kept, re-weighted and relabelled."""
    _, refined = learner.refine_all()
    decisions = refined.decisions
    config = learner.config
    return {
        "prior": config.refine_prior if config.refine else "off",
        "steps": len(decisions),
        "kept": int((decisions == KEEP).sum()),
        "reweighted": int((decisions == REWEIGHT).sum()),
        "relabelled": int((decisions == RELABEL).sum()),
    }


def write_outputs(out: Path, result: NIRLResult, config: NIRLConfig, run: NIRLRun) -> Path:
    """Policy files, weight history, learning curve and summary in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    kept = {} if result.selected_iteration is None else {"selected_iteration": result.selected_iteration}
    if result.averaged_rounds:
        kept["averaged_rounds"] = result.averaged_rounds
    result.learner.save_policy(out, env_steps=result.env_steps, maps=run.maps, **kept)
    result.history.save(out / HISTORY_FILE)
    with open(out / "curve.jsonl", "w") as fh:
        for point in result.curve:
            fh.write(json.dumps(point) + "\n")
    summary = {
        "run": asdict(run),
        "nirl": config.to_dict(),
        "env_steps": result.env_steps,
        "updates": result.learner.version,
        "iterations": result.learner.iteration,
        "demo_episodes": result.learner.demo_episodes,
        "demo_steps": len(result.learner.demos),
        "wall_time": result.wall_time,
        "final_eval": result.final_eval,
        "iq_steps": result.iq_steps,
        "selected_iteration": result.selected_iteration,
        "averaged_rounds": result.averaged_rounds,
        "policy_iteration": None if result.policy_result is None else result.policy_result.out,
        "refinement": result.demo_refinement,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if len(result.history) >= 2:
        plot_weight_changes(result.history, out / "weights.png")
    return out
