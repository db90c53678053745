"""The actor's outbox: a bounded queue of encoded batches, each kept until the learner acknowledges it.

At-least-once delivery: a sent batch stays here (``unacked``) until the
learner's acknowledgement for its seq (protocols.flow.Ack, sent only once the
batch is in the learner's write-ahead log) arrives; the learner drops
duplicates by (sender, seq). At most ``window`` batches are in flight: the actor
waits for acknowledgements while the window is full, so a learner whose rate
limiter holds inserts back slows its actors down (Reverb's blocking insert).
While nobody subscribes to the actor's key (router or learner gone) batches
wait here and the actor keeps stepping until the outbox (waiting + unacknowledged)
is full, then waits for the learner (back-pressure, never a drop). When the
learner is reachable again, or no acknowledgement came for ``ack_timeout``
seconds, the unacknowledged batches are sent again, oldest first (``resent``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable

from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.flow import Ack

log = logging.getLogger("navlearn.outbox")


def decode_ack(payload: bytes, incarnation: str) -> Ack | None:
    """The acknowledgement in ``payload`` if it is addressed to ``incarnation`` (an envelope sender,
    ``<id>#<start>``: a previous incarnation's or a sibling's acks on a shared key are ignored)."""
    try:
        ack = decode(payload)
    except ProtocolError as exc:
        log.warning("rejected an acknowledgement: %s", exc)
        return None
    return ack if isinstance(ack, Ack) and ack.actor == incarnation else None


class Outbox:
    """Batches waiting to be sent, oldest first; ``send`` is the transport (e.g. ``publisher.put``)."""

    def __init__(
        self,
        send: Callable[[bytes], None],
        reachable: Callable[[], bool],
        capacity: int = 64,
        window: int = 4,
        ack_timeout: float = 10.0,
    ) -> None:
        if capacity < 1 or window < 1:
            raise ValueError("outbox capacity and ack window must be >= 1")
        self._send = send
        self._reachable = reachable
        self.capacity = capacity
        self.window = window
        self.ack_timeout = ack_timeout
        self._waiting: deque[tuple[int, bytes]] = deque()
        self._unacked: dict[int, bytes] = {}
        """sent batches without an acknowledgement, by seq (insertion order = send order)"""
        self._changed = threading.Condition()
        self.sent_seq = 0
        """seq of the newest batch sent"""
        self.acked_seq = 0
        """seq of the newest batch the learner acknowledged"""
        self.sent = 0
        """sends, resends included"""
        self.acked = 0
        """batches acknowledged (each once)"""
        self.resent = 0
        """batches sent again (acknowledgement lost or learner restarted)"""
        self.blocked_s = 0.0
        """seconds ``flush`` waited for the learner (window of unacknowledged batches or outbox full)"""
        self.full_s = 0.0
        """of which seconds with the outbox full (back-pressure on the producer)"""
        self._last_progress = time.monotonic()
        self._was_reachable = True

    def __len__(self) -> int:
        """Batches held: waiting to be sent plus sent but unacknowledged."""
        return len(self._waiting) + len(self._unacked)

    @property
    def full(self) -> bool:
        return len(self) >= self.capacity

    @property
    def in_flight(self) -> int:
        return len(self._unacked)

    def put(self, seq: int, payload: bytes) -> None:
        """Queue batch ``seq`` (seqs increase); ``flush`` afterwards keeps the outbox within capacity."""
        self._waiting.append((seq, payload))

    def on_ack(self, accepted_seq: int) -> None:
        """The learner durably stored batch ``accepted_seq`` (called from a Zenoh callback thread)."""
        with self._changed:
            if self._unacked.pop(accepted_seq, None) is not None:
                self.acked += 1
            self.acked_seq = max(self.acked_seq, accepted_seq)
            self._last_progress = time.monotonic()
            self._changed.notify_all()

    def _requeue_unacked(self) -> None:
        """Put every unacknowledged batch back at the front of the queue, oldest first."""
        with self._changed:
            again = sorted(self._unacked.items())
            self._unacked.clear()
            self.resent += len(again)
            self._waiting.extendleft(reversed(again))
            self._last_progress = time.monotonic()

    def flush(self, stop: threading.Event) -> None:
        """Send what the window allows, waiting for acknowledgements while the learner is reachable.

        While nobody subscribes (router or learner gone) batches stay queued and this returns at
        once, unless the outbox is full: then it waits for room. Returns early when ``stop`` is set.
        """
        while (self._waiting or self._unacked) and not stop.is_set():
            if not self._reachable():
                self._was_reachable = False
                if not self.full:
                    return
                self._wait(lambda: stop.wait(0.2))
                continue
            if not self._was_reachable:  # the learner (or router) is back: what it did not ack, again
                self._was_reachable = True
                self._requeue_unacked()
            with self._changed:
                if self.in_flight >= self.window or not self._waiting:
                    if not self.full and not self._waiting:
                        return
                    if time.monotonic() - self._last_progress <= self.ack_timeout:
                        self._wait(lambda: self._changed.wait(0.2))
                        continue
                    timed_out = True
                else:
                    timed_out = False
            if timed_out:
                self._requeue_unacked()
                continue
            seq, payload = self._waiting.popleft()
            with self._changed:
                if not self._unacked:
                    self._last_progress = time.monotonic()
                self._unacked[seq] = payload
                self.sent_seq = max(self.sent_seq, seq)
                self.sent += 1
            self._send(payload)

    def _wait(self, wait: Callable[[], object]) -> None:
        full, start = self.full, time.monotonic()
        wait()
        waited = time.monotonic() - start
        self.blocked_s += waited
        if full:
            self.full_s += waited

    def drain(self, stop: threading.Event, timeout: float | None = None) -> bool:
        """Send everything and wait until all of it is acknowledged (resending after ``ack_timeout``
        or when the learner is back), until ``stop`` or ``timeout`` s; True when the outbox is empty."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while len(self) and not stop.is_set() and (deadline is None or time.monotonic() < deadline):
            self.flush(stop)
            with self._changed:
                stalled = time.monotonic() - self._last_progress > self.ack_timeout
                if self._unacked and not self._waiting and stalled and self._reachable():
                    self._requeue_unacked()
                    continue
                self._changed.wait(0.1)
        return len(self) == 0
