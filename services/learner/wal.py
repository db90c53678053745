"""The learner's write-ahead log: accepted messages, durable before they are acknowledged.

Between two checkpoints the learner appends every accepted batch (its encoded
message bytes) here and acknowledges it only afterwards, so a batch an actor
saw acknowledged survives a ``kill -9``: on start the learner loads the newest
checkpoint and replays the records written after it (``checkpoint["wal_seq"]``).

Layout: ``<dir>/wal-<first seq, 16 digits>.log`` segments, each a run of records

    magic b"NLW1" | length u32 | seq u64 | crc32 u32 (zlib, over seq + payload) | payload

with seqs increasing by one. After each checkpoint the log rotates to a new
segment and the older ones are deleted. A torn tail (a crash mid-append) or a
corrupt record (bad magic, length, checksum or seq) ends the log: it is
reported (log line + ``corrupt_records`` / ``cut_bytes``), the file is cut
there and later segments are removed; it never raises.

fsync policy: ``always`` (each append, or once per group of appends made with
``sync=False`` and closed by ``sync()``: a group commit, as databases do), ``<N>``
(at most every N ms, and on rotate/close) or ``never``. A process crash loses nothing written with any of
them (the bytes are in the OS page cache); a machine crash only with ``always``.
"""

from __future__ import annotations

import logging
import os
import re
import struct
import time
import zlib
from collections.abc import Iterator
from pathlib import Path

log = logging.getLogger("navlearn.wal")
MAGIC = b"NLW1"
HEADER = struct.Struct("<4sIQI")
MAX_RECORD = 256 * 1024 * 1024
_SEGMENT = re.compile(r"wal-(\d{16})\.log")


def parse_fsync(policy: str) -> float | None:
    """``always`` -> 0.0, ``never`` -> None, ``<N>`` -> N/1000 seconds between fsyncs."""
    policy = str(policy).strip().lower()
    if policy == "always":
        return 0.0
    if policy == "never":
        return None
    try:
        ms = float(policy)
    except ValueError:
        raise ValueError(f"wal fsync policy must be always, never or milliseconds, got {policy!r}") from None
    if ms < 0:
        raise ValueError(f"wal fsync interval must be >= 0 ms, got {ms}")
    return ms / 1000.0


def encode_record(seq: int, payload: bytes) -> bytes:
    crc = zlib.crc32(payload, zlib.crc32(struct.pack("<Q", seq)))
    return HEADER.pack(MAGIC, len(payload), seq, crc) + payload


class WriteAheadLog:
    """Append-only, checksummed, segmented log under ``directory``; ``open`` reads and repairs it."""

    def __init__(self, directory: str | Path, fsync: str = "always") -> None:
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.fsync_every = parse_fsync(fsync)
        self.last_seq = 0
        """seq of the newest record in the log (0: none yet)"""
        self.counters = {"appended": 0, "corrupt_records": 0, "cut_bytes": 0, "fsyncs": 0}
        self._file = None
        self._last_sync = time.monotonic()
        self._unsynced = False

    # ------------------------------------------------------------------ reading

    def segments(self) -> list[Path]:
        found = [(int(m.group(1)), p) for p in self.dir.iterdir() if (m := _SEGMENT.fullmatch(p.name))]
        return [p for _, p in sorted(found)]

    def recover(self, after: int = 0) -> Iterator[tuple[int, bytes]]:
        """Yield every intact record with seq > ``after`` in order (cutting a torn/corrupt tail), then
        open for appending (new seqs continue after both the log and ``after``). Consume it fully."""
        segments = self.segments()
        expected: int | None = None
        for index, path in enumerate(segments):
            good_end, bad = 0, None
            with open(path, "rb") as fh:
                data = fh.read()
            offset = 0
            while offset < len(data):
                record, reason = self._parse(data, offset, expected)
                if record is None:
                    bad = reason
                    break
                seq, payload, end = record
                expected = seq + 1
                self.last_seq = seq
                offset = good_end = end
                if seq > after:
                    yield seq, payload
            if bad is not None:
                self._cut(path, good_end, len(data), bad, segments[index + 1 :])
                break
        self.last_seq = max(self.last_seq, after)
        self._open_segment()

    def _parse(self, data: bytes, offset: int, expected: int | None):
        if len(data) - offset < HEADER.size:
            return None, "torn header"
        magic, length, seq, crc = HEADER.unpack_from(data, offset)
        if magic != MAGIC:
            return None, "bad magic"
        if length > MAX_RECORD:
            return None, f"length {length} too large"
        start = offset + HEADER.size
        if len(data) - start < length:
            return None, "torn payload"
        payload = data[start : start + length]
        if zlib.crc32(payload, zlib.crc32(struct.pack("<Q", seq))) != crc:
            return None, "checksum mismatch"
        if expected is not None and seq != expected:
            return None, f"seq {seq} where {expected} was expected"
        return (seq, payload, start + length), ""

    def _cut(self, path: Path, good_end: int, size: int, reason: str, later: list[Path]) -> None:
        cut = size - good_end + sum(p.stat().st_size for p in later)
        self.counters["corrupt_records"] += 1
        self.counters["cut_bytes"] += cut
        log.error(
            "write-ahead log %s: %s at byte %d after seq %d; cutting %d bytes (%d later segment(s))",
            path,
            reason,
            good_end,
            self.last_seq,
            cut,
            len(later),
        )
        with open(path, "r+b") as fh:
            fh.truncate(good_end)
            os.fsync(fh.fileno())
        for extra in later:
            extra.unlink(missing_ok=True)

    # ------------------------------------------------------------------ writing

    def _open_segment(self) -> None:
        if self._file is not None:
            self._sync(force=True)
            self._file.close()
        path = self.dir / f"wal-{self.last_seq + 1:016d}.log"
        self._file = open(path, "ab")  # noqa: SIM115 - held open across appends, closed in close()
        _fsync_dir(self.dir)

    def append(self, payload: bytes, sync: bool = True) -> int:
        """Write one record; durable per the fsync policy when this returns, or, with
        ``sync=False``, once ``sync()`` has returned (group commit). Returns its seq."""
        if self._file is None:
            raise RuntimeError("WriteAheadLog.recover() must run before append()")
        seq = self.last_seq + 1
        self._file.write(encode_record(seq, payload))
        self._file.flush()
        self.last_seq = seq
        self.counters["appended"] += 1
        self._unsynced = True
        if sync:
            self._sync()
        return seq

    def sync(self) -> None:
        """Make the appends made with ``sync=False`` durable per the fsync policy (one fsync for all)."""
        if self._unsynced:
            self._sync()

    def _sync(self, force: bool = False) -> None:
        if self._file is None or (self.fsync_every is None and not force):
            return
        now = time.monotonic()
        if force or now - self._last_sync >= (self.fsync_every or 0.0):
            os.fsync(self._file.fileno())
            self._last_sync = now
            self._unsynced = False
            self.counters["fsyncs"] += 1

    def rotate(self) -> None:
        """After a checkpoint holding everything up to ``last_seq``: new segment, older ones deleted."""
        self._open_segment()
        current = self.segments()[-1]
        for old in self.segments():
            if old != current:
                old.unlink(missing_ok=True)

    def close(self) -> None:
        if self._file is not None:
            self._sync(force=True)
            self._file.close()
            self._file = None


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
