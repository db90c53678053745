"""Ingest throughput with acknowledgements and the write-ahead log on, against off, in one run.

What it measures: transitions per second the learner *stores* (its ``transitions_received``
counter: batches inserted into the replay buffer; duplicates and drops excluded), read from
its status snapshots, the whole wire path included (actors' encode, Zenoh through the
learner's router, decode and checks in the inbox, insert, acknowledgement).

Three settings, each with its own learner process started with the same flags (router mode,
default inbox, ``--utd-ratio 0.0005``: almost no training, the main thread only ingests, so
every learner is ingest-bound in the same way):

* ``off``      - actors publish and never wait for acknowledgements, learner without WAL;
* ``acks``     - actors send through the real Outbox (ActorConfig's ack window), learner without WAL;
* ``acks+wal`` - the same actors, learner with its write-ahead log (``--wal-fsync``).

Every setting gets the same offered loads: 2 actors, batches of 128 transitions (an actor's
default 16 steps x 8 robots), paced to each of ``--offered`` transitions/s in all. With
acknowledgements an actor falls behind the pace when the learner cannot keep up
(back-pressure); without, the learner's per-actor inbox bound drops the surplus (counted). A
setting's throughput in a round is the most it stored at any of the offered loads: overloading
a learner without flow control costs it (it decodes what it then drops, and the GIL is shared
with its main thread), so a single load above every ceiling would understate ``off``.
Rounds are interleaved (each load: the three settings back to back, the order rotating each
round); the first round is a warm-up and discarded. The ratio is taken per round and its
median and range reported.

    python -m bench.ingest --rounds 4 --seconds 3
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import StatusReport, TransitionBatch
from services.actor.config import ActorConfig
from services.common.outbox import Outbox
from services.common.transport import ZenohSettings, free_port, open_session
from services.ops.status import query_status
from tests.reliability_helpers import N_ACTIONS, OBS_DIM, start_learner, stop_process

SETTINGS = ("off", "acks", "acks+wal")
ACTORS = 2


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=5, help="measured rounds of every setting (after 1 warm-up)")
    p.add_argument("--seconds", type=float, default=4.0, help="measurement window of each setting per round")
    p.add_argument(
        "--offered",
        type=float,
        nargs="+",
        default=[40_000.0, 60_000.0, 80_000.0],
        help="offered loads, transitions/s over all actors (the same in every setting)",
    )
    p.add_argument("--batch", type=int, default=128, help="transitions per batch")
    p.add_argument("--wal-fsync", default="always", help="the acks+wal learner's --wal-fsync")
    return p.parse_args(argv)


def run_name(setting: str) -> str:
    return "ingest-" + setting.replace("+", "-")


def learner_argv(endpoint: str, run: str, ckpt: Path | None, fsync: str) -> list[str]:
    return [
        sys.executable, "-m", "services.cli", "learner", "--listen", endpoint, "--mode", "router",
        "--run", run, "--checkpoint-dir", str(ckpt) if ckpt else "", "--checkpoint-every", "0",
        "--wal-fsync", fsync, "--hidden-sizes", "16", "--batch-size", "16", "--learning-starts", "64",
        "--utd-ratio", "0.0005", "--broadcast-every", "1000", "--log-every", "30",
    ]  # fmt: skip


class PacedActor:
    """One actor thread: batches of ``batch`` transitions at ``rate`` batches/s, fresh seqs, through
    the real Outbox (``acks``) or straight to the publisher (no waiting)."""

    def __init__(self, session, run: str, name: str, batch: int, rate: float, acks: bool) -> None:
        import zenoh

        rng = np.random.default_rng(0)
        self.template = TransitionBatch(
            sender=f"{name}#{time.time_ns()}", seq=0, actor=name, model="nnql", policy_version=0,
            env_ids=np.arange(batch, dtype=np.int32) % 8, obs=rng.random((batch, OBS_DIM), dtype=np.float32),
            action=rng.integers(0, N_ACTIONS, batch), reward=rng.standard_normal(batch).astype(np.float32),
            next_obs=rng.random((batch, OBS_DIM), dtype=np.float32), terminated=np.zeros(batch, bool),
            truncated=np.zeros(batch, bool),
        )  # fmt: skip
        self.name, self.period, self.acks, self.sent = name, 1.0 / rate, acks, 0
        self.publisher = session.declare_publisher(
            keys.transitions(run, name), congestion_control=zenoh.CongestionControl.BLOCK
        )
        cfg = ActorConfig()
        self.outbox = Outbox(
            self.publisher.put,
            lambda: self.publisher.matching_status.matching,
            cfg.outbox_size,
            cfg.ack_window,
            cfg.ack_timeout,
        )
        self.ack_subscriber = session.declare_subscriber(keys.acks(run, name), self._on_ack)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _on_ack(self, sample) -> None:
        ack = decode(sample.payload.to_bytes())
        if isinstance(ack, Ack) and ack.actor == self.template.sender:
            self.outbox.on_ack(ack.accepted_seq)

    def _loop(self) -> None:
        due = time.monotonic()
        while not self.stop.is_set():
            now = time.monotonic()
            if now < due:
                time.sleep(due - now)
            due = max(due + self.period, now - 4 * self.period)  # behind: catch up by 4 batches at most
            self.sent += 1
            payload = encode(dataclasses.replace(self.template, seq=self.sent))
            if self.acks:
                self.outbox.put(self.sent, payload)
                self.outbox.flush(self.stop)
            else:
                self.publisher.put(payload)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)
        self.ack_subscriber.undeclare()
        self.publisher.undeclare()


def fresh_status(session, run: str, after_seq: int, timeout: float = 5.0) -> tuple[float, StatusReport]:
    """The learner refreshes its snapshot every 0.5 s: poll until a newer one than ``after_seq``
    appears, so its time is known to a poll interval (20 ms) instead of 0.5 s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = query_status(session, run, timeout=2.0)
        if status is not None and status.seq > after_seq:
            return time.monotonic(), status
        time.sleep(0.02)
    raise TimeoutError(f"no fresh status from the learner of run {run}")


