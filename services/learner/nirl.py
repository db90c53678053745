"""NIRL inside the learner service, beside NNQL: the service-side wiring of agents.nirl.

The NIRL learner shares the service's buffers - actor experience is the NNQL replay,
demonstrations are the demonstration buffer (never evicted by experience) - and runs
its own updates (warm start from the demonstrations first, then reward / Q-learning
updates, ``agents.nirl.learner.NIRLLearner.update``). Its Q-network goes out on
``weights/nirl`` every ``broadcast_every`` updates with the Boltzmann schedule actors
follow (``navlearn actor --model nirl``).
"""

from __future__ import annotations

import logging
from pathlib import Path

from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner
from agents.nirl.weights import WeightHistory
from protocols.messages import ExplorationSchedule
from services.common.weights import WeightsBroadcaster
from worlds.config import NavConfig

log = logging.getLogger("navlearn.learner.nirl")
MODEL = "nirl"
HISTORY_EVERY = 1
"""record the weights of both networks every this many NIRL iterations (for `navlearn nirl weights`)"""


class NIRLTrainer:
    """One NIRL learner fed by the service; ``train(n)`` runs up to n updates when demos exist.
    Its networks live on ``device`` (the learner's ``--device``), the shared buffers in host memory."""

    def __init__(
        self,
        config: NIRLConfig,
        nav: NavConfig,
        experience,
        demos,
        session,
        run: str,
        sender: str,
        broadcast_every: int,
        device: str = "cpu",
    ):
        self.learner = NIRLLearner(config, nav, experience=experience, demos=demos, device=device)
        self.weights = WeightsBroadcaster(session, run, MODEL, sender)
        self.broadcast_every = max(int(broadcast_every), 1)
        self.history = WeightHistory()
        self.metrics: dict[str, float] = {}

    @property
    def version(self) -> int:
        return self.learner.version

    def train(self, max_updates: int) -> int:
        """Run up to ``max_updates`` NIRL updates (none without demonstrations); returns how many ran."""
        if not self.learner.ready():
            return 0
        ran = 0
        for _ in range(max_updates):
            iteration = self.learner.iteration
            self.metrics = self.learner.update()
            ran += 1
            if self.learner.version % self.broadcast_every == 0:
                self.broadcast()
            if self.learner.iteration != iteration and self.learner.iteration % HISTORY_EVERY == 0:
                self.history.record(
                    self.learner.iteration,
                    reward=self.learner.reward_weights(),
                    policy=self.learner.get_weights(),
                )
        return ran

    def broadcast(self) -> None:
        if not self.learner.ready():
            return  # no demonstrations yet: nothing learned worth sending
        exploration = ExplorationSchedule(**self.learner.exploration_schedule())
        learner, q = self.learner, self.learner.q
        weights = learner.get_weights()
        self.weights.publish(weights, learner.version, q.architecture, exploration, q.observation)

    def status_fields(self) -> tuple[dict[str, int], dict[str, float]]:
        """(counters, losses) to merge into the StatusReport, prefixed ``nirl/``."""
        counters = {
            "nirl/iterations": self.learner.iteration,
            "nirl/warm_updates": self.learner.warm_updates,
            "nirl/reward_updates": self.learner.reward_steps,
        }
        losses = {
            f"nirl/{k.removeprefix('losses/')}": v for k, v in self.metrics.items() if k.startswith("losses/")
        }
        # the learned reward's scale beside what it must value (path length, collision value)
        losses.update({k: v for k, v in self.metrics.items() if k.startswith("nirl/")})
        return counters, losses

    def save(self, path: Path) -> None:
        """NIRL's part of a learner checkpoint: networks, optimisers, counters, weight history."""
        self.learner.save_checkpoint(path)
        if len(self.history):
            self.history.save(path / "weights_history.safetensors")

    def load(self, path: Path) -> None:
        if not path.exists():
            log.info("checkpoint has no NIRL state; NIRL starts fresh")
            return
        self.learner.load_checkpoint(path)
        if (path / "weights_history.safetensors").exists():
            self.history = WeightHistory.load(path / "weights_history.safetensors")

    def close(self) -> None:
        self.weights.close()
