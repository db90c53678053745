"""The learner service: transitions in over Zenoh, NNQL updates at a bounded ratio, weights out.

Main thread only: it drains the inbox (filled by Zenoh callbacks) into the NNQL
learner's TorchRL replay while the rate limiter lets it insert, runs updates
while the limiter lets it train, broadcasts weights every ``broadcast_every``
updates, acknowledges each inserted batch to its actor (flow control; the batches
drained together share one write-ahead-log fsync before their acks go out), keeps the
status snapshot that the ``status/learner`` queryable serves, writes TensorBoard
scalars and checkpoints. A failing disk write (write-ahead log or checkpoint) stops intake and
acknowledgements until a retry works (services.learner.storage); the loop, status and SIGTERM
go on. ``services.learner.run.run_learner`` does the process set-up around it. Its settings
are in services.learner.config, what a checkpoint holds besides the networks in
services.learner.state, the status snapshot in services.learner.status.
"""

from __future__ import annotations

import logging
import pickle
import queue
import threading
import time
from pathlib import Path

import agents.evaluation.policies  # noqa: F401 - save_policy_dir imports it lazily (~2.5 s): not in a checkpoint
from agents.nnql.learner import NNQLLearner
from agents.nnql.ratelimit import RateLimiter
from agents.replay_files import stored_bytes
from protocols import keys
from protocols.codec import encode
from protocols.flow import Ack
from protocols.messages import (
    OWN_WORLD,
    DemoBatch,
    EvalReport,
    ExplorationSchedule,
    StatusReport,
    TransitionBatch,
)
from services.common.process import Scalars
from services.common.weights import WeightsBroadcaster
from services.learner.checkpoint import CheckpointDir
from services.learner.config import LearnerConfig
from services.learner.demo_buffer import DemoBuffer
from services.learner.durable import DurableIngest
from services.learner.inbox import Inbox, Received
from services.learner.nirl import NIRLTrainer
from services.learner.state import LearnerParts, checkpoint_wal_seq
from services.learner.stats import LearnerTally
from services.learner.status import build_status, progress_line, status_charts
from services.learner.storage import StorageGuard
from services.ops.status import eval_summary

log = logging.getLogger("navlearn.learner")

# Updates per NNQLLearner.update call: several amortise the call (bench/learner.py: 1.25 of a bare
# update with 16, 1.08 with one) while a slice of them stays near 20 ms.
UPDATES_PER_CALL = 8