def quiesce(session, run: str, seq: int, timeout: float = 15.0) -> int:
    """Wait until the learner stored everything still queued (its counter stands still)."""
    deadline = time.monotonic() + timeout
    _, status = fresh_status(session, run, seq)
    while time.monotonic() < deadline:
        _, newer = fresh_status(session, run, status.seq)
        if newer.counters.get("transitions_received") == status.counters.get("transitions_received"):
            return newer.seq
        status = newer
    return status.seq


def measure(session, setting: str, seq: int, label: str, offered: float, args) -> tuple[dict, int]:
    """One setting at one offered load: start the actors, measure ``args.seconds``, stop, wait until
    the learner is idle again (so nothing spills into the next measurement)."""
    run, rate = run_name(setting), offered / args.batch / ACTORS
    acks = setting != "off"
    actors = [PacedActor(session, run, f"{label}-{i}", args.batch, rate, acks) for i in range(ACTORS)]
    try:
        time.sleep(1.0)  # the inbox reaches its steady state
        t0, first = fresh_status(session, run, seq)
        sent0 = sum(a.sent for a in actors)
        time.sleep(max(args.seconds - 0.5, 0.1))
        t1, last = fresh_status(session, run, first.seq)
        sent1 = sum(a.sent for a in actors)
    finally:
        for a in actors:
            a.close()
    elapsed = t1 - t0

    def delta(name: str) -> int:
        return last.counters.get(name, 0) - first.counters.get(name, 0)

    dropped = sum(delta(f"dropped/sender_full/{a.name}") for a in actors) + delta("dropped/inbox_full")
    figures = {
        "stored_per_s": delta("transitions_received") / elapsed,
        "sent_per_s": (sent1 - sent0) * args.batch / elapsed,
        "dropped_per_s": dropped * args.batch / elapsed,
    }
    return figures, quiesce(session, run, last.seq)


def ratios(numerators: list[float], denominators: list[float]) -> dict | None:
    """summary() of the per-round ratios; None when a setting stored nothing in some round (the
    figures above say which), so the other figures still get printed."""
    if not all(denominators):
        return None
    return summary([n / d for n, d in zip(numerators, denominators, strict=True)])


def summary(values: list[float]) -> dict:
    return {
        "median": round(statistics.median(values), 3),
        "min": round(min(values), 3),
        "max": round(max(values), 3),
        "values": [round(v, 3) for v in values],
    }


