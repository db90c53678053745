"""A bounded queue with a bound per sender, in items and in bytes, served fairly by work: one
flooding actor cannot crowd out the others, slow them down or grow the learner's memory.

``put_nowait(sender, item, nbytes)`` raises ``SenderFull`` when that sender already has
``per_sender`` items or ``per_sender_bytes`` bytes waiting, and ``queue.Full`` when all
senders together hold ``capacity`` items or ``capacity_bytes`` bytes. Service is
start-time fair queueing (Goyal et al. 1996) over each item's work, ``nbytes +
MESSAGE_WORK``: at the learner's one observation size a batch's bytes are its
transitions times the row size, and ``MESSAGE_WORK`` is the fixed cost of any message
(decode, write-ahead-log record, acknowledgement). Each item gets a start tag,
``max(virtual time, the sender's previous finish tag)``, and the item with the smallest
start tag goes next; so every backlogged sender gets the same share of the work served
(transitions, not batches), and a sender that sends less than its share is served as soon
as its item arrives, ahead of a flooder's backlog.

One consumer (the learner's main thread): ``peek`` shows the item ``get_nowait`` takes next,
so the consumer can hold it back (e.g. until the rate limiter has room for its rows).
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from typing import Generic, TypeVar

T = TypeVar("T")

MESSAGE_WORK = 256
"""fixed work charged per message, in bytes of payload (about 2.5 transitions of 11 floats). A
training learner's binding cost is per transition (one update per 1/utd_ratio transitions; an update
of the default network took ~6 ms on one core here) and a message's own (a 20-26 us
decode, a log record, an ack) is a fraction of one transition's; the charge
keeps a sender of tiny batches from taking a larger share of the messages."""


class SenderFull(queue.Full):
    """This sender's share of the queue is full (others may still have room)."""


class FairQueue(Generic[T]):
    """Per-sender FIFO queues bounded in items and bytes, served in start-tag order."""

    def __init__(
        self, capacity: int, per_sender: int, capacity_bytes: int = 1 << 62, per_sender_bytes: int = 1 << 62
    ) -> None:
        if capacity < 1 or per_sender < 1 or capacity_bytes < 1 or per_sender_bytes < 1:
            raise ValueError("capacity, per_sender and their byte bounds must be >= 1")
        self.capacity = capacity
        self.per_sender = per_sender
        self.capacity_bytes = capacity_bytes
        self.per_sender_bytes = per_sender_bytes
        self._queues: dict[str, deque[tuple[float, int, T]]] = {}
        """sender -> (start tag, bytes, item), oldest first"""
        self._bytes: dict[str, int] = {}
        self._finish: dict[str, float] = {}
        """the finish tag of each sender's newest item (forgotten once virtual time passes it)"""
        self._virtual = 0.0
        self._size = 0
        self._total_bytes = 0
        self._ready = threading.Condition()

    def qsize(self) -> int:
        with self._ready:
            return self._size

    def nbytes(self) -> int:
        """Bytes waiting, all senders together."""
        with self._ready:
            return self._total_bytes

    def sender_full(self, sender: str, nbytes: int = 0) -> bool:
        """Would ``put_nowait(sender, item, nbytes)`` raise SenderFull?"""
        with self._ready:
            return self._full(sender, nbytes)

    def _full(self, sender: str, nbytes: int) -> bool:
        waiting = self._queues.get(sender)
        if waiting is None:
            return nbytes > self.per_sender_bytes
        return len(waiting) >= self.per_sender or self._bytes[sender] + nbytes > self.per_sender_bytes

    def put_nowait(self, sender: str, item: T, nbytes: int = 0) -> None:
        with self._ready:
            if self._full(sender, nbytes):
                raise SenderFull(sender)
            if self._size >= self.capacity or self._total_bytes + nbytes > self.capacity_bytes:
                raise queue.Full
            start = max(self._virtual, self._finish.get(sender, 0.0))
            self._finish[sender] = start + nbytes + MESSAGE_WORK
            self._queues.setdefault(sender, deque()).append((start, nbytes, item))
            self._bytes[sender] = self._bytes.get(sender, 0) + nbytes
            self._size += 1
            self._total_bytes += nbytes
            self._ready.notify()

    def peek(self) -> T | None:
        """The item ``get_nowait`` would take, or None when empty."""
        with self._ready:
            sender = self._next()
            return None if sender is None else self._queues[sender][0][2]

    def get_nowait(self) -> T:
        with self._ready:
            sender = self._next()
            if sender is None:
                raise queue.Empty
            return self._take(sender)

    def get(self, timeout: float | None = None) -> T:
        with self._ready:
            if not self._wait(timeout):
                raise queue.Empty
            return self._take(self._next())

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until an item is waiting (True) or ``timeout`` s have passed (False)."""
        with self._ready:
            return self._wait(timeout)

    def _wait(self, timeout: float | None) -> bool:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self._size == 0:
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return False
            self._ready.wait(remaining)
        return True

    def _next(self) -> str | None:
        if not self._queues:
            return None
        return min(self._queues, key=lambda s: self._queues[s][0][0])

    def _take(self, sender: str) -> T:
        waiting = self._queues[sender]
        start, nbytes, item = waiting.popleft()
        self._virtual = max(self._virtual, start)
        self._size -= 1
        self._total_bytes -= nbytes
        self._bytes[sender] -= nbytes
        if not waiting:
            del self._queues[sender], self._bytes[sender]
        # a finish tag at or behind virtual time no longer changes any start tag: forget it (bounded memory)
        for idle in [s for s, f in self._finish.items() if f <= self._virtual and s not in self._queues]:
            del self._finish[idle]
        return item
