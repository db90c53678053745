"""Throughput bookkeeping for status and TensorBoard: sliding-window rates and per-actor figures."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any


class RateWindow:
    """Events per second over the last ``window`` seconds (counts recorded with their time)."""

    def __init__(self, window: float = 10.0) -> None:
        self.window = window
        self._events: deque[tuple[float, int]] = deque()
        self._total = 0
        self._started = time.monotonic()

    def add(self, count: int = 1, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        self._events.append((now, count))
        self._total += count
        self._trim(now)

    def rate(self, now: float | None = None) -> float:
        now = time.monotonic() if now is None else now
        self._trim(now)
        span = min(self.window, now - self._started)
        return self._total / span if span > 0 else 0.0

    def _trim(self, now: float) -> None:
        while self._events and self._events[0][0] < now - self.window:
            self._total -= self._events.popleft()[1]


@dataclass
class ActorStats:
    """What the learner knows about one actor."""

    transitions: int = 0
    """transitions accepted from it (since the learner's first start)"""
    batches: int = 0
    last_seen: float = 0.0
    """Unix time of its last accepted batch"""
    last_seq: int = 0
    rate: RateWindow = field(default_factory=RateWindow)

    def add(self, count: int, seq: int, arrived: float) -> None:
        self.transitions += count
        self.batches += 1
        self.last_seen = arrived
        self.last_seq = seq
        self.rate.add(count)


class LagWindow:
    """Policy lag (learner version minus the version that acted) of the last ``size`` batches."""

    def __init__(self, size: int = 200) -> None:
        self._lags: deque[int] = deque(maxlen=size)

    def add(self, lag: int) -> None:
        self._lags.append(max(int(lag), 0))

    def mean(self) -> float:
        return sum(self._lags) / len(self._lags) if self._lags else 0.0


@dataclass
class LearnerTally:
    """The learner service's own figures: counters, per-actor totals, rates, policy lag, the newest
    losses and evaluation (what its status reports and its checkpoint keeps)."""

    counters: dict[str, int] = field(default_factory=dict)
    actors: dict[str, ActorStats] = field(default_factory=dict)
    lags: LagWindow = field(default_factory=LagWindow)
    update_rate: RateWindow = field(default_factory=RateWindow)
    insert_rate: RateWindow = field(default_factory=RateWindow)
    metrics: dict[str, float] = field(default_factory=dict)
    """the newest update's metrics (``losses/...``)"""
    last_eval: dict[str, Any] | None = None
    """the newest evaluation summary (services.ops.status.eval_summary)"""

    def count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + int(n)

    def inserted(self, actor: str, n: int, seq: int, arrived: float, lag: int) -> None:
        """A batch of ``n`` transitions from ``actor`` went into replay."""
        self.insert_rate.add(n)
        self.lags.add(lag)
        self.actors.setdefault(actor, ActorStats()).add(n, seq, arrived)
        self.count("transitions_received", n)
        self.count("batches_received")

    def state(self) -> dict[str, Any]:
        """The part of ``service.json`` these figures fill (keys unchanged since the first checkpoints)."""
        return {
            "counters": self.counters,
            "actors": {
                a: {"transitions": s.transitions, "batches": s.batches} for a, s in self.actors.items()
            },
            "last_eval": self.last_eval,
        }

    def load_state(self, state: dict[str, Any]) -> None:
        self.counters = {k: int(v) for k, v in state["counters"].items()}
        for actor, saved in state["actors"].items():
            self.actors[actor] = ActorStats(transitions=saved["transitions"], batches=saved["batches"])
        self.last_eval = state["last_eval"]
