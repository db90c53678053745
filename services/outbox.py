"""The actor's outbox: a bounded queue of encoded batches sent under an acknowledgement window.

A batch leaves only while fewer than ``window`` sent batches wait for the
learner's acknowledgement (protocols.flow.Ack): the actor waits for acknowledgements
while the window is full, so a learner whose rate limiter holds inserts back
slows its actors down (Reverb's blocking insert). While nobody subscribes to
the actor's key (router or learner gone) batches wait here and the actor keeps
stepping until the outbox is full, then waits for the learner to come back. An
acknowledgement that never comes (lost with a restarting learner) is given up
on after ``ack_timeout`` seconds.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable


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
        self._changed = threading.Condition()
        self.sent_seq = 0
        """seq of the newest batch sent"""
        self.acked_seq = 0
        """seq of the newest batch the learner acknowledged (or that was given up on)"""
        self.sent = 0
        self.acks_given_up = 0
        self._last_progress = time.monotonic()

    def __len__(self) -> int:
        return len(self._waiting)

    @property
    def full(self) -> bool:
        return len(self._waiting) >= self.capacity

    @property
    def in_flight(self) -> int:
        return max(self.sent_seq - self.acked_seq, 0)

    def put(self, seq: int, payload: bytes) -> None:
        """Queue batch ``seq`` (seqs increase); ``flush`` afterwards keeps the outbox within capacity."""
        self._waiting.append((seq, payload))

    def on_ack(self, accepted_seq: int) -> None:
        """The learner accepted batch ``accepted_seq`` (called from a Zenoh callback thread)."""
        with self._changed:
            if accepted_seq > self.acked_seq:
                self.acked_seq = min(accepted_seq, self.sent_seq) if self.sent_seq else accepted_seq
                self._last_progress = time.monotonic()
                self._changed.notify_all()

    def flush(self, stop: threading.Event) -> None:
        """Send what the window allows, waiting for acknowledgements while the learner is reachable.

        While nobody subscribes (router or learner gone) batches stay queued and this returns at
        once, unless the outbox is full: then it waits for room. Returns early when ``stop`` is set.
        """
        while self._waiting and not stop.is_set():
            if not self._reachable():
                if not self.full:
                    return
                stop.wait(0.2)
                continue
            with self._changed:
                if self.in_flight >= self.window:
                    if time.monotonic() - self._last_progress <= self.ack_timeout:
                        self._changed.wait(0.2)
                        continue
                    self.acks_given_up += self.in_flight
                    self.acked_seq = self.sent_seq
            seq, payload = self._waiting.popleft()
            self._send(payload)
            with self._changed:
                if self.in_flight == 0:
                    self._last_progress = time.monotonic()
                self.sent_seq = seq
                self.sent += 1
