"""Duplicate detection by (sender, seq) for at-least-once delivery.

An actor resends a batch whose acknowledgement it did not see (lost with a
killed learner, or a timeout), so the learner may receive it twice. Per sender
(an actor incarnation, ``<id>#<start time>``) this keeps the highest contiguous
seq seen and a bounded set of seqs above it; senders not heard from for long
are forgotten once more than ``max_senders`` exist. The state goes into each
checkpoint and is rebuilt from the write-ahead log replay.
"""

from __future__ import annotations

from collections import OrderedDict


class Deduplicator:
    """``seen(sender, seq)``: True for a duplicate, else records it and returns False."""

    def __init__(self, max_senders: int = 4096, max_gaps: int = 4096) -> None:
        self.max_senders = max_senders
        self.max_gaps = max_gaps
        self._state: OrderedDict[str, tuple[int, set[int]]] = OrderedDict()

    def seen(self, sender: str, seq: int) -> bool:
        if seq < 1:  # unnumbered (seqs start at 1): nothing to recognise it by
            return False
        floor, above = self._state.get(sender, (0, set()))
        if seq <= floor or seq in above:
            self._state.move_to_end(sender)
            return True
        above = set(above)
        above.add(seq)
        while floor + 1 in above:
            floor += 1
            above.discard(floor)
        if len(above) > self.max_gaps:  # a sender that skips seqs for ever: keep the newest ones
            drop = sorted(above)[: len(above) - self.max_gaps]
            floor = drop[-1]
            above = {s for s in above if s > floor}
        self._state[sender] = (floor, above)
        self._state.move_to_end(sender)
        while len(self._state) > self.max_senders:
            self._state.popitem(last=False)
        return False

    def forget(self, sender: str, seq: int) -> None:
        """Undo ``seen(sender, seq)`` (its batch was not stored after all: a failed write)."""
        if sender not in self._state or seq < 1:
            return
        floor, above = self._state[sender]
        above = set(above)
        if seq in above:
            above.discard(seq)
        elif seq <= floor:
            above.update(range(seq + 1, floor + 1))
            floor = seq - 1
        self._state[sender] = (floor, above)

    def state(self) -> dict[str, list]:
        return {s: [floor, sorted(above)] for s, (floor, above) in self._state.items()}

    def load_state(self, state: dict[str, list]) -> None:
        self._state = OrderedDict((s, (int(f), {int(x) for x in a})) for s, (f, a) in state.items())
