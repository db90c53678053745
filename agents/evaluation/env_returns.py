"""Evaluation on a user's Gymnasium env (``--env``): episode return, success where the env says it,
episode length.

navlearn's world has outcomes, A* paths and SPL (:mod:`agents.evaluation.runner`); a user's env has only
what Gymnasium defines, so this reports what the Gymnasium and SB3 literature does: the mean episode
return over a fixed number of greedy episodes with a 95% confidence interval (normal approximation,
``1.96 * std / sqrt(n)``) compared with the env's registered ``reward_threshold`` (gymnasium's
"solved"), the mean episode length, and the success rate (Wilson interval) from the terminal
``info["is_success"]`` where the env gives it (the gymnasium-robotics / SB3 convention). The episodes
are fixed by ``seed``: copy ``j`` of the vector env is reset with ``seed + j`` and runs episodes
``j, j + n, ...`` (each copy its own quota, so short episodes are not over-counted).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.evaluation.metrics import rate
from agents.nnql.rollout import VectorRollout
from worlds.own_env import EnvConfig, make_vector_env, reward_threshold

Z_95 = 1.959963984540054


def return_interval(returns: np.ndarray) -> dict[str, float]:
    """Mean of ``returns`` with its 95% confidence interval (normal approximation) and the std."""
    n = len(returns)
    mean = float(np.mean(returns)) if n else float("nan")
    std = float(np.std(returns, ddof=1)) if n > 1 else 0.0
    half = Z_95 * std / math.sqrt(n) if n else float("nan")
    return {"mean": mean, "low": mean - half, "high": mean + half, "std": std}


def summarize_episodes(
    returns: list[float], lengths: list[int], successes: list[bool | None], threshold: float | None
) -> dict[str, Any]:
    """The metrics map of one env (an EvalReport family): episodes, return, length, success (only when
    every episode said it), the reward threshold and whether the mean reached it."""
    values = np.asarray(returns, dtype=np.float64)
    metrics: dict[str, Any] = {
        "episodes": len(returns),
        "return": return_interval(values),
        "length": float(np.mean(lengths)) if lengths else float("nan"),
    }
    said = [s for s in successes if s is not None]
    if said and len(said) == len(successes):
        metrics["success"] = rate(int(sum(said)), len(said)).to_dict()
    if threshold is not None:
        metrics["reward_threshold"] = threshold
        metrics["solved"] = bool(metrics["return"]["mean"] >= threshold)
    return metrics


def evaluate_env(
    policy, config: EnvConfig, episodes: int, seed: int = 0, num_envs: int = 16
) -> dict[str, dict[str, Any]]:
    """Run ``policy`` (observations ``(N, obs_dim)`` -> actions) for ``episodes`` episodes of the env;
    returns ``{env id: metrics}`` (:func:`summarize_episodes`), the shape of navlearn's per-family
    metrics."""
    if episodes < 1:
        raise ValueError(f"episodes={episodes}: need at least 1")
    n = min(num_envs, episodes)
    quota = np.array([len(range(j, episodes, n)) for j in range(n)])
    done = np.zeros(n, dtype=np.int64)
    returns: list[float] = []
    lengths: list[int] = []
    successes: list[bool | None] = []
    env = make_vector_env(EnvConfig(**{**config.__dict__, "env_vector": "sync"}), n)
    try:
        rollout = VectorRollout(env, policy)
        rollout.reset(seed=seed)
        while (done < quota).any():
            _, ended = rollout.step()
            for episode in ended:
                j = episode.env_id
                if done[j] >= quota[j]:
                    continue
                done[j] += 1
                returns.append(episode.episode_return)
                lengths.append(episode.length)
                successes.append(episode.success)
    finally:
        env.close()
    return {config.env: summarize_episodes(returns, lengths, successes, reward_threshold(config))}


def table(metrics: dict[str, dict[str, Any]]) -> str:
    """One line per env: return mean [CI], length, success where known, solved where a threshold is."""
    lines = []
    for name, m in metrics.items():
        r = m["return"]
        line = f"{name}: return {r['mean']:.1f} [{r['low']:.1f}, {r['high']:.1f}]"
        line += f" over {m['episodes']} episodes"
        line += f", length {m['length']:.0f}"
        if "success" in m:
            s = m["success"]
            line += f", success {100 * s['value']:.0f}% [{100 * s['low']:.0f}, {100 * s['high']:.0f}]"
        if "reward_threshold" in m:
            line += f", threshold {m['reward_threshold']:g}: {'reached' if m['solved'] else 'not reached'}"
        lines.append(line)
    return "\n".join(lines)
