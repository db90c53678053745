"""Duplicate detection for at-least-once delivery: by (sender, seq), and by content.

An actor resends a batch whose acknowledgement it did not see (lost with a
killed learner, or a timeout), so the learner may receive it twice. Per sender
(an actor incarnation, ``<id>#<start time>``) this keeps the highest contiguous
seq seen and a bounded set of seqs above it; senders not heard from for long
are forgotten once more than ``max_senders`` exist. The state goes into each
checkpoint and is rebuilt from the write-ahead log replay.

The envelope's ``sender`` is what the batch says of itself: a copy of an acknowledged batch with
a rewritten sender is a new (sender, seq). So the learner also recognises a batch by its
content (``content_digest``, ``ContentIndex``): stored once, whatever the sender field says.
"""

from __future__ import annotations

import base64
import hashlib
from collections import OrderedDict

import numpy as np


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


def content_digest(message) -> bytes:
    """A batch's content identity: 16 bytes of BLAKE2b over its kind and every array it carries
    (name, dtype, shape, bytes), not its envelope (``sender``, ``seq``): a resend, or a copy with a
    rewritten sender, has the same digest. Two different batches of an actor never share one
    (they differ in observations drawn from noisy sensors, or in their robots' ids)."""
    h = hashlib.blake2b(message.KIND.encode(), digest_size=DIGEST_BYTES)
    for name, value in vars(message).items():
        if isinstance(value, np.ndarray):
            h.update(f"|{name}|{value.dtype.str}|{value.shape}|".encode())
            h.update(np.ascontiguousarray(value).tobytes())
    return h.digest()


DIGEST_BYTES = 16


class ContentIndex:
    """The digests (``content_digest``) of the last ``capacity`` batches stored, oldest forgotten
    first: ``seen(digest)`` is True for a batch stored already, whatever its sender says.

    Bounded: 65,536 digests (about 7 MB here, 1 MB in a checkpoint) reach back well past what a
    replay of the default 100,000 transitions holds; a copy of an older batch is taken again.
    """

    def __init__(self, capacity: int = 65_536) -> None:
        self.capacity = capacity
        self._digests: OrderedDict[bytes, None] = OrderedDict()

    def seen(self, digest: bytes) -> bool:
        if digest in self._digests:
            return True
        self._digests[digest] = None
        while len(self._digests) > self.capacity:
            self._digests.popitem(last=False)
        return False

    def forget(self, digest: bytes) -> None:
        """Undo ``seen(digest)`` (its batch was not stored after all: a failed write)."""
        self._digests.pop(digest, None)

    def state(self) -> str:
        """The digests, oldest first, as one base64 string (for the checkpoint's JSON)."""
        return base64.b64encode(b"".join(self._digests)).decode()

    def load_state(self, state: str) -> None:
        raw = base64.b64decode(state)
        digests = [raw[k : k + DIGEST_BYTES] for k in range(0, len(raw), DIGEST_BYTES)]
        self._digests = OrderedDict.fromkeys(digests[-self.capacity :])
