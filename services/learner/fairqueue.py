"""A bounded queue with a bound per sender, served round-robin: one flooding actor cannot crowd out
the others or grow the learner's memory.

``put_nowait`` raises ``SenderFull`` when that sender already has ``per_sender``
items waiting and ``queue.Full`` when all senders together hold ``capacity``;
``get``/``get_nowait`` take the oldest item of the next sender in turn, so every
sender gets the same share of the learner's ingest however fast it sends.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import OrderedDict, deque
from typing import Generic, TypeVar

T = TypeVar("T")


class SenderFull(queue.Full):
    """This sender's share of the queue is full (others may still have room)."""


class FairQueue(Generic[T]):
    """Per-sender FIFO queues, at most ``per_sender`` items each and ``capacity`` in all."""

    def __init__(self, capacity: int, per_sender: int) -> None:
        if capacity < 1 or per_sender < 1:
            raise ValueError("capacity and per_sender must be >= 1")
        self.capacity = capacity
        self.per_sender = per_sender
        self._queues: OrderedDict[str, deque[T]] = OrderedDict()
        self._size = 0
        self._ready = threading.Condition()

    def qsize(self) -> int:
        with self._ready:
            return self._size

    def sender_full(self, sender: str) -> bool:
        """Has ``sender`` its ``per_sender`` items waiting (so ``put_nowait`` would raise SenderFull)?"""
        with self._ready:
            return self._full(self._queues.get(sender))

    def _full(self, waiting: deque[T] | None) -> bool:
        return waiting is not None and len(waiting) >= self.per_sender

    def put_nowait(self, sender: str, item: T) -> None:
        with self._ready:
            waiting = self._queues.get(sender)
            if self._full(waiting):
                raise SenderFull(sender)
            if self._size >= self.capacity:
                raise queue.Full
            if waiting is None:
                waiting = self._queues[sender] = deque()
            waiting.append(item)
            self._size += 1
            self._ready.notify()

    def get_nowait(self) -> T:
        with self._ready:
            return self._take()

    def get(self, timeout: float | None = None) -> T:
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._ready:
            while self._size == 0:
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    raise queue.Empty
                self._ready.wait(remaining)
            return self._take()

    def _take(self) -> T:
        if self._size == 0:
            raise queue.Empty
        sender, waiting = next(iter(self._queues.items()))
        item = waiting.popleft()
        self._size -= 1
        del self._queues[sender]
        if waiting:  # back of the line: the next sender goes first next time
            self._queues[sender] = waiting
        return item
