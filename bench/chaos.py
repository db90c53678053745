"""Chaos benchmark: SIGKILLed learners, a restarted actor and router, a flooding actor - nothing
acknowledged may be lost. Then ingest throughput with acknowledgements + write-ahead log on vs off
(bench/ingest.py: the same offered loads in every setting, interleaved rounds).

Processes: a stand-alone router, a learner (client, checkpoints every 2 s), traceable actors
in this process (tests/reliability_helpers.TracedActor: unique ids in the rewards, the real
Outbox, one Zenoh session each) and a flooder publishing the same big batch without waiting.
At the end the learner is stopped with SIGTERM and its final checkpoint is read back:
every acknowledged id must be stored exactly once.

Then the flood and large-batch phases (issue #19): a fresh learner, one normal traced actor
offering 25 batches/s (``--normal-rate``), and services/actor/flooder.py in its own process, in
interleaved rounds: alone; with valid batches of the largest accepted size (1000 rows) on the
flooder's own key; with ~60 MB valid batches on 4 more keys; with both. Reported:
the normal actor's acknowledged batches/s per phase, its slowdown under each, the learner's
peak RSS (VmHWM) and what it refused.

    python -m bench.chaos --actors 3 --kills 3 --seconds 45
    python -m bench.chaos --only-flood --flood-rounds 3 --flood-seconds 10
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench import ingest
from protocols.codec import encode
from services.actor.flooder import launch as launch_flooder
from services.common.transport import ZenohSettings, free_port, open_session
from services.learner.checkpoint import CheckpointDir
from services.ops.status import query_status
from tests.reliability_helpers import TracedActor, caught_up, settle, start_learner, stop_process, stored_ids
from tests.reliability_helpers import learner_argv as hosting_learner_argv


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--actors", type=int, default=3, help="traceable actors (2-4)")
    p.add_argument("--kills", type=int, default=3, help="learner SIGKILLs")
    p.add_argument("--seconds", type=float, default=45.0, help="length of the chaos phase")
    p.add_argument(
        "--throughput-seconds", type=float, default=3.0, help="each ingest measurement (bench/ingest.py)"
    )
    p.add_argument("--ingest-rounds", type=int, default=4, help="ingest rounds after the warm-up")
    p.add_argument("--wal-fsync", default="always", help="learner --wal-fsync in the ingest comparison")
    p.add_argument("--only-ingest", action="store_true", help="skip the chaos phase, measure ingest only")
    p.add_argument("--only-flood", action="store_true", help="run only the flood and large-batch phases")
    p.add_argument("--flood-rounds", type=int, default=3, help="interleaved rounds of the flood phases")
    p.add_argument("--flood-seconds", type=float, default=10.0, help="each flood-phase measurement")
    p.add_argument("--flooder-nice", type=int, default=19, help="nice of the flooder process (0: none)")
    p.add_argument(
        "--normal-rate", type=float, default=25.0, help="batches/s the normal actor offers (0: all it can)"
    )
    p.add_argument(
        "--phases", nargs="+", default=list(FLOOD_PHASES), choices=list(FLOOD_PHASES), help="flood phases run"
    )
    p.add_argument(
        "--learner-code",
        default="",
        help="run the flood phases' learner from this checkout (PYTHONPATH), e.g. a worktree of main",
    )
    return p.parse_args()


def peak_rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


REPLAY_CAPACITY = 250_000
"""the learner's replay ring: larger than all a 45 s chaos phase stores on a quiet machine (about
100k), so nothing stored is evicted (an evicted transition would read back as lost). Not larger:
each checkpoint writes the whole ring, and with 1M a run acknowledged 20x fewer transitions."""


def learner_argv(endpoint: str, run: str, ckpt: Path | None, *extra: str) -> list[str]:
    return [
        sys.executable, "-m", "services.cli", "learner", "--connect", endpoint, "--mode", "client",
        "--run", run, "--checkpoint-dir", str(ckpt) if ckpt else "", "--hidden-sizes", "16",
        "--batch-size", "16", "--learning-starts", "64", "--broadcast-every", "20", "--log-every", "5",
        "--connect-timeout", "120", "--replay-capacity", str(REPLAY_CAPACITY), *extra,
    ]  # fmt: skip


def start_router(endpoint: str, log: Path) -> subprocess.Popen:
    with open(log, "ab") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "services.cli", "router", "--listen", endpoint], stdout=fh, stderr=fh
        )


class ActorThread:
    """One traceable actor with its own session, sending until stopped."""

    def __init__(self, endpoint: str, run: str, name: str, first_id: int, rate: float = 0.0) -> None:
        """``rate``: batches/s offered (0: as fast as acknowledgements allow, 5 ms apart)."""
        self.session = open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120))
        self.actor = TracedActor(self.session, run, name, per_batch=16, first_id=first_id)
        self.rate = rate
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        due = time.monotonic()
        while not self.stop.is_set():
            self.actor.send_one(self.stop)
            # held back by the learner, a real actor's robots stop too: no burst to make up for it
            due = max(due + 1.0 / self.rate, time.monotonic()) if self.rate else time.monotonic() + 0.005
            self.stop.wait(max(0.0, due - time.monotonic()))

    def drain(self, timeout: float) -> None:
        self.stop.set()
        self.thread.join(10)
        deadline = time.monotonic() + timeout
        flush_stop = threading.Event()
        while len(self.actor.outbox) and time.monotonic() < deadline:
            threading.Timer(1.0, flush_stop.set).start()
            self.actor.outbox.flush(flush_stop)
            flush_stop.clear()
            time.sleep(0.2)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)
        self.actor.close()
        self.session.close()


def chaos(args, root: Path) -> dict:
    endpoint, run = f"tcp/127.0.0.1:{free_port()}", "chaos"
    ckpt = root / "ckpt"
    router = start_router(endpoint, root / "router.log")
    argv = learner_argv(endpoint, run, ckpt, "--checkpoint-every", "2")
    learner = start_learner(argv, root / "learner.log")
    peak = 0.0
    actors = [ActorThread(endpoint, run, f"a{i}", first_id=1 + i * 1_000_000) for i in range(args.actors)]
    retired: list[ActorThread] = []
    flood_session = open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120))
    flooder = TracedActor(flood_session, run, "flood", per_batch=512, first_id=9_000_000)
    flood_payload = encode(flooder.make_batch())
    flood_stop = threading.Event()

    def flood() -> None:
        while not flood_stop.is_set():
            flooder.publisher.put(flood_payload)

    flood_thread = threading.Thread(target=flood, daemon=True)
    flood_thread.start()
    watcher = open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120))
    resume_s: list[float] = []

    def acks_total() -> int:
        return sum(len(a.actor.acked_seqs) for a in actors + retired)

    start = time.monotonic()
    events = [("kill", start + args.seconds * (k + 1) / (args.kills + 2)) for k in range(args.kills)]
    events += [("actor", start + args.seconds * 0.55), ("router", start + args.seconds * 0.75)]
    for what, at in sorted(events, key=lambda e: e[1]):
        while time.monotonic() < at:
            peak = max(peak, peak_rss_mb(learner.pid))
            time.sleep(0.2)
        if what == "kill":
            peak = max(peak, peak_rss_mb(learner.pid))
            learner.send_signal(signal.SIGKILL)
            learner.wait()
            before = acks_total()
            t0 = time.monotonic()
            learner = start_learner(argv, root / "learner.log")
            while acks_total() == before and time.monotonic() - t0 < 120:
                time.sleep(0.05)
            resume_s.append(time.monotonic() - t0)
            print(f"learner SIGKILLed and restarted: acknowledging again after {resume_s[-1]:.1f} s")
        elif what == "actor":
            old = actors.pop(1)
            old.close()  # a crash: its unacknowledged batches die with it (never acknowledged, not lost)
            retired.append(old)
            actors.append(ActorThread(endpoint, run, "a1", first_id=1 + args.actors * 1_000_000))
            print("actor a1 restarted (new incarnation)")
        else:
            router.send_signal(signal.SIGTERM)
            router.wait(30)
            router = start_router(endpoint, root / "router.log")
            print("router restarted")
    while time.monotonic() < start + args.seconds:
        time.sleep(0.2)
    flood_stop.set()
    flood_thread.join(10)
    for a in actors:
        a.drain(60)
    status = query_status(watcher, run, timeout=5.0)
    peak = max(peak, peak_rss_mb(learner.pid))
    stop_process(learner)
    stored = stored_ids(CheckpointDir(ckpt).latest(), REPLAY_CAPACITY)
    if stored.size >= REPLAY_CAPACITY:
        raise RuntimeError(f"the replay ring filled up ({REPLAY_CAPACITY}): evictions would read as losses")
    unique, counts = np.unique(stored, return_counts=True)
    everyone = actors + retired
    sent = np.concatenate([a.actor.sent_ids() for a in everyone])
    acked = np.concatenate([a.actor.acked_ids() for a in everyone])
    counters = status.counters if status else {}
    result = {
        "actors": args.actors,
        "learner_kills": args.kills,
        "transitions_sent": int(sent.size),
        "transitions_acknowledged": int(acked.size),
        "transitions_stored": int(unique.size),
        "stored_twice": int((counts > 1).sum()),
        "acknowledged_lost": int(np.setdiff1d(acked, unique).size),
        "batches_unacknowledged_at_actor_crash": int(sum(len(a.actor.outbox) for a in retired)),
        "duplicates_dropped": int(counters.get("duplicates_dropped", -1)),
        "resent_batches": int(sum(a.actor.outbox.resent for a in everyone)),
        "flood_dropped": int(counters.get("dropped/sender_full/flood", 0)),
        "learner_peak_rss_mb": round(peak, 1),
        "resume_seconds": [round(s, 2) for s in resume_s],
        "policy_version_final": int(status.versions["nnql"]) if status else -1,
    }
    for a in actors:
        a.close()
    for s in (watcher, flood_session):
        s.close()
    stop_process(router)
    return result


FLOOD_PHASES = {
    "alone": None,
    "rows": ["--rows", "1000"],
    "large": ["--rows", "0", "--big-mb", "60", "--big-keys", "4"],
    "flood": ["--rows", "1000", "--big-mb", "60", "--big-keys", "4"],
}
"""The flooder's arguments per phase (1000 rows: the learner's default row limit, 1% of its 100k replay)"""


def flood(args, root: Path) -> dict:
    """The normal actor's acknowledged rate alone, under a flood and under large batches."""
    endpoint, run = f"tcp/127.0.0.1:{free_port()}", "flood"
    # hosts the router; 100k replay; checkpoints only on stop (a periodic one would stall every phase alike)
    argv = hosting_learner_argv(endpoint, run, root / "flood-ckpt", "--checkpoint-every", "0")
    if args.learner_code:
        argv = ["env", f"PYTHONPATH={args.learner_code}", *argv]
    learner = start_learner(argv, root / "flood-learner.log")
    normal = ActorThread(endpoint, run, "normal", first_id=1, rate=args.normal_rate)
    watcher = open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120))
    deadline = time.monotonic() + 180
    while len(normal.actor.acked_seqs) < 50 and time.monotonic() < deadline:
        time.sleep(0.2)
    rates: dict[str, list[float]] = {phase: [] for phase in args.phases}
    settle(watcher, run)
    rss_before = peak_rss_mb(learner.pid)
    flooder_args = ["--connect", endpoint, "--run", run]
    for _ in range(args.flood_rounds):
        for phase in args.phases:
            extra = FLOOD_PHASES[phase]
            proc = None if extra is None else launch_flooder([*flooder_args, *extra], nice=args.flooder_nice)
            start, acked = time.monotonic(), len(normal.actor.acked_seqs)
            time.sleep(args.flood_seconds)
            rates[phase].append((len(normal.actor.acked_seqs) - acked) / (time.monotonic() - start))
            if proc is not None:
                stop_process(proc, timeout=30)
                settle(watcher, run)  # what the router still held of the flood is through
            caught_up(normal.actor)  # the next phase starts without a backlog to catch up on
            print(f"{phase}: normal actor {rates[phase][-1]:.1f} acknowledged batches/s")
    status = query_status(watcher, run, timeout=5.0)
    peak = peak_rss_mb(learner.pid)
    normal.drain(60)
    lost = len(normal.actor.outbox)
    normal.close()
    watcher.close()
    stop_process(learner)
    counters = status.counters if status else {}
    alone = float(np.median(rates["alone"]))
    return {
        "flood/normal_batches_per_s": {k: [round(r, 1) for r in v] for k, v in rates.items()},
        **{
            f"flood/slowdown/{k}": round(1 - float(np.median(v)) / alone, 3)
            for k, v in rates.items()
            if k != "alone"
        },
        "flood/learner_rss_mb_before": round(rss_before, 1),
        "flood/learner_peak_rss_mb": round(peak, 1),
        "flood/rejected_batch_too_large": int(counters.get("rejected/batch_too_large", 0)),
        "flood/dropped_sender_full_flood": int(counters.get("dropped/sender_full/flood", 0)),
        "flood/flood_transitions_stored": int(counters.get("transitions/flood", 0)),
        "flood/normal_unacknowledged_at_end": lost,
    }


