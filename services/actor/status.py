"""An actor's own status, answered on ``navlearn/<run>/status/actor:<id>`` (``navlearn status --actors``).

The answer is the status message kind (protocols' StatusReport: counters, rates,
versions) filled with the actor's figures: its outbox (held, bound, unacknowledged,
sent, acknowledged, resent), the time it spent waiting for the learner, whether it
is slowed down by back-pressure now, its robot-steps and the weights it follows.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

from protocols import keys
from protocols.keys import ACTOR_STATUS_PREFIX
from protocols.messages import StatusReport
from services.common.outbox import Outbox
from services.ops.status import status_replies

BACKPRESSURE_SHARE = 0.5
"""the actor reports back-pressure when it waited for the learner more than this share of the window"""


class BlockedShare:
    """Share of wall time spent waiting for the learner over the last ``window`` seconds."""

    def __init__(self, window: float = 5.0) -> None:
        self.window = window
        self._samples: deque[tuple[float, float]] = deque()
        self._lock = threading.Lock()  # the actor's loop adds, a status query (Zenoh thread) too

    def add(self, blocked_s: float, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        with self._lock:
            self._samples.append((now, blocked_s))
            while len(self._samples) > 2 and self._samples[1][0] <= now - self.window:
                self._samples.popleft()

    def share(self) -> float:
        with self._lock:
            if len(self._samples) < 2:
                return 0.0
            (t0, b0), (t1, b1) = self._samples[0], self._samples[-1]
        return min(1.0, max(0.0, (b1 - b0) / (t1 - t0))) if t1 > t0 else 0.0


@dataclass(frozen=True)
class ActorView:
    """What an actor's status reports besides its outbox and back-pressure: taken by the actor itself."""

    sender: str
    model: str
    version: int
    """the weights version it acts with"""
    learner_version: int
    """the learner's version in its newest acknowledgement"""
    reachable: bool
    robot_steps: int
    episodes: int
    weights_applied: int
    recent_successes: tuple[int, ...]
    """1 or 0 per recent episode"""
    steps_per_s: float


def actor_status(view: ActorView, outbox: Outbox, blocked: BlockedShare, seq: int) -> StatusReport:
    """An actor's status (called on a Zenoh thread)."""
    blocked.add(outbox.blocked_s)  # the actor may be inside a long wait: count it up to now
    share = blocked.share()
    counters = {
        "outbox_held": len(outbox),
        "outbox_capacity": outbox.capacity,
        "unacknowledged": outbox.in_flight,
        "ack_window": outbox.window,
        "batches_sent": outbox.sent,
        "batches_acknowledged": outbox.acked,
        "batches_resent": outbox.resent,
        "waiting_for_learner_ms": int(1000 * outbox.blocked_s),
        "outbox_full_ms": int(1000 * outbox.full_s),
        "backpressure": int(share > BACKPRESSURE_SHARE),
        "learner_reachable": int(view.reachable),
        "robot_steps": view.robot_steps,
        "episodes": view.episodes,
        "weights_applied": view.weights_applied,
        "learner_version": view.learner_version,
    }
    successes = view.recent_successes
    rates = {"waiting_for_learner_share": share, "robot_steps_per_s": view.steps_per_s}
    if successes:
        rates["success_rate"] = sum(successes) / len(successes)
    return StatusReport(
        sender=view.sender, seq=seq, counters=counters, rates=rates, versions={view.model: view.version}
    )


def query_actor_statuses(session, run: str, timeout: float = 2.0) -> dict[str, StatusReport]:
    """Every actor's answer on ``status/actor:<id>``, by actor id."""
    return {
        name.removeprefix(ACTOR_STATUS_PREFIX): message
        for name, message in status_replies(session, keys.everything(run, "status"), timeout)
        if name.startswith(ACTOR_STATUS_PREFIX)
    }


def actor_status_dicts(statuses: dict[str, StatusReport]) -> dict[str, dict]:
    """JSON-able: actor id -> its counters, rates and weights versions."""
    return {
        actor: {"sender": s.sender, "counters": s.counters, "rates": s.rates, "versions": s.versions}
        for actor, s in sorted(statuses.items())
    }


def render_actor_statuses(actors: dict[str, dict]):
    """A rich table, one row per actor."""
    from rich.table import Table

    table = Table(title="actor status (status/actor:<id>)")
    columns = ("actor", "version", "steps/s", "outbox", "unacked", "resent", "waiting", "back-pressure")
    for column in columns:
        table.add_column(column, justify="left" if column == "actor" else "right")
    for actor, view in actors.items():
        c, r = view["counters"], view["rates"]
        table.add_row(
            actor,
            " ".join(str(v) for v in view["versions"].values()),
            f"{r.get('robot_steps_per_s', 0.0):.0f}",
            f"{c.get('outbox_held', 0)}/{c.get('outbox_capacity', 0)}",
            str(c.get("unacknowledged", 0)),
            str(c.get("batches_resent", 0)),
            f"{100 * r.get('waiting_for_learner_share', 0.0):.0f}%",
            "[red]yes[/red]" if c.get("backpressure") else "no",
        )
    return table
