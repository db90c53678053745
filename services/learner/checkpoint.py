"""Atomic, rotated, checksummed checkpoint directories: ``<root>/ckpt-00000042/``.

A checkpoint is written into a hidden temporary directory next to the final
ones, its files are checksummed into ``manifest.json`` (size and SHA-256 of
every file) and flushed to disk, then the directory is renamed into place: on
POSIX a rename is atomic, so a directory named ``ckpt-*`` is always complete and
a crash mid-write only leaves a ``.tmp-*`` directory, which the writer removes
when it starts again (:meth:`CheckpointDir.remove_unfinished`; readers never
touch it, since the writer may still be filling it). The newest ``keep``
checkpoints are kept; older ones are deleted after a new one is in place.

Before writing, :meth:`CheckpointDir.save` checks that the file system has room
for the checkpoint (the caller's estimate, and at least the size of the last
one), so a full disk is an ``OSError`` (ENOSPC) raised before anything is
written, never a SIGBUS from a memory-mapped write. Before use,
:meth:`CheckpointDir.newest_intact` checks every file against the manifest
(missing, extra, truncated, changed); damaged checkpoints newer than the newest
intact one are renamed ``damaged-ckpt-*`` and logged with the file and the
reason. If none is intact it raises and renames nothing, so an operator decides.
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path

log = logging.getLogger("navlearn.checkpoint")
_NAME = re.compile(r"ckpt-(\d{8})")
_TMP_PREFIX = ".tmp-ckpt-"
DAMAGED_PREFIX = "damaged-"
MANIFEST = "manifest.json"
FORMAT = "navlearn-checkpoint/1"
SPACE_MARGIN = 1 << 20
"""bytes kept free beyond a checkpoint's estimated size"""


class CheckpointDamaged(ValueError):
    """A checkpoint whose files do not match its manifest (the message names the file and why)."""


class NoIntactCheckpoint(ValueError):
    """Checkpoints exist but every one is damaged: resuming would silently start afresh."""


def _digest(path: Path) -> str:
    sha = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            sha.update(chunk)
    return sha.hexdigest()


def _files(path: Path) -> list[Path]:
    return sorted(p for p in path.rglob("*") if p.is_file() and p.name != MANIFEST)


def write_manifest(path: Path) -> int:
    """Checksum and flush every file under ``path`` into ``path/manifest.json``; returns total bytes."""
    files = {}
    for file in _files(path):
        with open(file, "rb") as fh:
            os.fsync(fh.fileno())
        files[file.relative_to(path).as_posix()] = {"size": file.stat().st_size, "sha256": _digest(file)}
    (path / MANIFEST).write_text(json.dumps({"format": FORMAT, "files": files}, indent=1) + "\n")
    with open(path / MANIFEST, "rb") as fh:
        os.fsync(fh.fileno())
    for directory in sorted({p.parent for p in _files(path)} | {path}, key=lambda p: -len(p.parts)):
        _fsync_dir(directory)
    return sum(f["size"] for f in files.values())


def verify(path: Path) -> int:
    """Check every file of checkpoint ``path`` against its manifest; returns its size in bytes.
    Raises CheckpointDamaged naming the first file that differs and how."""
    try:
        manifest = json.loads((path / MANIFEST).read_text())
        listed = manifest["files"]
        if manifest.get("format") != FORMAT or not isinstance(listed, dict):
            raise ValueError(f"not a {FORMAT} manifest")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CheckpointDamaged(f"{path / MANIFEST}: unreadable ({exc})") from None
    present = {p.relative_to(path).as_posix() for p in _files(path)}
    for extra in sorted(present - set(listed)):
        raise CheckpointDamaged(f"{path / extra}: not in the manifest")
    for name, entry in sorted(listed.items()):
        file = path / name
        if name not in present:
            raise CheckpointDamaged(f"{file}: missing")
        size = file.stat().st_size
        if size != entry.get("size"):
            raise CheckpointDamaged(f"{file}: {size} bytes, the manifest says {entry.get('size')}")
        if _digest(file) != entry.get("sha256"):
            raise CheckpointDamaged(f"{file}: checksum differs from the manifest")
    return sum(int(e["size"]) for e in listed.values())


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
        self.last_size = 0
        """bytes of the last checkpoint written or verified (the floor of the next one's estimate)"""

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

    def newest_intact(self) -> Path | None:
        """The newest checkpoint whose files match its manifest (None if there is none at all).
        Damaged newer ones are renamed ``damaged-ckpt-*`` and logged; if every one is damaged,
        raises NoIntactCheckpoint and renames nothing."""
        damaged: list[tuple[Path, str]] = []
        for path in reversed(self.all()):
            try:
                self.last_size = verify(path)
            except CheckpointDamaged as exc:
                damaged.append((path, str(exc)))
                continue
            for bad, reason in damaged:
                aside, n = bad.with_name(DAMAGED_PREFIX + bad.name), 0
                while aside.exists():  # a number reused after an earlier one was set aside
                    n += 1
                    aside = bad.with_name(f"{DAMAGED_PREFIX}{bad.name}.{n}")
                os.rename(bad, aside)
                log.error(
                    "checkpoint %s is damaged (%s); set aside as %s, resuming from %s",
                    bad,
                    reason,
                    aside,
                    path,
                )
            return path
        if damaged:
            reasons = "; ".join(f"{p.name}: {r}" for p, r in damaged)
            raise NoIntactCheckpoint(
                f"no intact checkpoint in {self.root} ({reasons}). Resuming would start afresh: "
                "move the directory away (or pass --resume false) to do that knowingly"
            )
        return None

    def save(self, write: Callable[[Path], None], estimate: int = 0) -> Path:
        """Check there is room for ``estimate`` bytes (and the last checkpoint's size), call
        ``write(tmp_dir)`` to fill a new checkpoint, checksum it, publish it atomically and rotate.
        A full file system raises OSError(ENOSPC) naming the directory, before or while writing."""
        need = max(int(estimate), self.last_size) + SPACE_MARGIN
        free = shutil.disk_usage(self.root).free
        if free < need:
            raise OSError(
                errno.ENOSPC,
                f"{free} bytes free, a checkpoint needs about {need}; not written",
                str(self.root),
            )
        existing = self.all()
        number = int(_NAME.fullmatch(existing[-1].name).group(1)) + 1 if existing else 1
        final = self.root / f"ckpt-{number:08d}"
        tmp = self.root / f"{_TMP_PREFIX}{number:08d}-{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        try:
            write(tmp)
            self.last_size = write_manifest(tmp)
            os.rename(tmp, final)
            _fsync_dir(self.root)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        for old in self.all()[: -self.keep]:
            shutil.rmtree(old, ignore_errors=True)
        return final
