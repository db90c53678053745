"""The learner's disk health: what to do when writing the write-ahead log or a checkpoint fails.

A full disk (ENOSPC), a read-only remount or an I/O error must neither kill the
learner (it holds the replay in memory) nor let it acknowledge what it could not
store. On a failure the service calls ``failed``: one log line names what was being
written, the path and the error; acknowledgements stop (``blocked()`` is true while
it waits; the batches stay with their actors, which resend them); the status shows
``storage_error 1``; and after a back-off (1 s, doubling to ``longest``) the service
tries again. The first write that works calls ``succeeded``, which logs the recovery.
No clocks or threads of its own: the caller passes ``now`` (``time.monotonic()``).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

log = logging.getLogger("navlearn.storage")


class StorageGuard:
    """Failure state of the learner's writes, with exponential back-off between retries."""

    def __init__(self, first: float = 1.0, longest: float = 30.0) -> None:
        self.first = first
        self.longest = longest
        self.error: str | None = None
        """what failed and why (None: healthy)"""
        self.what = ""
        """"write-ahead log" or "checkpoint": what failed last"""
        self.failures = 0
        self.retry_at = 0.0
        self._delay = first
        self._streak = 0

    def failed(self, what: str, path: object, exc: BaseException, now: float) -> None:
        """Writing ``what`` at ``path`` raised ``exc``: stop acknowledging until ``retry_at``."""
        self.failures += 1
        self._streak += 1
        error = f"{what} {path}: {type(exc).__name__}: {exc}"
        if self._streak == 1:
            log.error(
                "storage error writing the %s; acknowledgements stopped, retrying in %.0f s",
                error,
                self._delay,
            )
        else:
            log.warning(
                "storage still failing (attempt %d): %s; next in %.0f s", self._streak, error, self._delay
            )
        self.error, self.what = error, what
        self.retry_at = now + self._delay
        self._delay = min(self._delay * 2, self.longest)

    def blocked(self, now: float) -> bool:
        """True while a failure waits for its retry (nothing is taken in or acknowledged)."""
        return self.error is not None and now < self.retry_at

    def due(self, now: float, scheduled: float) -> bool:
        """Is a write scheduled for ``scheduled`` (a periodic checkpoint) to be tried at ``now``? Not
        while a failure waits for its retry: a periodic write tried sooner would fail again and
        push the back-off on, so the retries would follow the period, not the schedule the log
        announced ("retrying in 1 s", "next in 2 s", 4, 8, ... ``longest``)."""
        return now >= scheduled and not self.blocked(now)

    def succeeded(self) -> None:
        """A write worked: acknowledge again."""
        if self.error is not None:
            log.info("storage recovered after %d failed attempt(s): writing again", self._streak)
        self.error, self.what, self._streak, self._delay = None, "", 0, self.first

    def counters(self) -> dict[str, int]:
        return {"storage_error": int(self.error is not None), "storage_failures": self.failures}


def fsync_dir(path: Path) -> None:
    """Make a directory's entries durable (a file created or renamed in it survives a crash)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
