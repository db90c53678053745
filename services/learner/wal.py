"""The learner's write-ahead log: accepted messages, durable before they are acknowledged.

Between two checkpoints the learner appends every accepted batch (its encoded
message bytes) here and acknowledges it only afterwards, so a batch an actor
saw acknowledged survives a ``kill -9``: on start the learner loads the newest
checkpoint and replays the records written after it (``checkpoint["wal_seq"]``).

Layout: ``<dir>/wal-<first seq, 16 digits>.log`` segments, each a run of records

    magic b"NLW1" | length u32 | seq u64 | crc32 u32 (zlib, over seq + payload) | payload

with seqs increasing by one (the format of every navlearn write-ahead log so far). After
each checkpoint the log rotates to a new segment; segments whose records are all
older than the oldest checkpoint still kept are deleted, so resuming from an older
checkpoint (the newest one damaged) still finds every record written after it.

Reading resynchronises: a damaged record (bad magic, length or checksum) is skipped
by searching forward for the next magic that starts an intact record, so one flipped
bit loses one record, not the rest of the log. What was skipped is logged (file,
byte offset, reason) and counted: ``corrupt_records`` damaged places, ``skipped_records``
records lost there (the gap in seqs), ``skipped_bytes``; a damaged or torn end of the
newest segment (a crash mid-append) is cut (``cut_bytes``). Reading never raises.

A write or sync that fails (a full disk: ENOSPC, EIO) raises OSError after cutting the
log back to the end of the last group that was synced, so the log holds only whole
records and none of the group that failed (none of it acknowledged); the caller
retries those batches later or lets the actors resend them.

fsync policy: ``always`` (each append, or once per group of appends made with
``sync=False`` and closed by ``sync()``: a group commit, as databases do), ``<N>``
(at most every N ms, and on rotate/close) or ``never``. A process crash loses nothing written with any of
them (the bytes are in the OS page cache); a machine crash only with ``always``.
"""

from __future__ import annotations