def run_rounds(args: argparse.Namespace, sessions: dict, seqs: dict) -> list[dict]:
    """Warm-up plus ``args.rounds`` rounds; each: {(setting, offered): figures}. Warm-up dropped."""
    rounds = []
    for r in range(args.rounds + 1):
        order = SETTINGS[r % 3 :] + SETTINGS[: r % 3]
        figures = {}
        for i, offered in enumerate(args.offered):
            for setting in order:
                figures[setting, offered], seqs[setting] = measure(
                    sessions[setting], setting, seqs[setting], f"r{r}l{i}", offered, args
                )
            line = ", ".join(
                f"{s} {figures[s, offered]['stored_per_s']:.0f}"
                f" (dropped {figures[s, offered]['dropped_per_s']:.0f})"
                for s in SETTINGS
            )
            print(f"{'warm-up' if r == 0 else f'round {r}'}, offered {offered:.0f}/s: stored/s {line}")
        if r > 0:
            rounds.append(figures)
    return rounds


def run_ingest(args: argparse.Namespace, root: Path) -> dict:
    """Start one learner per setting, run the interleaved rounds, stop them; the figures."""
    learners, sessions, seqs = {}, {}, {}
    try:
        for setting in SETTINGS:
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            ckpt = root / "wal-learner" if setting == "acks+wal" else None
            argv = learner_argv(endpoint, run_name(setting), ckpt, args.wal_fsync)
            learners[setting] = start_learner(argv, root / f"{run_name(setting)}.log")
            sessions[setting] = open_session(
                ZenohSettings(connect=[endpoint], run=run_name(setting), connect_timeout=120)
            )
        for setting in SETTINGS:
            seqs[setting] = fresh_status(sessions[setting], run_name(setting), -1, timeout=180)[1].seq
        print(f"3 learners up; batches of {args.batch}, offered loads {args.offered} transitions/s")
        rounds = run_rounds(args, sessions, seqs)
    finally:
        for session in sessions.values():
            session.close()
        for learner in learners.values():
            stop_process(learner)

    def best(setting: str) -> list[float]:
        """Per round: the most the setting stored at any offered load (its ceiling)."""
        return [max(f[setting, o]["stored_per_s"] for o in args.offered) for f in rounds]

    off, acks, wal = best("off"), best("acks"), best("acks+wal")
    result = {
        "offered_per_s": args.offered,
        "batch": args.batch,
        "rounds": args.rounds,
        "seconds": args.seconds,
        "wal_fsync": args.wal_fsync,
        "ack_window": ActorConfig().ack_window,
    }
    for setting in SETTINGS:
        result[f"stored_per_s/{setting}"] = summary(best(setting))
        for o in args.offered:
            per_load = {k: summary([f[setting, o][k] for f in rounds]) for k in rounds[0][setting, o]}
            result[f"at_{o:.0f}/{setting}"] = {k: v["median"] for k, v in per_load.items()}
    result["ratio_acks_wal_vs_off"] = ratios(wal, off)
    result["ratio_acks_vs_off"] = ratios(acks, off)
    result["ratio_acks_wal_vs_acks"] = ratios(wal, acks)
    wal_vs_off = result["ratio_acks_wal_vs_off"]
    result["aim_met"] = wal_vs_off is not None and wal_vs_off["median"] >= 0.7
    return result


def report(result: dict) -> None:
    for setting in SETTINGS:
        s = result[f"stored_per_s/{setting}"]
        print(
            f"{setting:>9}: stored (best load per round) median {s['median']:.0f} transitions/s"
            f" (range {s['min']:.0f}-{s['max']:.0f})"
        )
    for name in ("ratio_acks_wal_vs_off", "ratio_acks_vs_off", "ratio_acks_wal_vs_acks"):
        r = result[name]
        if r is None:
            print(f"{name}: none (a setting stored nothing in some round)")
            continue
        print(
            f"{name}: median {r['median']:.2f} (range {r['min']:.2f}-{r['max']:.2f}, per round {r['values']})"
        )
    print(f"aim (acks+WAL >= 0.7 x off): {'met' if result['aim_met'] else 'NOT met'}")


def main() -> None:
    args = parse_args()
    with tempfile.TemporaryDirectory(prefix="navlearn-ingest-") as tmp:
        result = run_ingest(args, Path(tmp))
    report(result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
