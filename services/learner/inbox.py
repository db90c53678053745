"""The learner's inbox: Zenoh callbacks decode and enqueue, the main thread takes.

Callbacks run on Zenoh's threads, so they do only what cannot wait: decode and
validate the bytes (protocols.codec), check that the key matches the message,
and put it in a bounded queue: transition batches in a FairQueue (a bound per
actor, served round-robin, so a flooding actor neither crowds out the others
nor grows memory). Nothing here touches the replay buffer or the
network weights. A message that fails is counted under ``rejected/<reason>``
(the ProtocolError reason); one that finds its queue full under
``dropped/inbox_full``, or ``dropped/sender_full`` when only its actor's share
is full (``dropped/sender_full/<actor>`` says who). A batch whose actor's share
is already full is dropped before it is decoded: a flooding actor then costs the
learner a key parse per message, not a decode. Neither ever raises into
Zenoh. Oversized messages are refused by the codec (``rejected/size``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass

from protocols import keys
from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import DemoBatch, EvalReport, Message, TransitionBatch
from services.learner.fairqueue import FairQueue, SenderFull

log = logging.getLogger("navlearn.inbox")
EXPECTED = {"transitions": TransitionBatch, "demos": DemoBatch, "eval": EvalReport}
"""Channel -> the message kind it carries."""


@dataclass
class Received:
    """One accepted message: the name in its key (actor, source, evaluator), when it arrived, and the
    bytes it came as (what the write-ahead log stores: the decoded arrays are views of them)."""

    channel: str
    name: str
    message: Message
    arrived: float
    payload: bytes = b""


class Inbox:
    """Bounded queues fed by Zenoh callbacks: transition batches, and the rest (demos, eval reports)."""

    def __init__(
        self, limits: Limits, capacity: int, run: str, log_every: float = 10.0, per_sender: int = 0
    ) -> None:
        """``per_sender``: transition batches one actor may have waiting (0: a quarter of ``capacity``)."""
        self.limits = limits
        self.run = run
        self.transitions: FairQueue[Received] = FairQueue(capacity, per_sender or max(1, capacity // 4))
        self.other: queue.Queue[Received] = queue.Queue(maxsize=capacity)
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._log_every = log_every
        self._last_log: dict[str, float] = {}

    def subscribe(self, session) -> list:
        """Declare the subscribers (transitions/*, demos/*, eval/*); returns them for undeclaring."""
        return [session.declare_subscriber(keys.everything(self.run, ch), self.on_sample) for ch in EXPECTED]

    def on_sample(self, sample) -> None:
        """Zenoh callback: decode, check, enqueue - or count why not."""
        arrived = time.time()
        try:
            parsed = keys.parse(sample.key_expr)
            if parsed.channel == "transitions" and self.transitions.sender_full(parsed.name):
                self._sender_full(parsed.name)
                return
            payload = sample.payload.to_bytes()
            message = decode(payload, self.limits)
            expected = EXPECTED.get(parsed.channel)
            if expected is None or not isinstance(message, expected):
                raise ProtocolError("kind", f"{message.KIND} message on {parsed.channel}/{parsed.name}")
            if isinstance(message, TransitionBatch) and message.actor != parsed.name:
                raise ProtocolError("key", f"batch of actor {message.actor!r} on the key of {parsed.name!r}")
        except ProtocolError as exc:
            self.count(f"rejected/{exc.reason}")
            self._warn(exc.reason, f"rejected a message on {sample.key_expr}: {exc}")
            return
        item = Received(parsed.channel, parsed.name, message, arrived, payload)
        try:
            if parsed.channel == "transitions":
                self.transitions.put_nowait(parsed.name, item)
            else:
                self.other.put_nowait(item)
        except SenderFull:
            self._sender_full(parsed.name)
        except queue.Full:
            self.count("dropped/inbox_full")
            self._warn("inbox_full", f"inbox full, dropped a {parsed.channel} message from {parsed.name}")

    def _sender_full(self, name: str) -> None:
        self.count("dropped/sender_full")
        self.count(f"dropped/sender_full/{name}")
        self._warn("sender_full", f"{name} sends faster than its share; dropped a batch")

    def reject(self, reason: str, what: str) -> None:
        """Count a message the main thread found unusable after decoding (e.g. wrong obs_dim)."""
        self.count(f"rejected/{reason}")
        self._warn(reason, what)

    def count(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._counts[name] += n

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    def load_counts(self, counts: dict[str, int]) -> None:
        with self._lock:
            self._counts.update(counts)

    def _warn(self, reason: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_log.get(reason, -1e9) >= self._log_every:
            self._last_log[reason] = now
            log.warning("%s (counting %s; logged at most every %.0f s)", text, reason, self._log_every)
