"""What a learner checkpoint holds besides the networks: the service's own state (``service.json``).

``write_service_state`` fills a checkpoint directory being written (the NNQL learner with
its replay buffer, the demonstrations, NIRL, and service.json: rate limiter, counters,
inbox counts, per-actor totals, last evaluation, write-ahead log position and duplicate
filter); ``load_service_state`` puts all of it back into a LearnerService on resume.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from services.learner.stats import ActorStats


def write_service_state(service: Any, tmp: Path) -> None:
    """Write ``service``'s state into the unfinished checkpoint directory ``tmp``."""
    service.learner.save_checkpoint(tmp / "nnql")
    service.demos.save(tmp / "demos")
    if service.nirl is not None:
        service.nirl.save(tmp / "nirl")
    state = {
        "limiter": service.limiter.state(),
        "counters": service.counters,
        "inbox_counts": service.inbox.counts(),
        "actors": {
            a: {"transitions": s.transitions, "batches": s.batches} for a, s in service.actors.items()
        },
        "demo_episodes": service.demos.episodes,
        "last_eval": service.last_eval,
        "durable": service.durable.checkpoint_state() if service.durable else None,
    }
    (tmp / "service.json").write_text(json.dumps(state, indent=1) + "\n")


def load_service_state(service: Any, path: Path) -> None:
    """Restore ``service`` from the checkpoint directory ``path``."""
    service.learner.load_checkpoint(path / "nnql")
    state = json.loads((path / "service.json").read_text())
    service.limiter.load_state(state["limiter"])
    service.counters = {k: int(v) for k, v in state["counters"].items()}
    service.inbox.load_counts(state["inbox_counts"])
    for actor, saved in state["actors"].items():
        service.actors[actor] = ActorStats(transitions=saved["transitions"], batches=saved["batches"])
    service.demos.load(path / "demos", state["demo_episodes"])
    if service.nirl is not None:
        service.nirl.load(path / "nirl")
    service.last_eval = state["last_eval"]
    if service.durable is not None:
        service.durable.load_state(state.get("durable"))
