"""Damaged and full storage under a real learner process: it recovers, never acknowledges a loss.

- A damaged newest checkpoint (learner.pt cut by 200 bytes, then a garbage service.json)
  is set aside, logged with the file and the reason, and the learner resumes from the
  newest intact one plus its write-ahead log: every acknowledged transition is stored.
- A crafted pickle in a checkpoint (with a manifest recomputed, as someone who can write
  the directory would) never runs.
- The write-ahead log holds the bytes the learner accepted (not a re-encoding) and is
  replayed under the learner's own limits (its number of actions), not the defaults.
- A full disk (a 20 MB tmpfs, as root) under the write-ahead log and under a checkpoint:
  one log line naming the path and the error, ``storage_error 1`` in a status that keeps
  answering, no acknowledgement while failing, recovery once there is room, a clean stop on
  SIGTERM, never a SIGBUS; and nothing acknowledged lost afterwards.
"""

from __future__ import annotations

import errno
import os
import pickle
import shutil
import subprocess
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import msgpack
import numpy as np
import pytest

from protocols import keys
from protocols.codec import decode, encode
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from services.learner.checkpoint import CheckpointDir, write_manifest
from services.learner.wal import WriteAheadLog
from services.ops.status import progress_line, query_status, status_dict
from tests.conftest import free_port
from tests.reliability_helpers import (
    N_ACTIONS,
    OBS_DIM,
    TracedActor,
    learner_argv,
    start_learner,
    stop_process,
    stored_ids,
)

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(420)]


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


class Rig:
    """A learner process on ``ckpt_dir`` and a traced actor sending to it from a thread."""

    def __init__(self, tmp_path: Path, ckpt_dir: Path, *extra: str, per_batch: int = 8) -> None:
        port = free_port()
        self.endpoint, self.run = f"tcp/127.0.0.1:{port}", f"storage{port}"
        self.argv = learner_argv(self.endpoint, self.run, ckpt_dir, *extra)
        self.log_path = tmp_path / "learner.log"
        self.ckpt_dir = ckpt_dir
        self.learner = start_learner(self.argv, self.log_path)
        self.session = open_session(
            ZenohSettings(mode="client", connect=[self.endpoint], run=self.run, connect_timeout=120)
        )
        self.actor = TracedActor(self.session, self.run, "a1", per_batch=per_batch)
        self.stop, self.sending = threading.Event(), threading.Event()
        self.thread = threading.Thread(target=self._send, daemon=True)
        self.thread.start()

    def _send(self) -> None:
        while not self.stop.is_set():
            if self.sending.is_set():
                self.actor.send_one(self.stop)
            time.sleep(0.01)

    def restart(self) -> None:
        self.learner = start_learner(self.argv, self.log_path)

    def status(self):
        return query_status(self.session, self.run, timeout=3.0)

    def counter(self, name: str) -> int | None:
        status = self.status()
        return None if status is None else status.counters.get(name, 0)

    def acked(self) -> int:
        return len(self.actor.acked_seqs)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)
        self.actor.close()
        self.session.close()
        stop_process(self.learner)

    def assert_nothing_acknowledged_lost(self) -> np.ndarray:
        stored = stored_ids(CheckpointDir(self.ckpt_dir).latest())
        unique, counts = np.unique(stored, return_counts=True)
        assert counts.max() == 1, f"{int((counts > 1).sum())} transitions stored twice"
        missing = np.setdiff1d(self.actor.acked_ids(), unique)
        assert missing.size == 0, f"{missing.size} acknowledged transitions lost"
        return unique


def _stop(process: subprocess.Popen, timeout: float = 60.0) -> int:
    """SIGTERM and the exit code; fails if it does not stop in time (the hang this guards against)."""
    process.terminate()
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        raise AssertionError(f"the learner ignored SIGTERM for {timeout:.0f} s") from None


# ---------------------------------------------------------------- damaged checkpoints


