"""Durable, de-duplicated ingest for the learner: write-ahead log + de-duplication by (sender, seq)
and by content (services.learner.dedup).

The learner calls ``admit`` for every decoded batch before inserting it: a
duplicate (an actor's resend of a batch already stored) is counted and must
only be acknowledged again; anything else is appended to the write-ahead log
(the bytes the learner received and accepted, not a re-encoding) and synced
(``sync``) before it is inserted and acknowledged, so an acknowledgement means "durably stored".
If the append or the sync fails (OSError: a full disk), the log is cut back to the
last synced group and the duplicate filter forgets that group, so the actors' resends
of it are taken as new once the disk has room again.
``checkpoint_state`` goes into each checkpoint (the log position and the
de-duplication state); ``checkpointed`` then rotates the log. On start,
``load_state`` (from the checkpoint, if any) and ``replay`` give back the
batches accepted after that checkpoint, which the learner inserts again
without logging them twice, decoded with the learner's own limits.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import DemoBatch, Message, TransitionBatch
from services.learner.dedup import ContentIndex, Deduplicator, content_digest
from services.learner.wal import WriteAheadLog

log = logging.getLogger("navlearn.durable")


@dataclass
class Replayed:
    """A batch read back from the log: its channel (transitions/demos) and the key's name."""

    channel: str
    name: str
    message: Message


def dedup_key(message: Message) -> str:
    """``<actor or source>/<envelope sender>``: an incarnation (``<id>#<start>``) on its own key."""
    name = message.actor if isinstance(message, TransitionBatch) else getattr(message, "source", "")
    return f"{name}/{message.sender}"


class DurableIngest:
    """The learner's write-ahead log and duplicate filter (one per learner process)."""

    def __init__(self, directory: str | Path, fsync: str = "always", limits: Limits | None = None) -> None:
        self.wal = WriteAheadLog(directory, fsync)
        self.dedup = Deduplicator()
        self.content = ContentIndex()
        self.limits = limits or Limits()
        self.checkpoint_seq = 0
        self._group: list[tuple[str, int, bytes]] = []  # dedup keys and digests admitted since the last sync
        self.counters = {
            "duplicates_dropped": 0,
            "duplicates_by_content": 0,
            "wal_replayed": 0,
            "wal_undecodable": 0,
        }

    def admit(self, message: Message, payload: bytes) -> bool:
        """False for a duplicate (counted): a (sender, seq) seen before, or content stored before under
        another sender (also counted as ``duplicates_by_content``); else log ``payload`` (the accepted
        bytes of ``message``) and return True. It is durable once ``sync()`` has returned: one fsync
        for the group of batches admitted before it. OSError: nothing of the group is logged (see
        ``sync``)."""
        key = dedup_key(message)
        if self.dedup.seen(key, message.seq):
            self.counters["duplicates_dropped"] += 1
            return False
        digest = content_digest(message)
        if self.content.seen(digest):
            self.dedup.forget(key, message.seq)  # not stored under this (sender, seq) either
            self.counters["duplicates_dropped"] += 1
            self.counters["duplicates_by_content"] += 1
            return False
        self._group.append((key, message.seq, digest))
        try:
            self.wal.append(payload, sync=False)
        except OSError:
            self._forget_group()
            raise
        return True

    def sync(self) -> None:
        """Make the group durable; on OSError the log holds none of it and the filter forgets it."""
        try:
            self.wal.sync()
        except OSError:
            self._forget_group()
            raise
        self._group.clear()

    def _forget_group(self) -> None:
        for key, seq, digest in self._group:
            self.dedup.forget(key, seq)
            self.content.forget(digest)
        self._group.clear()

    @property
    def path(self) -> Path:
        """The log's directory (named in storage errors)."""
        return self.wal.dir

    def checkpoint_state(self) -> dict:
        return {
            "wal_seq": self.wal.last_seq,
            "dedup": self.dedup.state(),
            "content": self.content.state(),
            "counters": self.counters,
        }

    def checkpointed(self, keep_after: int | None = None) -> None:
        """The checkpoint holding ``checkpoint_state()`` is in place: start a new log segment, keeping
        the records after ``keep_after`` (the oldest checkpoint still kept) for a resume from it."""
        self.checkpoint_seq = self.wal.last_seq
        self.wal.rotate(keep_after)

    def load_state(self, state: dict | None) -> None:
        if state:
            self.checkpoint_seq = int(state["wal_seq"])
            self.dedup.load_state(state["dedup"])
            self.content.load_state(state.get("content", ""))  # absent from older checkpoints
            self.counters.update({k: int(v) for k, v in state.get("counters", {}).items()})

    def replay(self) -> Iterator[Replayed]:
        """The batches logged after the loaded checkpoint, in order (de-duplication state rebuilt)."""
        for seq, payload in self.wal.recover(after=self.checkpoint_seq):
            try:
                message = decode(payload, self.limits)
            except ProtocolError as exc:  # accepted under these limits, so only if they or the format changed
                self.counters["wal_undecodable"] += 1
                log.error("write-ahead log record %d does not decode (%s); skipped", seq, exc)
                continue
            if isinstance(message, TransitionBatch):
                channel, name = "transitions", message.actor
            elif isinstance(message, DemoBatch):
                channel, name = "demos", message.source
            else:
                continue
            self.dedup.seen(dedup_key(message), message.seq)
            self.content.seen(content_digest(message))
            self.counters["wal_replayed"] += 1
            yield Replayed(channel, name, message)

    def status_counters(self) -> dict[str, int]:
        wal = self.wal.counters
        return {
            **self.counters,
            "wal/appended": wal["appended"],
            "wal/corrupt_records": wal["corrupt_records"],
            "wal/skipped_records": wal["skipped_records"],
            "wal/skipped_bytes": wal["skipped_bytes"],
            "wal/cut_bytes": wal["cut_bytes"],
            "wal/fsyncs": wal["fsyncs"],
            "wal/seq": self.wal.last_seq,
        }

    def close(self) -> None:
        self.wal.close()
