"""One writer per directory: an exclusive OS lock (``fcntl.flock``) held for a process's lifetime.

A learner's checkpoints, write-ahead log and (under ``navlearn up``) its log file belong to one
process: a second learner on the same directory would replay the first one's log, write stale
checkpoints beside its own and append to its log. So the learner locks its checkpoint
directory and ``navlearn up`` its run directory before touching anything there. The lock is the
kernel's, on an open file: it goes with the process (exit, crash, SIGKILL), so there is never a
stale lock to clear by hand; the file keeps the holder's pid, only for the refusal's message.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path


class DirectoryInUse(ValueError):
    """Another live process holds the directory's lock (its pid in ``holder``, or None if unknown); a
    ValueError, so commands refuse it like any bad argument (exit code 2)."""

    def __init__(self, message: str, holder: int | None) -> None:
        super().__init__(message)
        self.holder = holder


class DirLock:
    """The exclusive lock on ``directory`` (file ``<directory>/<name>``), taken at once or refused.

    ``what`` names the directory in the refusal (e.g. "checkpoint directory") and ``way_out`` says
    what to do instead (e.g. "give another --checkpoint-dir").
    """

    def __init__(self, directory: str | Path, name: str, what: str, way_out: str) -> None:
        self.path = Path(directory) / name
        self.what = what
        self.way_out = way_out
        self._fd: int | None = None

    def acquire(self) -> DirLock:
        """Take the lock or raise DirectoryInUse naming the holder's pid and the way out."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_pid(fd)
            os.close(fd)
            who = f"process {holder}" if holder else "another process"
            raise DirectoryInUse(
                f"{self.what} {self.path.parent} is in use by {who} (it holds {self.path}); "
                f"stop that one first, or {self.way_out}",
                holder,
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the lock
            self._fd = None

    def __enter__(self) -> DirLock:
        return self.acquire()

    def __exit__(self, *_exc: object) -> None:
        self.release()


def holder_pid(directory: str | Path, name: str) -> int | None:
    """The pid of the live process holding ``<directory>/<name>``'s lock, or None if nobody holds it."""
    path = Path(directory) / name
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_pid(fd) or -1
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _read_pid(fd: int) -> int | None:
    try:
        return int(os.pread(fd, 32, 0).decode().strip() or 0) or None
    except (OSError, ValueError):
        return None
