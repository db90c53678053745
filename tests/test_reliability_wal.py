"""Write-ahead log and de-duplication: round trip, torn tail, resynchronisation after a damaged record,
replay after a checkpoint, a failed write or sync cut back, the storage back-off."""

from __future__ import annotations

import errno
import itertools
import logging
import os
import struct
import zlib

import numpy as np
import pytest

from protocols.codec import encode
from services.learner import wal as wal_module
from services.learner.dedup import Deduplicator
from services.learner.durable import DurableIngest
from services.learner.storage import StorageGuard
from services.learner.wal import HEADER, WriteAheadLog, parse_fsync
from tests.test_reliability_storage import _batch


def _fill(path, payloads, fsync="always"):
    wal = WriteAheadLog(path, fsync)
    assert list(wal.recover()) == []
    seqs = [wal.append(p) for p in payloads]
    wal.close()
    return seqs


def test_round_trip(tmp_path):
    payloads = [bytes([i]) * (i * 37 + 1) for i in range(20)]
    assert _fill(tmp_path, payloads) == list(range(1, 21))
    wal = WriteAheadLog(tmp_path, "never")
    assert list(wal.recover()) == list(enumerate(payloads, 1))
    assert wal.append(b"next") == 21
    assert wal.counters["corrupt_records"] == 0
    wal.close()


def test_torn_tail_is_cut_and_appending_continues(tmp_path):
    _fill(tmp_path, [b"a" * 100, b"b" * 100, b"c" * 100])
    segment = WriteAheadLog(tmp_path).segments()[-1]
    size = segment.stat().st_size
    with open(segment, "r+b") as fh:
        fh.truncate(size - 30)  # a crash in the middle of the last append
    wal = WriteAheadLog(tmp_path)
    assert [s for s, _ in wal.recover()] == [1, 2]
    assert wal.counters["corrupt_records"] == 1
    assert wal.counters["cut_bytes"] == HEADER.size + 100 - 30
    assert wal.append(b"d") == 3
    wal.close()
    again = WriteAheadLog(tmp_path)
    assert list(again.recover()) == [(1, b"a" * 100), (2, b"b" * 100), (3, b"d")]
    assert again.counters["corrupt_records"] == 0
    again.close()


def test_damaged_last_record_is_cut_like_a_torn_tail(tmp_path, caplog):
    _fill(tmp_path, [b"x" * 50 for _ in range(5)])
    segment = WriteAheadLog(tmp_path).segments()[-1]
    data = bytearray(segment.read_bytes())
    record = HEADER.size + 50
    data[4 * record + HEADER.size + 10] ^= 0x04  # payload of the last record: a damaged end is cut
    segment.write_bytes(bytes(data))
    wal = WriteAheadLog(tmp_path)
    assert [s for s, _ in wal.recover()] == [1, 2, 3, 4]
    assert wal.counters["corrupt_records"] == 1
    assert "checksum mismatch" in caplog.text
    assert segment.stat().st_size == 4 * record
    wal.close()


def _records(path) -> list[tuple[int, int]]:
    """(offset, length) of each record of a segment."""
    data, offset, out = path.read_bytes(), 0, []
    while offset < len(data):
        length = HEADER.unpack_from(data, offset)[1]
        out.append((offset, HEADER.size + length))
        offset += HEADER.size + length
    return out


