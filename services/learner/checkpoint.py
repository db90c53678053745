"""Atomic, rotated checkpoint directories: ``<root>/ckpt-00000042/``.

A checkpoint is written into a hidden temporary directory next to the final
ones, flushed to disk, then renamed into place: on POSIX a rename is atomic,
so a directory named ``ckpt-*`` is always complete and a crash mid-write only
leaves a ``.tmp-*`` directory, which the writer removes when it starts again
(:meth:`CheckpointDir.remove_unfinished`; readers never touch it, since the
writer may still be filling it). The newest ``keep``
checkpoints are kept; older ones are deleted after a new one is in place.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path

log = logging.getLogger("navlearn.checkpoint")
_NAME = re.compile(r"ckpt-(\d{8})")
_TMP_PREFIX = ".tmp-ckpt-"


def _fsync_tree(path: Path) -> None:
    """Flush every file and directory under ``path`` (then the directory itself)."""
    for dirpath, _dirnames, filenames in os.walk(path):
        for name in filenames:
            with open(os.path.join(dirpath, name), "rb") as fh:
                os.fsync(fh.fileno())
        _fsync_dir(Path(dirpath))


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class CheckpointDir:
    """The checkpoints of one service under ``root``, newest last."""

    def __init__(self, root: str | Path, keep: int = 3) -> None:
        if keep < 1:
            raise ValueError(f"keep must be >= 1, got {keep}")
        self.root = Path(root)
        self.keep = keep
        self.root.mkdir(parents=True, exist_ok=True)

    def remove_unfinished(self) -> None:
        """Delete temporary directories left by a writer that crashed. Only the writer calls this."""
        for leftover in self.root.glob(_TMP_PREFIX + "*"):
            log.warning("removing unfinished checkpoint %s", leftover)
            shutil.rmtree(leftover, ignore_errors=True)

    def all(self) -> list[Path]:
        """Complete checkpoints, oldest first."""
        found = [(int(m.group(1)), p) for p in self.root.iterdir() if (m := _NAME.fullmatch(p.name))]
        return [p for _, p in sorted(found)]

    def latest(self) -> Path | None:
        checkpoints = self.all()
        return checkpoints[-1] if checkpoints else None

    def save(self, write: Callable[[Path], None]) -> Path:
        """Call ``write(tmp_dir)`` to fill a new checkpoint, then publish it atomically and rotate."""
        existing = self.all()
        number = int(_NAME.fullmatch(existing[-1].name).group(1)) + 1 if existing else 1
        final = self.root / f"ckpt-{number:08d}"
        tmp = self.root / f"{_TMP_PREFIX}{number:08d}-{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        try:
            write(tmp)
            _fsync_tree(tmp)
            os.rename(tmp, final)
            _fsync_dir(self.root)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        for old in self.all()[: -self.keep]:
            shutil.rmtree(old, ignore_errors=True)
        return final