import itertools
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
    """Append-only, checksummed, segmented log under ``directory``; ``recover`` reads and repairs it."""

    def __init__(self, directory: str | Path, fsync: str = "always") -> None:
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.fsync_every = parse_fsync(fsync)
        self.last_seq = 0
        """seq of the newest record in the log (0: none yet)"""
        self.counters = {
            "appended": 0,
            "corrupt_records": 0,
            "skipped_records": 0,
            "skipped_bytes": 0,
            "cut_bytes": 0,
            "fsyncs": 0,
        }
        self._fd: int | None = None
        self._path: Path | None = None
        self._size = 0  # bytes of whole records in the current segment
        self._committed = (0, 0)  # (size, last_seq) at the end of the last group that synced
        self._last_sync = time.monotonic()
        self._unsynced = False

    # ------------------------------------------------------------------ reading

    def segments(self) -> list[Path]:
        found = [(int(m.group(1)), p) for p in self.dir.iterdir() if (m := _SEGMENT.fullmatch(p.name))]
        return [p for _, p in sorted(found)]

    def recover(self, after: int = 0) -> Iterator[tuple[int, bytes]]:
        """Yield every intact record with seq > ``after`` in order (skipping damaged ones, cutting a
        torn tail), then open for appending (new seqs continue after both the log and ``after``).
        Consume it fully."""
        segments = self.segments()
        expected = after + 1 if after else None
        for index, path in enumerate(segments):
            data = path.read_bytes()
            offset = 0
            while offset < len(data):
                record, reason = _parse(data, offset)
                if record is None:
                    found = _resync(data, offset + 1)
                    if found is None and index == len(segments) - 1:
                        self._cut(path, offset, len(data), reason)
                        break
                    end = len(data) if found is None else found
                    self._skipped(path, offset, end - offset, reason)
                    offset = end
                    continue
                seq, payload, offset = record
                if seq <= after or (expected is not None and seq < expected):
                    self.last_seq = max(self.last_seq, seq)
                    continue  # before the checkpoint (kept for an older one), or a stale copy
                if expected is not None and seq > expected:
                    self.counters["skipped_records"] += seq - expected
                    log.error(
                        "write-ahead log %s: records %d..%d are missing (lost in damage); continuing at %d",
                        path, expected, seq - 1, seq,
                    )  # fmt: skip
                expected = seq + 1
                self.last_seq = seq
                yield seq, payload
        self.last_seq = max(self.last_seq, after)
        self._open_segment()

    def _skipped(self, path: Path, offset: int, length: int, reason: str) -> None:
        self.counters["corrupt_records"] += 1
        self.counters["skipped_bytes"] += length
        log.error(
            "write-ahead log %s: %s at byte %d; skipped %d bytes to the next intact record",
            path, reason, offset, length,
        )  # fmt: skip

    def _cut(self, path: Path, good_end: int, size: int, reason: str) -> None:
        self.counters["corrupt_records"] += 1
        self.counters["cut_bytes"] += size - good_end
        log.error(
            "write-ahead log %s: %s at byte %d after seq %d (a torn or damaged end); cutting %d bytes",
            path, reason, good_end, self.last_seq, size - good_end,
        )  # fmt: skip
        with open(path, "r+b") as fh:
            fh.truncate(good_end)
            os.fsync(fh.fileno())

    # ------------------------------------------------------------------ writing

    def _open_segment(self) -> None:
        """Start ``wal-<last_seq + 1>.log``; the current segment stays in use if that fails."""
        self._sync(force=True)
        path = self.dir / f"wal-{self.last_seq + 1:016d}.log"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        try:
            _fsync_dir(self.dir)
        except OSError:
            os.close(fd)
            raise
        if self._fd is not None:
            os.close(self._fd)
        self._fd, self._path = fd, path
        self._size = os.fstat(fd).st_size
        self._committed = (self._size, self.last_seq)

    def append(self, payload: bytes, sync: bool = True) -> int:
        """Write one record; durable per the fsync policy when this returns, or, with
        ``sync=False``, once ``sync()`` has returned (group commit). Returns its seq.
        On OSError the log is cut back to the last synced group (see the module docstring)."""
        if self._fd is None:
            raise RuntimeError("WriteAheadLog.recover() must run before append()")
        seq = self.last_seq + 1
        record = memoryview(encode_record(seq, payload))
        try:
            while record:
                record = record[os.write(self._fd, record) :]
        except OSError:
            self._roll_back()
            raise
        self._size += HEADER.size + len(payload)
        self.last_seq = seq
        self.counters["appended"] += 1
        self._unsynced = True
        if sync:
            self.sync()
        return seq

    def sync(self) -> None:
        """Make the appends made with ``sync=False`` durable per the fsync policy (one fsync for all)."""
        if self._unsynced:
            try:
                self._sync()
            except OSError:
                self._roll_back()
                raise
        self._committed = (self._size, self.last_seq)

    def _roll_back(self) -> None:
        """Cut the segment back to the end of the last synced group (whole records only)."""
        size, seq = self._committed
        try:
            os.ftruncate(self._fd, size)
        except OSError as exc:  # the reader skips a partial record anyway
            log.error("write-ahead log %s: could not cut back to byte %d (%s)", self._path, size, exc)
        self._size, self.last_seq, self._unsynced = size, seq, False

    def _sync(self, force: bool = False) -> None:
        if self._fd is None or (self.fsync_every is None and not force):
            return
        now = time.monotonic()
        if force or now - self._last_sync >= (self.fsync_every or 0.0):
            os.fsync(self._fd)
            self._last_sync = now
            self._unsynced = False
            self.counters["fsyncs"] += 1

    def rotate(self, keep_after: int | None = None) -> None:
        """After a checkpoint holding everything up to ``last_seq``: start a new segment and delete
        the segments whose records all have seq <= ``keep_after`` (the position of the oldest
        checkpoint still kept; default ``last_seq``: every older segment)."""
        self._open_segment()
        keep_after = self.last_seq if keep_after is None else keep_after
        segments = self.segments()
        for old, newer in itertools.pairwise(segments):
            if old != self._path and _first_seq(newer) - 1 <= keep_after:
                old.unlink(missing_ok=True)

    def close(self) -> None:
        """Sync and close; a failing sync is logged (the caller is stopping), never raised."""
        if self._fd is not None:
            try:
                self._sync(force=True)
            except OSError as exc:
                log.error("write-ahead log %s: final sync failed (%s)", self._path, exc)
            os.close(self._fd)
            self._fd = None


def _first_seq(segment: Path) -> int:
    return int(_SEGMENT.fullmatch(segment.name).group(1))


def _parse(data: bytes, offset: int):
    """((seq, payload, end), "") for an intact record at ``offset``, else (None, why not)."""
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
    return (seq, payload, start + length), ""


def _resync(data: bytes, start: int) -> int | None:
    """Offset of the next intact record at or after ``start`` (None: none left)."""
    offset = data.find(MAGIC, start)
    while offset != -1:
        if _parse(data, offset)[0] is not None:
            return offset
        offset = data.find(MAGIC, offset + 1)
    return None


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
