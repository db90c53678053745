"""The actor runs its loop with numpy's BLAS on one thread (threadpoolctl, as agents.evaluation).

OpenBLAS splits the policy's small matrix products over every core and spins between calls:
an actor of 64 robots spent 18x its CPU per robot-step that way (bench/RESULTS.md, capacity).
"""

from __future__ import annotations

import threading

from threadpoolctl import threadpool_info

import services.actor.actor as actor_module
from services.actor.config import ActorConfig
from services.common.transport import ZenohSettings


def blas_threads() -> set[int]:
    return {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}


def test_the_actor_loop_runs_on_one_blas_thread(monkeypatch) -> None:
    seen: list[set[int]] = []

    class FakeActor:  # the real set-up (env, session, token) with the loop replaced by a probe
        def __init__(self, *args, **kwargs) -> None:
            pass

        def run(self, stop: threading.Event) -> int:
            seen.append(blas_threads())
            return 0

        def close(self) -> None:
            pass

    class Session:
        def close(self) -> None:
            pass

    class Token:
        def undeclare(self) -> None:
            pass

    monkeypatch.setattr(actor_module, "Actor", FakeActor)
    monkeypatch.setattr(actor_module, "connect", lambda settings, stop: Session())
    monkeypatch.setattr(actor_module, "declare_alive", lambda *args: Token())
    config = ActorConfig(id="blas1", envs=2, maps="rooms:10", seed=0)
    assert actor_module.run_actor(config, ZenohSettings(), threading.Event()) == 0
    assert seen == [{1}], seen
