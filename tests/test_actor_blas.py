"""The actor runs its loop with numpy's BLAS on one thread (threadpoolctl, as agents.evaluation).

OpenBLAS splits the policy's small matrix products over every core and spins between calls:
an actor of 64 robots spent 18x its CPU per robot-step that way (bench/capacity.py measures it).
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

        def __enter__(self) -> FakeActor:
            return self

        def __exit__(self, *exc: object) -> None:
            pass

        def run(self, stop: threading.Event) -> int:
            seen.append(blas_threads())
            return 0

    class Closable:  # stands in for the Zenoh session and the liveliness token
        def __enter__(self) -> Closable:
            return self

        def __exit__(self, *exc: object) -> None:
            pass

    monkeypatch.setattr(actor_module, "Actor", FakeActor)
    monkeypatch.setattr(actor_module, "open_session", lambda settings, stop: Closable())
    monkeypatch.setattr(actor_module, "declare_alive", lambda *args: Closable())
    config = ActorConfig(id="blas1", envs=2, maps="rooms:10", seed=0)
    assert actor_module.run_actor(config, ZenohSettings(), threading.Event()) == 0
    assert seen == [{1}], seen
