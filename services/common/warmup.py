"""The robot world's numba kernels, compiled once before the processes that use them start.

Every kernel is compiled with ``cache=True``: the first process on a machine (or the first after
worlds/ changed) compiles them - :data:`TYPICAL_COMPILE` (results/first-run/) - and writes numba's cache
(``__pycache__`` beside the sources, or ``NUMBA_CACHE_DIR``); later processes load it in about a
second. ``navlearn up`` calls :func:`compile_world` before it starts its processes, so they do not
all compile at once while the training clock runs; ``navlearn world compile`` does the same for
processes started by hand (the secure recipe, supervisord), before their clocks start.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

TYPICAL_COMPILE = "35-40 s on 2 idle cores, 75-90 s on busy ones"
"""a cold compile of the world measured on this project's 2-core machine (bench/first_run.py,
results/first-run/): 75-90 s of wall clock at load 6-8, 42-51 CPU seconds (one thread: about the
wall clock when a core is free)"""
COMPILE_NOTE = (
    f"a cold numba cache compiles the world first ({TYPICAL_COMPILE}; `navlearn world compile` does "
    "it ahead); later starts load it"
)
STAGES = ("the robots' reset", "the robots' step", "the evaluation's planners")
"""what compile_world compiles, in order (each stage's kernels, then the next)"""
KERNELS = 61
"""the navlearn functions a cold compile_world compiles (worlds/ and agents/; every helper that is
called rather than inlined is one, once per argument types), counted by the numba:compile events:
the "k of N" of the progress line"""


def _counter(report: Callable[[int], None]):
    """A numba compile-event listener that counts finished compiles of navlearn's own functions
    (worlds/, agents/) and reports the count (numba imported here, not when the CLI is built)."""
    from numba.core import event

    class Counter(event.Listener):
        done = 0

        def on_start(self, _event) -> None:
            pass

        def on_end(self, compiled) -> None:
            module = getattr(compiled.data["dispatcher"].py_func, "__module__", "") or ""
            if module.startswith(("worlds.", "agents.")):
                self.done += 1
                report(self.done)

    return Counter()


def progress_text(stage: int, kernels: int, seconds: float) -> str:
    """One line: how far the compile is (stage, kernels compiled of :data:`KERNELS`), how long it
    has taken and how long it usually takes."""
    return (
        f"compiling the robot world (first run only): {STAGES[stage]} ({stage + 1}/{len(STAGES)}), "
        f"{min(kernels, KERNELS)} of ~{KERNELS} kernels, {seconds:.0f} s so far; usually {TYPICAL_COMPILE}"
    )


def compile_world(maps: str, progress: Callable[[str], None] | None = None) -> tuple[float, bool]:
    """Step a small vector env on ``maps`` and evaluate one episode of each held-out family, both in
    :data:`worlds.config.LEARNING_NAV` (the kernels of actors and the evaluator, the observation's
    own included); returns (seconds taken, whether anything was compiled). ``progress`` gets a
    :func:`progress_text` line whenever a kernel or a stage is done (nothing when all is cached)."""
    from numba.core import event

    from agents.evaluation import evaluate, make_eval_set
    from worlds.config import LEARNING_NAV
    from worlds.kernel import step_all
    from worlds.vector_env import NavigationVectorEnv

    start = time.perf_counter()
    stage = [0]

    def report(kernels: int) -> None:
        if progress is not None:
            progress(progress_text(stage[0], kernels, time.perf_counter() - start))

    counter = _counter(report)
    with event.install_listener("numba:compile", counter):
        env = NavigationVectorEnv(2, config=LEARNING_NAV, maps=maps, seed=0)
        try:
            env.reset(seed=0)
            stage[0] = 1
            for _ in range(2):
                env.step(np.zeros(2, dtype=np.int64))
        finally:
            env.close()
        stage[0] = 2
        sets = [make_eval_set(family, 1, seed=0) for family in ("unseen", "dynamic")]
        evaluate(lambda obs: np.zeros(len(obs), dtype=np.int64), sets, LEARNING_NAV)
    compiled = sum(step_all.stats.cache_misses.values()) > 0 or counter.done > 0
    return time.perf_counter() - start, compiled


def compile_with_progress(console, maps: str) -> tuple[float, bool]:
    """:func:`compile_world` with its progress line (stage, kernels, seconds, the usual
    time): updated in place on a terminal, printed every 10 s in a log."""
    import time
    from contextlib import nullcontext

    from services.common.warmup import compile_world

    first = "compiling the robot world (first run only)..."
    spinner = console.status(first) if console.is_terminal else nullcontext()
    if not console.is_terminal:
        console.print(first)
    printed = [time.monotonic()]

    def progress(line: str) -> None:
        if console.is_terminal:
            spinner.update(line)
        elif time.monotonic() - printed[0] >= 10:
            console.print(line, highlight=False)
            printed[0] = time.monotonic()

    with spinner:
        return compile_world(maps, progress)
