"""Write-ahead log and de-duplication: round trip, torn tail, bit flip, replay after a checkpoint."""

from __future__ import annotations

import pytest

from services.learner.dedup import Deduplicator
from services.learner.wal import HEADER, WriteAheadLog, parse_fsync


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


def test_bit_flip_in_the_middle_stops_there(tmp_path, caplog):
    _fill(tmp_path, [b"x" * 50 for _ in range(5)])
    segment = WriteAheadLog(tmp_path).segments()[-1]
    data = bytearray(segment.read_bytes())
    record = HEADER.size + 50
    data[2 * record + HEADER.size + 10] ^= 0x04  # payload of record 3
    segment.write_bytes(bytes(data))
    wal = WriteAheadLog(tmp_path)
    assert [s for s, _ in wal.recover()] == [1, 2]
    assert wal.counters["corrupt_records"] == 1
    assert "checksum mismatch" in caplog.text
    assert segment.stat().st_size == 2 * record
    wal.close()


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
