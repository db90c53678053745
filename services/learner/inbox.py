"""The learner's inbox: Zenoh callbacks decode and enqueue, the main thread takes.

Callbacks run on Zenoh's threads, so they do only what cannot wait: decode and
validate the bytes (protocols.codec), check that the key matches the message,
and put it in a bounded queue: transition batches in one FairQueue, demos and
evaluation reports in another, each bounded in items and bytes, with a bound per
sender, served fairly by work (bytes, so transitions; see services.learner.fairqueue):
a flooding actor neither crowds out the others nor grows memory. Nothing here
touches the replay buffer or the network weights. A message that fails is counted
under ``rejected/<reason>`` (the ProtocolError reason); one that finds its queue full
under ``dropped/inbox_full``, or ``dropped/sender_full`` when only its sender's share
is full (``dropped/sender_full/<name>`` says who). Checked before decoding, so a
flooder costs a key parse per message, not a decode:

* a sender whose share is full: ``dropped/sender_full``;
* a transition batch larger than ``max_rows`` rows could be (``rejected/batch_too_large``;
  its rows are checked again once decoded);
* a name beyond ``max_names`` distinct names (``rejected/too_many_names``): names are
  remembered once a message of theirs is accepted, names in ``known_names`` (an ACL's)
  always pass. The names bound every per-name counter and the status.

Nothing ever raises into Zenoh. Oversized messages are refused by the codec (``rejected/oversize``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass

from agents.nnql.config import NNQLConfig
from agents.nnql.ratelimit import RateLimiter
from protocols import keys
from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import DemoBatch, EvalReport, Message, TransitionBatch
from services.learner.config import LearnerConfig
from services.learner.fairqueue import FairQueue, SenderFull
from services.ops.acl import acl_publishers

log = logging.getLogger("navlearn.inbox")
MB = 2**20
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


def transition_bytes_bound(rows: int, obs_dim: int) -> int:
    """At most the encoded size of a TransitionBatch of ``rows`` rows of ``obs_dim`` floats: per row
    two observations of 8-byte floats, 8-byte action, reward and env id, two flags; 64 KiB of
    envelope, keys and strings."""
    return rows * (16 * obs_dim + 26) + 65_536


class Inbox:
    """Bounded queues fed by Zenoh callbacks: transition batches, and the rest (demos, eval reports)."""

    def __init__(
        self,
        limits: Limits,
        capacity: int,
        run: str,
        log_every: float = 10.0,
        per_sender: int = 0,
        capacity_bytes: int = 256 * MB,
        max_rows: int | None = None,
        max_names: int = 256,
        known_names: frozenset[str] = frozenset(),
    ) -> None:
        """``capacity``/``capacity_bytes``: what each queue holds; ``per_sender``: transition batches one
        actor may have waiting (0: a quarter of ``capacity``; its bytes: a quarter of ``capacity_bytes``);
        ``max_rows``: transitions per batch (default ``limits.max_batch``); ``max_names``: distinct
        sender names besides ``known_names``."""
        if capacity_bytes < 2 * limits.max_message_bytes:
            raise ValueError(
                f"inbox of {capacity_bytes / MB:.0f} MB cannot hold two messages of the largest size "
                f"accepted ({limits.max_message_bytes / MB:.0f} MB); raise the inbox's bytes (--inbox-mb)"
            )
        self.limits = limits
        self.run = run
        self.max_rows = limits.max_batch if max_rows is None else max_rows
        self.max_transition_bytes = transition_bytes_bound(self.max_rows, limits.max_obs_dim)
        self.transitions: FairQueue[Received] = FairQueue(
            capacity, per_sender or max(1, capacity // 4), capacity_bytes, capacity_bytes // 4
        )
        self.other: FairQueue[Received] = FairQueue(capacity, capacity, capacity_bytes, capacity_bytes // 2)
        self.max_names = max_names
        self.known_names = frozenset(known_names)
        self._names: set[str] = set()
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._log_every = log_every
        self._last_log: dict[str, float] = {}

    def names(self) -> set[str]:
        """Sender names seen (besides the known ones), at most ``max_names``."""
        with self._lock:
            return set(self._names)

    def remember(self, names) -> None:
        """Take ``names`` as seen (a resumed learner's), as many as the bound allows."""
        with self._lock:
            for name in names:
                if name not in self.known_names and len(self._names) < self.max_names:
                    self._names.add(name)

    def _name_admitted(self, name: str) -> bool:
        with self._lock:
            return name in self.known_names or name in self._names or len(self._names) < self.max_names

    def _accepted(self, name: str) -> None:
        with self._lock:
            if name not in self.known_names and name not in self._names and len(self._names) < self.max_names:
                self._names.add(name)

    def subscribe(self, session) -> list:
        """Declare the subscribers (transitions/*, demos/*, eval/*); returns them for undeclaring."""
        return [session.declare_subscriber(keys.everything(self.run, ch), self.on_sample) for ch in EXPECTED]

    def on_sample(self, sample) -> None:
        """Zenoh callback: decode, check, enqueue - or count why not."""
        arrived = time.time()
        try:
            parsed = keys.parse(sample.key_expr)
            nbytes = len(sample.payload)
            queue_ = self.transitions if parsed.channel == "transitions" else self.other
            if not self._name_admitted(parsed.name):
                self.reject(
                    "too_many_names",
                    f"refused {parsed.channel}/{parsed.name}: {self.max_names} sender names known already "
                    "(raise --max-names, or give the learner the ACL with --acl-names)",
                )
                return
            if parsed.channel == "transitions" and nbytes > self.max_transition_bytes:
                self.reject("batch_too_large", f"{nbytes} bytes from {parsed.name}: {self._rows_fix()}")
                return
            if queue_.sender_full(parsed.name, nbytes):
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
        if isinstance(message, TransitionBatch) and len(message) > self.max_rows:
            self.reject(
                "batch_too_large", f"{len(message)} transitions from {parsed.name}: {self._rows_fix()}"
            )
            return
        item = Received(parsed.channel, parsed.name, message, arrived, payload)
        try:
            queue_.put_nowait(parsed.name, item, nbytes)
            self._accepted(parsed.name)
        except SenderFull:
            self._sender_full(parsed.name)
        except queue.Full:
            self.count("dropped/inbox_full")
            self._warn("inbox_full", f"inbox full, dropped a {parsed.channel} message from {parsed.name}")

    def _rows_fix(self) -> str:
        return (
            f"this learner takes at most {self.max_rows} transitions per batch (the smaller of "
            "--max-batch-fraction x --replay-capacity and --rate-tolerance / --utd-ratio); send smaller "
            "batches (navlearn actor --batch-steps, --envs) or raise those"
        )

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


def max_batch_rows(config: LearnerConfig, nnql: NNQLConfig) -> int:
    """The most transitions one batch may hold: a ``max_batch_fraction`` of the replay, and no more
    than the rate limiter lets in at once (``rate_tolerance / utd_ratio``)."""
    fits_limiter = RateLimiter(nnql.utd_ratio, 1, config.rate_tolerance).max_rows()
    rows = min(int(config.max_batch_fraction * nnql.replay_capacity), fits_limiter)
    if rows < 1:
        raise ValueError(
            f"max_batch_fraction {config.max_batch_fraction} x replay_capacity {nnql.replay_capacity} admits "
            "no transition batch; raise --max-batch-fraction"
        )
    return rows


def learner_inbox(
    config: LearnerConfig, nnql: NNQLConfig, limits: Limits, run: str, acl_files: tuple[str | None, ...]
) -> Inbox:
    """The learner service's inbox: its bounds from ``config`` and ``nnql``; the publishers named in
    ``acl_files`` (empty entries skipped) always accepted."""
    known = [acl_publishers(f, run) for f in acl_files if f]
    return Inbox(
        limits,
        config.inbox_size,
        run,
        log_every=config.log_every,
        capacity_bytes=config.inbox_mb * MB,
        max_rows=max_batch_rows(config, nnql),
        max_names=config.max_names,
        known_names=frozenset().union(*known),
    )