def test_damaged_newest_checkpoint_is_set_aside_and_nothing_acknowledged_is_lost(tmp_path):
    ckpt_dir = tmp_path / "ckpt"
    rig = Rig(tmp_path, ckpt_dir, "--checkpoint-every", "2")
    try:
        rig.sending.set()
        enough = lambda: rig.acked() >= 30 and len(CheckpointDir(ckpt_dir).all()) >= 2  # noqa: E731
        wait_for(enough, 180, "acks and two checkpoints")
        time.sleep(1.0)
        assert _stop(rig.learner) == 0  # mid-stream: the final checkpoint holds acks the older ones do not
        rig.sending.clear()
        older, newest = CheckpointDir(ckpt_dir).all()[-2:]
        assert len(stored_ids(older)) < len(rig.actor.acked_ids())  # resuming from it needs the log

        state = newest / "nnql" / "learner.pt"
        state.write_bytes(state.read_bytes()[:-200])
        rig.restart()
        wait_for(lambda: rig.status() is not None, 120, "the learner to answer after the damage")
        acked = rig.acked()
        rig.sending.set()
        wait_for(lambda: rig.acked() >= acked + 20, 120, "acks after the restart")
        log = rig.log_path.read_text()
        assert f"checkpoint {newest} is damaged" in log and "learner.pt" in log
        assert f"set aside as {newest.with_name('damaged-' + newest.name)}" in log
        assert rig.learner.poll() is None

        assert _stop(rig.learner) == 0
        rig.sending.clear()
        newest = CheckpointDir(ckpt_dir).latest()
        (newest / "service.json").write_text("garbage")
        rig.restart()
        wait_for(lambda: rig.status() is not None, 120, "the learner to answer after a garbage service.json")
        assert f"checkpoint {newest} is damaged" in rig.log_path.read_text()
        wait_for(lambda: len(rig.actor.outbox) == 0, 60, "the outbox to drain")
    finally:
        rig.close()
    stored = rig.assert_nothing_acknowledged_lost()
    assert len(stored) >= 30 * 8
    assert sorted(p.name for p in ckpt_dir.iterdir() if p.name.startswith("damaged-"))  # kept for a look


class Marker:
    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.write_text, (self.path, "code ran"))


def test_crafted_pickle_in_the_checkpoint_directory_never_runs(tmp_path):
    ckpt_dir = tmp_path / "ckpt"
    rig = Rig(tmp_path, ckpt_dir, "--checkpoint-every", "0")
    marker = tmp_path / "marker"
    try:
        rig.sending.set()
        wait_for(lambda: rig.acked() >= 10, 180, "acks")
        rig.sending.clear()
        wait_for(lambda: len(rig.actor.outbox) == 0, 60, "the outbox to drain")
        assert _stop(rig.learner) == 0
        newest = CheckpointDir(ckpt_dir).latest()
        for name in ("prefetch.pkl", "transform.t"):  # what TorchRL's own loader unpickles
            (newest / "nnql" / "replay" / name).write_bytes(pickle.dumps(Marker(marker)))
        (newest / "manifest.json").unlink()
        write_manifest(newest)  # whoever can write the directory can also rewrite the checksums
        rig.restart()
        wait_for(lambda: rig.status() is not None, 120, "the learner to answer")
        assert rig.status().replay_sizes["transitions"] >= 80
    finally:
        rig.close()
    assert not marker.exists(), "a pickle from the checkpoint directory ran in the learner"


# ---------------------------------------------------------------- a full disk (tmpfs, root only)


@contextmanager
def small_disk(path: Path, size_mb: int = 20):
    """A ``size_mb`` tmpfs at ``path`` (root only; the test is skipped with the reason otherwise)."""
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a small tmpfs (a full disk is simulated by one)")
    if shutil.which("mount") is None:
        pytest.skip("no mount command to create a small tmpfs")
    path.mkdir(parents=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(path)], capture_output=True, text=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def fill(disk: Path, leave: int = 0) -> Path:
    """Fill ``disk`` with one file until ``leave`` bytes (or nothing) are free."""
    filler = disk / "filler"
    with open(filler, "ab") as fh:
        chunk = 1 << 20
        while chunk >= 4096:
            room = shutil.disk_usage(disk).free - leave
            if room < chunk:
                chunk //= 2
                continue
            try:
                fh.write(bytes(chunk))
                fh.flush()
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
                break
    return filler


def test_full_disk_under_the_write_ahead_log(tmp_path):
    with small_disk(tmp_path / "disk") as disk:
        rig = Rig(tmp_path, disk / "ckpt", "--checkpoint-every", "1000")
        try:
            rig.sending.set()
            wait_for(lambda: rig.acked() >= 20, 180, "acks")
            filler = fill(disk)
            wait_for(lambda: rig.counter("storage_error") == 1, 60, "storage_error in the status")
            # the failed group commit was cut back to its last synced group, which gives the space of
            # its whole records back: a retry of fewer batches may fit there and be acknowledged,
            # rightly (written and synced). Fill that too, then nothing more fits
            fill(disk)
            wait_for(lambda: rig.counter("storage_error") == 1, 60, "storage_error after the top-up")
            time.sleep(1.0)
            before = rig.acked()
            time.sleep(4.0)
            assert rig.acked() == before, "acknowledged while the log could not be written"
            assert rig.learner.poll() is None and rig.status() is not None  # alive, status answering
            assert "STORAGE ERROR" in progress_line(status_dict(rig.status(), []))  # navlearn status/up
            log = rig.log_path.read_text()
            first = [line for line in log.splitlines() if "storage error writing the write-ahead log" in line]
            assert len(first) == 1, first
            assert str(disk / "ckpt" / "wal") in first[0] and "No space left on device" in first[0]
            assert "Traceback" not in log

            filler.unlink()  # room again: the retry (with back-off) takes batches in again
            wait_for(lambda: rig.acked() >= before + 10, 90, "acks after space came back")
            wait_for(lambda: rig.counter("storage_error") == 0, 30, "storage_error cleared")
            assert "storage recovered" in rig.log_path.read_text()

            filler = fill(disk)
            wait_for(lambda: rig.counter("storage_error") == 1, 60, "the second storage error")
            assert _stop(rig.learner, 60) == 0  # SIGTERM while failing: a clean stop, session released
            assert "learner stopped" in rig.log_path.read_text()
            filler.unlink()
            rig.sending.clear()
            rig.restart()
            wait_for(lambda: rig.status() is not None, 120, "the learner to answer after the restart")
            rig.sending.set()
            wait_for(lambda: len(rig.actor.outbox) == 0 or rig.acked() >= before + 40, 120, "acks")
            rig.sending.clear()
            wait_for(lambda: len(rig.actor.outbox) == 0, 60, "the outbox to drain")
        finally:
            rig.close()
        rig.assert_nothing_acknowledged_lost()


