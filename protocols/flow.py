"""Flow control on the wire: the learner's acknowledgement of an actor's transition batches.

The learner acknowledges every batch it inserts into replay on ``acks/<actor>``.
An actor keeps at most a window of unacknowledged batches in flight, so a learner
whose rate limiter holds inserts back slows its actors down instead of dropping
their data (Reverb's blocking inserts, over the network). Importing this module
registers the ``ack`` kind with the codec.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from protocols.messages import Message, register
from protocols.schema import count, text


@register
@dataclass(kw_only=True, eq=False)
class Ack(Message):
    """The newest transition batch of ``actor`` the learner accepted into replay."""

    KIND: ClassVar[str] = "ack"
    VERSION: ClassVar[int] = 1
    actor: str = text()
    """The batch's envelope sender (the actor incarnation, ``<id>#<start>``): a restarted actor
    ignores acknowledgements meant for its predecessor's seqs."""
    accepted_seq: int = count()
    """Envelope ``seq`` of that batch."""
    policy_version: int = count()
    """The learner's policy version when it accepted the batch."""


__all__ = ["Ack"]