class LearnerService:
    """One NNQL learner behind Zenoh. Built by ``run_learner`` (services.learner.run); ``run(stop)`` is
    the main loop; a context manager that closes what it declared."""

    def __init__(
        self,
        config: LearnerConfig,
        learner: NNQLLearner,
        session,
        run: str,
        inbox: Inbox,
        demos: DemoBuffer,
        sender: str,
        nirl: NIRLTrainer | None = None,
        env: str = OWN_WORLD,
    ):
        """``env``: the signature of the env this run trains on (worlds.own_env.EnvConfig.signature);
        transition batches of another env are refused, naming both."""
        self.config = config
        self.env = env
        self.learner = learner
        self.session = session
        self.run_name = run
        self.inbox = inbox
        self.demos = demos
        self.sender = sender
        self.nirl = nirl
        self.nnql_ran = 0  # NNQL updates in the last loop (NIRL's pace once warm)
        nnql = learner.config
        self.limiter = RateLimiter(
            nnql.utd_ratio, max(nnql.learning_starts, nnql.batch_size), config.rate_tolerance
        )
        self.checkpoints = (
            CheckpointDir(config.checkpoint_dir, config.keep_checkpoints) if config.checkpoint_dir else None
        )
        if self.checkpoints is not None:
            self.checkpoints.remove_unfinished()
        self.scalars = Scalars(config.tensorboard)
        self.tally = LearnerTally()
        self.status_bytes: bytes = b""
        self.status_seq = 0
        self.ack_seq = 0
        self._unacked: list[tuple[str, int, str]] = []  # (key name, seq, incarnation) awaiting commit
        self._pending: list[Received] = []  # logged, stored and acknowledged once the log is synced
        self.durable = (
            DurableIngest(Path(config.checkpoint_dir) / "wal", config.wal_fsync, inbox.limits)
            if config.checkpoint_dir
            else None
        )  # write-ahead log + duplicate filter: acknowledged means durably stored
        self.storage = StorageGuard()
        self._replaying = False
        self.parts = LearnerParts(
            learner, demos, self.limiter, inbox, self.tally, self.durable, nirl, self.storage
        )
        """the typed view that checkpoints and the status snapshot are made from"""
        self.weights = WeightsBroadcaster(session, run, config.model, sender)
        self._status_queryable = session.declare_queryable(keys.status(run), self._on_status, complete=True)

    # ---------------------------------------------------------------- checkpoints

    def save_checkpoint(self) -> Path | None:
        if self.checkpoints is None:
            return None
        start = time.perf_counter()
        estimate = stored_bytes(self.learner.replay) + stored_bytes(self.demos.replay)
        try:
            path = self.checkpoints.save(self.parts.write, estimate)
        except Exception as exc:  # ENOSPC, EIO, or a library's own wrapper of them (torch: RuntimeError)
            self.storage.failed("checkpoint", self.checkpoints.root, exc, time.monotonic())
            return None
        self.storage.succeeded()
        if self.durable is not None:
            try:  # keep the log the oldest kept checkpoint needs (a resume from it if newer ones are damaged)
                self.durable.checkpointed(checkpoint_wal_seq(self.checkpoints.all()[0]))
            except OSError as exc:
                self.storage.failed("write-ahead log", self.durable.path, exc, time.monotonic())
        self._count("checkpoints")
        log.info(
            "checkpoint %s (version %d, replay %d) in %.2f s",
            path,
            self.learner.version,
            len(self.learner.replay),
            time.perf_counter() - start,
        )
        return path

    def resume(self, path: Path) -> None:
        try:
            self.parts.load(path)
        except (ValueError, KeyError, TypeError, OSError, RuntimeError, pickle.UnpicklingError) as exc:
            raise ValueError(
                f"checkpoint {path} matches its checksums but does not load here "
                f"({type(exc).__name__}: {exc}); was it written with other settings?"
            ) from exc
        log.info(
            "resumed from %s: version %d, replay %d, demos %d",
            path,
            self.learner.version,
            len(self.learner.replay),
            len(self.demos),
        )

    def replay_log(self) -> None:
        """Insert again what the write-ahead log holds after the checkpoint (before subscribing)."""
        if self.durable is None:
            return
        self._replaying = True
        for record in self.durable.replay():
            self._insert(Received(record.channel, record.name, record.message, time.time()))
        self._commit()
        self._replaying = False
        log.info("write-ahead log replayed: %s", self.durable.status_counters())

    # ---------------------------------------------------------------- the loop

    def run(self, stop: threading.Event) -> int:
        cfg = self.config
        self.broadcast()
        self.refresh_status()
        now = time.monotonic()
        next_status, next_log = now + 0.5, now + cfg.log_every
        next_checkpoint = now + cfg.checkpoint_every if cfg.checkpoint_every > 0 else float("inf")
        while not stop.is_set():
            if cfg.max_updates and self.learner.version >= cfg.max_updates:
                log.info("reached %d updates", cfg.max_updates)
                break
            blocked = self.storage.blocked(time.monotonic())
            busy = self._drain_other(blocked)
            busy |= not blocked and self._ingest(max_batches=16)
            busy |= self._train(max_updates=32)
            busy |= self._train_nirl()
            if not busy and blocked:
                time.sleep(0.05)  # storage is failing: nothing to take in until the retry
            elif not busy:
                self._wait_for_data(0.05)
            now = time.monotonic()
            if self.storage.what == "checkpoint" and not self.storage.blocked(now):
                next_checkpoint = now  # retry the checkpoint that failed
            if now >= next_status:
                self.refresh_status()
                next_status = now + 0.5
            if now >= next_log:
                self._log_progress()
                next_log = now + cfg.log_every
            if self.storage.due(now, next_checkpoint):  # not while a failure waits for its retry
                self.save_checkpoint()
                next_checkpoint = time.monotonic() + cfg.checkpoint_every
        self.broadcast()
        self.save_checkpoint()  # a failure is logged; the write-ahead log holds what was acknowledged
        self.refresh_status()
        return 0

    def _wait_for_data(self, timeout: float) -> None:
        """Idle: wait for a batch, or sleep when the next one waits for the rate limiter (cannot
        happen while updates are possible: kept as a guard against a busy loop)."""
        if self.inbox.transitions.qsize():
            time.sleep(timeout)
        elif self.inbox.transitions.wait(timeout):
            self._ingest(max_batches=1)

    def _ingest(self, max_batches: int) -> bool:
        """Insert up to ``max_batches`` batches, in the inbox's fair order, each once the rate limiter
        has room for its rows (a batch waits for the updates it owes; it never jumps ahead)."""
        done = 0
        admitted = 0  # rows taken in this call: they reach the limiter at the commit
        while done < max_batches and not self.storage.blocked(time.monotonic()):
            item = self.inbox.transitions.peek()
            if item is None or not self.limiter.can_insert(admitted + len(item.message)):
                break
            self._insert(self.inbox.transitions.get_nowait())
            admitted += len(item.message)
            done += 1
        self._commit()
        return done > 0

    def _insert(self, item: Received) -> None:
        """A transition or demonstration batch: checked, logged, then stored and acknowledged at the
        next ``_commit`` (at once when there is no log, or when it comes from the log's replay)."""
        message = item.message
        if isinstance(message, TransitionBatch) and message.env != self.env:
            self.inbox.reject(
                "env",
                f"refused transitions from actor {item.name}: it runs env {message.env!r}, this learner "
                f"trains on env {self.env!r} (start the actor with the learner's --env, or give another "
                "--run)",
            )
            return
        obs_dim, obs = self.learner.architecture["obs_dim"], item.message.obs
        if obs.shape[1] != obs_dim:
            self.inbox.reject(
                "shape", f"{item.channel} from {item.name} have obs_dim {obs.shape[1]}, not {obs_dim}"
            )
            return
        if self.durable is None or self._replaying:
            self._store(item)
            return
        try:
            fresh = self.durable.admit(item.message, item.payload)
        except OSError as exc:
            self._storage_failed(exc, also_lost=1)
            return
        if fresh:
            self._pending.append(item)
        else:  # a resend of a stored batch: acknowledge it again
            self._ack(item.name, item.message.seq, item.message.sender)

    def _store(self, item: Received) -> None:
        """Insert a (durably logged) batch into its buffer, count it and queue its acknowledgement."""
        message = item.message
        if isinstance(message, DemoBatch):
            steps = self.demos.add(message)
            self._count("demo_steps", steps)
            self._count("demo_batches")
            self._count(f"demo_steps/{message.source}", steps)
            self._count(f"demo_episodes/{message.source}", len(message.episode_lengths))
        else:
            n = self.learner.add(message)
            self.limiter.inserted(n)
            self.tally.inserted(
                item.name, n, message.seq, item.arrived, self.learner.version - message.policy_version
            )
        self._ack(item.name, message.seq, message.sender)

    def _storage_failed(self, exc: OSError, also_lost: int = 0) -> None:
        """The log could not take the group: none of it is stored or acknowledged (actors resend)."""
        self.storage.failed("write-ahead log", self.durable.path, exc, time.monotonic())
        self._count("batches_not_stored", len(self._pending) + also_lost)
        self._pending.clear()
        self._unacked.clear()

    def _ack(self, actor: str, seq: int, incarnation: str) -> None:
        """Acknowledge batch ``seq`` of ``incarnation`` (its envelope sender, ``<id>#<start>``), so a
        restarted actor with the same id never takes its predecessor's acks for its own seqs. The ack
        goes out at the next ``_commit``, once the write-ahead log holds the batch durably."""
        self._unacked.append((actor, seq, incarnation))

    def _commit(self) -> None:
        """Group commit: one write-ahead-log sync for the batches logged since the last commit,
        then their acknowledgements."""
        if self._pending:
            try:
                self.durable.sync()
            except OSError as exc:
                self._storage_failed(exc)
                return
            self.storage.succeeded()
            for item in self._pending:
                self._store(item)
            self._pending.clear()
        for actor, seq, incarnation in self._unacked:
            self.ack_seq += 1
            ack = Ack(
                sender=self.sender,
                seq=self.ack_seq,
                actor=incarnation,
                accepted_seq=seq,
                policy_version=self.learner.version,
            )
            self.session.put(keys.acks(self.run_name, actor), encode(ack))
        self._unacked.clear()

    def _train(self, max_updates: int, max_seconds: float = 0.02) -> bool:
        """Up to ``max_updates`` updates the rate limiter allows, for about ``max_seconds`` (a batch
        waiting in the inbox waits one slice, not a burst of updates, before it goes in), several per
        ``update`` call: each call runs up to the next broadcast, at most ``UPDATES_PER_CALL``."""
        every = self.config.broadcast_every
        replay_size = len(self.learner.replay)
        until = time.monotonic() + max_seconds
        ran = 0
        while ran == 0 or time.monotonic() < until:
            allowed = min(max_updates - ran, self.limiter.updates_allowed(replay_size))
            if allowed <= 0:
                break
            count = min(allowed, UPDATES_PER_CALL, every - self.learner.version % every)
            self.tally.metrics = self.learner.update(count)
            self.limiter.updated(count)
            self.tally.update_rate.add(count)
            ran += count
            if self.learner.version % every == 0:
                self.broadcast()
        self.nnql_ran = ran
        return ran > 0

    def _train_nirl(self) -> bool:
        """NIRL's updates: its warm start on the demonstrations (8 per loop, also while no actor
        sends), then ``nirl_updates`` per NNQL update, so it never spins on data that does not grow."""
        if self.nirl is None:
            return False
        learner = self.nirl.learner
        warming = learner.warm_updates < learner.config.warmstart_updates
        due = 8 if warming else self.config.nirl_updates * self.nnql_ran
        return self.nirl.train(due) > 0

    def _drain_other(self, blocked: bool = False) -> bool:
        """Demonstrations (dropped and counted while storage is failing: their sender resends) and
        evaluation reports."""
        busy = False
        while True:
            try:
                item = self.inbox.other.get_nowait()
            except queue.Empty:
                self._commit()
                return busy
            busy = True
            if isinstance(item.message, DemoBatch):
                if blocked:
                    self.inbox.count("dropped/storage_error")
                else:
                    self._insert(item)
            elif isinstance(item.message, EvalReport):
                self._on_eval(item)

    def _on_eval(self, item: Received) -> None:
        self._count("eval_reports")
        self.tally.last_eval = eval_summary(item.name, item.message, item.arrived)
        families = self.tally.last_eval["families"]
        log.info(
            "eval report from %s for version %d: %s",
            item.name,
            item.message.policy_version,
            ", ".join(
                f"{f} success {s['success']}" if s.get("return") is None else f"{f} return {s['return']:.1f}"
                for f, s in families.items()
            ),
        )

    def broadcast(self) -> None:
        exploration = ExplorationSchedule.of(self.learner.config)
        learner = self.learner
        self.weights.publish(
            learner.get_weights(),
            learner.version,
            learner.architecture,
            exploration,
            learner.observation,
            self.env,
        )
        self._count("weights_broadcast")
        if self.nirl is not None:
            self.nirl.broadcast()

    def _count(self, name: str, n: int = 1) -> None:
        self.tally.count(name, n)

    # ---------------------------------------------------------------- status

    def status(self) -> StatusReport:
        self.status_seq += 1
        # a Gymnasium --env has no navlearn observation: the status says the env instead
        observation = self.config.observation if self.env == OWN_WORLD else f"env {self.env}"
        return build_status(self.parts, self.config.model, observation, self.sender, self.status_seq)

    def refresh_status(self) -> None:
        status = self.status()
        self.status_bytes = encode(status)
        charts = status_charts(status, self.tally.metrics)
        self.scalars.add(charts, self.learner.version)

    def _on_status(self, query) -> None:
        query.reply(keys.status(self.run_name), self.status_bytes)

    def _log_progress(self) -> None:
        log.info("%s", progress_line(self.status(), self.tally))

    def __enter__(self) -> LearnerService:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._status_queryable.undeclare()
        if self.durable is not None:
            self.durable.close()
        self.weights.close()
        if self.nirl is not None:
            self.nirl.close()
        self.scalars.close()