def test_full_disk_under_a_checkpoint_is_no_sigbus(tmp_path):
    with small_disk(tmp_path / "disk") as disk:
        rig = Rig(tmp_path, disk / "ckpt", "--checkpoint-every", "2", per_batch=256)
        try:
            rig.sending.set()
            wait_for(lambda: (rig.counter("transitions_received") or 0) >= 20_000, 240, "20k transitions")
            filler = fill(disk, leave=1 << 20)  # room for the log for a while, not for a ~4 MB checkpoint
            wait_for(lambda: rig.counter("storage_error") == 1, 60, "storage_error in the status")
            assert rig.learner.poll() is None, f"the learner died (exit {rig.learner.returncode})"
            lines = [
                line for line in rig.log_path.read_text().splitlines() if "storage error writing the" in line
            ]
            assert lines and str(disk / "ckpt") in lines[0], lines
            assert "a checkpoint needs about" in "\n".join(lines) or "No space left" in "\n".join(lines)
            time.sleep(3.0)
            assert rig.learner.poll() is None and rig.status() is not None
            code = _stop(rig.learner, 60)
            assert code == 0, f"exit {code} (SIGBUS is -7)"
            filler.unlink()
            assert not [p for p in (disk / "ckpt").iterdir() if p.name.startswith(".tmp-ckpt")]
        finally:
            rig.close()


# ---------------------------------------------------------------- what the log holds


def _batch(seq: int, ids: list[float], action: int = 0) -> TransitionBatch:
    n = len(ids)
    return TransitionBatch(
        sender="a1#1", seq=seq, actor="a1", model="nnql", policy_version=0,
        env_ids=np.arange(n, dtype=np.int32), obs=np.zeros((n, OBS_DIM), np.float32),
        action=np.full(n, action), reward=np.asarray(ids, np.float32),
        next_obs=np.zeros((n, OBS_DIM), np.float32), terminated=np.zeros(n, bool),
        truncated=np.zeros(n, bool),
    )  # fmt: skip


def _reordered(payload: bytes) -> bytes:
    """The same message with its map keys in another order: valid, but not what encode() writes."""
    unpacked = msgpack.unpackb(payload, raw=False, ext_hook=msgpack.ExtType, strict_map_key=False)
    return msgpack.packb(dict(reversed(list(unpacked.items()))), use_bin_type=True)


def test_the_log_holds_the_accepted_bytes_and_replays_under_the_learners_limits(tmp_path):
    ckpt_dir = tmp_path / "ckpt"
    wal = WriteAheadLog(ckpt_dir / "wal")
    list(wal.recover())
    wal.append(encode(_batch(1, [1001, 1002, 1003], action=N_ACTIONS + 2)))  # valid only without limits
    wal.append(encode(_batch(2, [1004, 1005])))
    wal.close()
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"bytes{port}"
    learner = start_learner(learner_argv(endpoint, run, ckpt_dir), tmp_path / "learner.log")
    session = None
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        wait_for(lambda: query_status(session, run, timeout=3.0) is not None, 120, "the learner")
        status = query_status(session, run, timeout=3.0)
        assert status.counters["wal_undecodable"] == 1  # the learner's n_actions, not the defaults
        assert status.replay_sizes["transitions"] == 2

        sent = _reordered(encode(_batch(3, [1006, 1007, 1008, 1009])))
        assert encode(decode(sent)) != sent
        session.put(keys.transitions(run, "a1"), sent)
        stored = lambda: query_status(session, run, timeout=3.0).replay_sizes["transitions"] == 6  # noqa: E731
        wait_for(stored, 60, "the batch to be stored")
    finally:
        if session is not None:
            session.close()
        learner.kill()  # no final checkpoint: the log keeps the records
        learner.wait()
    logged = [payload for seq, payload in WriteAheadLog(ckpt_dir / "wal").recover() if seq == 3]
    assert logged == [sent]  # byte for byte what arrived, not a re-encoding
