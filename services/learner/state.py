"""The learner service's parts as one typed view, and what a checkpoint holds besides the networks.

``LearnerParts.write`` fills a checkpoint directory being written (the NNQL learner with its replay
buffer, the demonstrations, NIRL, and ``service.json``: rate limiter, counters, inbox counts,
per-actor totals, last evaluation, write-ahead log position and duplicate filter); ``load`` puts all
of it back on resume. services.learner.status builds the status snapshot from the same view.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from agents.nnql.learner import NNQLLearner
from services.learner.demo_buffer import DemoBuffer
from services.learner.durable import DurableIngest
from services.learner.inbox import Inbox
from services.learner.nirl import NIRLTrainer
from services.learner.ratelimit import RateLimiter
from services.learner.stats import LearnerTally
from services.learner.storage import StorageGuard


@dataclass(frozen=True)
class LearnerParts:
    """What a LearnerService is made of, besides its config and its Zenoh declarations."""

    learner: NNQLLearner
    demos: DemoBuffer
    limiter: RateLimiter
    inbox: Inbox
    tally: LearnerTally
    durable: DurableIngest | None
    """write-ahead log and duplicate filter (None without a checkpoint directory)"""
    nirl: NIRLTrainer | None
    storage: StorageGuard
    """whether the last write-ahead-log or checkpoint write failed (its counters go into the status)"""

    def write(self, tmp: Path) -> None:
        """Write the state into the unfinished checkpoint directory ``tmp``."""
        self.learner.save_checkpoint(tmp / "nnql")
        self.demos.save(tmp / "demos")
        if self.nirl is not None:
            self.nirl.save(tmp / "nirl")
        tally = self.tally.state()
        state = {
            "limiter": self.limiter.state(),
            "counters": tally["counters"],
            "inbox_counts": self.inbox.counts(),
            "actors": tally["actors"],
            "demo_episodes": self.demos.episodes,
            "last_eval": tally["last_eval"],
            "durable": self.durable.checkpoint_state() if self.durable else None,
        }
        (tmp / "service.json").write_text(json.dumps(state, indent=1) + "\n")

    def load(self, path: Path) -> None:
        """Restore the state from the checkpoint directory ``path``."""
        self.learner.load_checkpoint(path / "nnql")
        state = json.loads((path / "service.json").read_text())
        self.limiter.load_state(state["limiter"])
        self.tally.load_state(state)
        self.inbox.load_counts(state["inbox_counts"])
        self.demos.load(path / "demos", state["demo_episodes"])
        if self.nirl is not None:
            self.nirl.load(path / "nirl")
        if self.durable is not None:
            self.durable.load_state(state.get("durable"))


def checkpoint_wal_seq(path: Path) -> int:
    """The write-ahead log position a checkpoint holds everything up to (0 if it cannot say)."""
    try:
        durable = json.loads((path / "service.json").read_text()).get("durable") or {}
        return int(durable.get("wal_seq", 0))
    except (OSError, ValueError, AttributeError, TypeError):
        return 0
