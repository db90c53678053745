"""Files that hold secrets (passwords, private keys): written 0600, whether or not they existed.

``os.open(path, O_CREAT, 0o600)`` sets the mode only when it creates the file: over an
existing 0644 file the new secret would stay readable by everyone. ``write_private``
writes a fresh 0600 temporary file (``mkstemp``) next to the target and renames it
over the target, so the secret is never in a file with another mode, and a crash
leaves the old file or the new one, never half of one.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def write_private(path: str | Path, data: bytes | str) -> None:
    """Replace ``path`` with ``data`` in a file only its owner can read or write (0600)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")  # created 0600
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