@pytest.mark.parametrize("where", ["payload", "length", "magic", "crc", "seq"])
def test_one_damaged_record_in_the_middle_loses_only_that_record(tmp_path, caplog, where):
    rng = np.random.default_rng(3)
    payloads = [rng.bytes(int(rng.integers(20, 400))) for _ in range(40)]
    _fill(tmp_path, payloads)
    segment = WriteAheadLog(tmp_path).segments()[-1]
    data = bytearray(segment.read_bytes())
    offset, length = _records(segment)[2]  # record 3 of 40
    at = {"magic": 1, "length": 5, "seq": 10, "crc": 17, "payload": HEADER.size + length // 3}[where]
    data[offset + min(at, length - 1)] ^= 0x10
    segment.write_bytes(bytes(data))
    wal = WriteAheadLog(tmp_path)
    got = list(wal.recover())
    assert got == [(i + 1, p) for i, p in enumerate(payloads) if i != 2]
    assert wal.counters["corrupt_records"] == 1
    assert wal.counters["skipped_records"] == 1
    assert wal.counters["skipped_bytes"] == length
    assert wal.counters["cut_bytes"] == 0
    assert "skipped" in caplog.text and "records 3..3 are missing" in caplog.text
    assert wal.append(b"next") == 41  # appending continues after the newest record
    wal.close()


def test_damaged_end_of_an_older_segment_loses_only_that_record(tmp_path):
    wal = WriteAheadLog(tmp_path)
    list(wal.recover())
    for i in range(3):
        wal.append(b"first%d" % i)
    wal.rotate(keep_after=0)  # as after a checkpoint, with an older checkpoint still needing seq 1..
    for i in range(3):
        wal.append(b"second%d" % i)
    wal.close()
    first = wal.segments()[0]
    data = bytearray(first.read_bytes())
    data[-2] ^= 0x01  # the last record of the older segment
    first.write_bytes(bytes(data))
    again = WriteAheadLog(tmp_path)
    assert [s for s, _ in again.recover()] == [1, 2, 4, 5, 6]
    assert again.counters["skipped_records"] == 1 and again.counters["cut_bytes"] == 0
    again.close()


def test_log_written_by_the_previous_release_reads(tmp_path):
    """The record format is unchanged (magic NLW1, length, seq, crc32 over seq + payload): a segment
    built byte by byte as navlearn wrote it before resynchronisation existed still reads."""
    records = b""
    for seq, payload in enumerate([b"alpha", b"beta" * 10, b""], 1):
        crc = zlib.crc32(payload, zlib.crc32(struct.pack("<Q", seq)))
        records += struct.pack("<4sIQI", b"NLW1", len(payload), seq, crc) + payload
    (tmp_path / "wal-0000000000000001.log").write_bytes(records)
    wal = WriteAheadLog(tmp_path)
    assert list(wal.recover()) == [(1, b"alpha"), (2, b"beta" * 10), (3, b"")]
    assert wal.counters["corrupt_records"] == 0
    wal.close()


def test_failed_write_cuts_back_to_the_last_synced_group(tmp_path, monkeypatch):
    wal = WriteAheadLog(tmp_path)
    list(wal.recover())
    wal.append(b"kept")
    wal.append(b"group-1", sync=False)  # part of a group that will not be synced
    real_write = os.write

    def half_then_full(fd, data):
        real_write(fd, bytes(data[: len(data) // 2]))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(wal_module.os, "write", half_then_full)
    with pytest.raises(OSError):
        wal.append(b"group-2", sync=False)
    monkeypatch.undo()
    assert wal.last_seq == 1  # the whole unsynced group is gone, not acknowledged
    assert wal.append(b"after") == 2
    wal.close()
    again = WriteAheadLog(tmp_path)
    assert list(again.recover()) == [(1, b"kept"), (2, b"after")]
    assert again.counters["corrupt_records"] == 0
    again.close()


def test_rotation_keeps_what_the_oldest_checkpoint_needs(tmp_path):
    wal = WriteAheadLog(tmp_path)
    list(wal.recover())
    positions = []
    for round_ in range(4):
        for i in range(3):
            wal.append(b"r%d-%d" % (round_, i))
        positions.append(wal.last_seq)  # a checkpoint here, keep=2
        wal.rotate(keep_after=positions[-2] if len(positions) >= 2 else 0)
    wal.close()
    again = WriteAheadLog(tmp_path)
    assert [s for s, _ in again.recover(after=positions[-2])] == [10, 11, 12]
    assert min(s for s, _ in WriteAheadLog(tmp_path).recover()) == positions[-2] + 1
    again.close()


def test_replay_after_checkpoint_and_rotation(tmp_path):
    wal = WriteAheadLog(tmp_path)
    list(wal.recover())
    for i in range(5):
        wal.append(b"before%d" % i)
    checkpoint_seq = wal.last_seq
    wal.rotate()
    assert len(wal.segments()) == 1
    for i in range(3):
        wal.append(b"after%d" % i)
    wal.close()
    reopened = WriteAheadLog(tmp_path)
    assert list(reopened.recover(after=checkpoint_seq)) == [(6, b"after0"), (7, b"after1"), (8, b"after2")]
    reopened.close()


def test_seqs_continue_after_checkpoint_when_log_is_gone(tmp_path):
    wal = WriteAheadLog(tmp_path)
    assert list(wal.recover(after=41)) == []
    assert wal.append(b"p") == 42
    wal.close()


def test_fsync_policies():
    assert parse_fsync("always") == 0.0
    assert parse_fsync("never") is None
    assert parse_fsync("50") == pytest.approx(0.05)
    with pytest.raises(ValueError):
        parse_fsync("sometimes")


def test_group_commit_one_fsync_for_a_group(tmp_path):
    wal = WriteAheadLog(tmp_path, "always")
    list(wal.recover())
    wal.append(b"single")
    assert wal.counters["fsyncs"] == 1
    for i in range(5):
        wal.append(bytes([i]) * 10, sync=False)
    assert wal.counters["fsyncs"] == 1  # not yet durable
    wal.sync()
    assert wal.counters["fsyncs"] == 2  # one fsync for the five
    wal.sync()
    assert wal.counters["fsyncs"] == 2  # nothing new to sync
    wal.close()
    reread = WriteAheadLog(tmp_path, "never")
    assert [seq for seq, _ in reread.recover()] == list(range(1, 7))
    reread.close()


def test_dedup_contiguous_gaps_and_state_round_trip():
    d = Deduplicator()
    assert [d.seen("a#1", s) for s in (1, 2, 4)] == [False, False, False]
    assert d.seen("a#1", 2) and d.seen("a#1", 4)
    assert not d.seen("a#1", 3)
    assert not d.seen("a#2", 1)  # a new incarnation starts again at 1
    restored = Deduplicator()
    restored.load_state(d.state())
    assert restored.seen("a#1", 3) and restored.seen("a#2", 1)
    assert not restored.seen("a#1", 5)
    assert not d.seen("b", 0) and not d.seen("b", 0)  # unnumbered messages are never duplicates


def test_dedup_forget_undoes_seen():
    d = Deduplicator()
    for seq in (1, 2, 3, 5):
        d.seen("a", seq)
    d.forget("a", 2)  # below the contiguous floor
    d.forget("a", 5)  # above it
    assert not d.seen("a", 2) and not d.seen("a", 5)
    assert d.seen("a", 1) and d.seen("a", 3)


def test_a_failed_group_is_forgotten_so_its_resends_are_taken(tmp_path, monkeypatch):
    durable = DurableIngest(tmp_path, "always")
    list(durable.replay())
    first, second = _batch(1, [1.0]), _batch(2, [2.0])
    assert durable.admit(first, encode(first))
    durable.sync()
    assert durable.admit(second, encode(second))

    def no_space(_fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(wal_module.os, "fsync", no_space)
    with pytest.raises(OSError):
        durable.sync()
    monkeypatch.undo()
    assert not durable.admit(first, encode(first))  # synced before: still a duplicate
    assert durable.admit(second, encode(second))  # its group failed: the resend is new
    durable.sync()
    durable.close()
    again = DurableIngest(tmp_path, "always")
    assert [r.message.seq for r in again.replay()] == [1, 2]
    again.close()


def test_storage_guard_backs_off_and_recovers(caplog):
    caplog.set_level(logging.INFO, logger="navlearn.storage")
    guard = StorageGuard(first=1.0, longest=4.0)
    assert not guard.blocked(0.0) and guard.counters() == {"storage_error": 0, "storage_failures": 0}
    failure = OSError(28, "No space left on device")
    guard.failed("write-ahead log", "/x/wal", failure, now=10.0)
    assert guard.blocked(10.5) and not guard.blocked(11.0)
    guard.failed("write-ahead log", "/x/wal", failure, now=11.0)
    guard.failed("write-ahead log", "/x/wal", failure, now=13.0)
    guard.failed("write-ahead log", "/x/wal", failure, now=17.0)
    assert guard.retry_at == 21.0  # 1, 2, 4, then capped at 4
    assert guard.counters() == {"storage_error": 1, "storage_failures": 4}
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and "/x/wal" in errors[0].message and "No space left" in errors[0].message
    guard.succeeded()
    assert not guard.blocked(17.5) and guard.counters()["storage_error"] == 0
    assert "storage recovered" in caplog.text


def test_periodic_checkpoints_on_a_full_disk_retry_on_the_schedule_the_log_announces(caplog):
    """Issue 43: with --checkpoint-every 2 the log announced retries in 2, 4, 8, 16, 30 s but a
    checkpoint was tried every 2 s. The service's loop, as in LearnerService.run: a checkpoint is
    tried when due (guard.due), and a failed one is retried once the guard stops blocking."""
    caplog.set_level(logging.INFO, logger="navlearn.storage")
    guard = StorageGuard(first=1.0, longest=30.0)
    failure = OSError(28, "No space left on device")
    every, next_checkpoint, attempts = 2.0, 2.0, []
    for tick in range(0, 120_00, 5):  # 120 s in steps of 50 ms
        now = tick / 100
        if guard.what == "checkpoint" and not guard.blocked(now):
            next_checkpoint = now  # retry the checkpoint that failed
        if guard.due(now, next_checkpoint):
            attempts.append(now)
            guard.failed("checkpoint", "/x/ckpt", failure, now)
            next_checkpoint = now + every
    announced = [float(r.getMessage().rsplit(" in ", 1)[1].split()[0]) for r in caplog.records]
    gaps = [round(b - a, 2) for a, b in itertools.pairwise(attempts)]
    assert gaps[:6] == [1.0, 2.0, 4.0, 8.0, 16.0, 30.0], gaps
    assert gaps == announced[: len(gaps)]


def test_a_stored_batch_with_a_rewritten_sender_is_a_duplicate_by_content(tmp_path):
    """Issue 43: duplicates were recognised by (sender, seq) only, so a copy of an acknowledged batch
    whose sender field was rewritten was stored a second time."""
    durable = DurableIngest(tmp_path, "always")
    list(durable.replay())
    batch = _batch(1, [1.0, 2.0])
    assert durable.admit(batch, encode(batch))
    durable.sync()
    for sender, seq in (("a1#2", 1), ("someone-else#7", 5), ("a1#1", 9)):
        rewritten = _batch(seq, [1.0, 2.0])
        rewritten.sender = sender
        assert not durable.admit(rewritten, encode(rewritten)), (sender, seq)
    assert durable.counters["duplicates_by_content"] == 3 and durable.counters["duplicates_dropped"] == 3
    other = _batch(2, [1.0, 3.0])  # other content from the same sender: new
    assert durable.admit(other, encode(other))
    durable.sync()
    # the content index survives a checkpoint and a restart, and the log's replay rebuilds it
    state = durable.checkpoint_state()
    durable.close()
    again = DurableIngest(tmp_path, "always")
    again.load_state(state)
    list(again.replay())
    copy = _batch(3, [1.0, 3.0])
    copy.sender = "x#1"
    assert not again.admit(copy, encode(copy))
    again.close()
    replayed = DurableIngest(tmp_path, "always")  # no checkpoint: everything from the log
    assert len(list(replayed.replay())) == 2
    copy.sender = "y#1"
    assert not replayed.admit(copy, encode(copy))
    replayed.close()