def main() -> None:
    args = parse_args()
    with tempfile.TemporaryDirectory(prefix="navlearn-chaos-") as tmp:
        root = Path(tmp)
        if args.only_flood:
            print(json.dumps(flood(args, root)))
            return
        result = {} if args.only_ingest else chaos(args, root)
        if not args.only_ingest:
            result.update(flood(args, root))
        if not args.only_ingest:
            print(
                f"sent {result['transitions_sent']}, acknowledged {result['transitions_acknowledged']}, "
                f"stored {result['transitions_stored']}, lost {result['acknowledged_lost']}, "
                f"stored twice {result['stored_twice']}, duplicates dropped {result['duplicates_dropped']}, "
                f"peak RSS {result['learner_peak_rss_mb']} MB, resume {result['resume_seconds']} s"
            )
        rounds, seconds, fsync = str(args.ingest_rounds), str(args.throughput_seconds), args.wal_fsync
        ingest_args = ingest.parse_args(["--rounds", rounds, "--seconds", seconds, "--wal-fsync", fsync])
        (root / "ingest").mkdir()
        figures = ingest.run_ingest(ingest_args, root / "ingest")
        ingest.report(figures)
        result.update({f"ingest/{k}": v for k, v in figures.items()})
    print(json.dumps(result))


if __name__ == "__main__":
    main()
