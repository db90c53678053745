"""The robot world's numba kernels, compiled once before the processes that use them start.

Every kernel is compiled with ``cache=True``: the first process on a machine (or the
first after worlds/ changed) compiles them - 1 to 2.5 minutes on a busy 2-core machine - and
writes numba's cache (``__pycache__`` beside the sources, or ``NUMBA_CACHE_DIR``); later
processes load it in about a second. ``navlearn up`` calls :func:`compile_world` before it
starts its processes, so they do not all compile at once while the training clock runs.
"""

from __future__ import annotations

import time

import numpy as np

COMPILE_NOTE = "a cold numba cache compiles the world first, a minute or more; later starts load it"


def compile_world(maps: str) -> tuple[float, bool]:
    """Step a small vector env on ``maps`` and evaluate one episode of each held-out family (the
    kernels of actors and the evaluator); returns (seconds taken, whether anything was compiled)."""
    from agents.evaluation import evaluate, make_eval_set
    from worlds.kernel import step_all
    from worlds.vector_env import NavigationVectorEnv

    start = time.perf_counter()
    env = NavigationVectorEnv(2, maps=maps, seed=0)
    try:
        env.reset(seed=0)
        for _ in range(2):
            env.step(np.zeros(2, dtype=np.int64))
    finally:
        env.close()
    sets = [make_eval_set(family, 1, seed=0) for family in ("unseen", "dynamic")]
    evaluate(lambda obs: np.zeros(len(obs), dtype=np.int64), sets)
    compiled = sum(step_all.stats.cache_misses.values()) > 0
    return time.perf_counter() - start, compiled
