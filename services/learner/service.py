"""The learner service: transitions in over Zenoh, NNQL updates at a bounded ratio, weights out.

Main thread only: it drains the inbox (filled by Zenoh callbacks) into the NNQL
learner's TorchRL replay while the rate limiter lets it insert, runs updates
while the limiter lets it train, broadcasts weights every ``broadcast_every``
updates, acknowledges each inserted batch to its actor (flow control; the batches
drained together share one write-ahead-log fsync before their acks go out), keeps the
status snapshot that the ``status/learner`` queryable serves, writes TensorBoard
scalars and checkpoints. ``run_learner`` does the process set-up around it. Its settings
are in services.learner.config, what a checkpoint holds besides the networks in
services.learner.state, the status snapshot in services.learner.status.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any

from agents.nnql.config import NNQLConfig
from protocols import keys
from protocols.codec import encode
from protocols.flow import Ack
from protocols.limits import Limits
from protocols.messages import DemoBatch, EvalReport, LearnerStatus, TransitionBatch
from services.common.process import Scalars, connect
from services.common.transport import ZenohSettings, declare_alive
from services.learner.checkpoint import CheckpointDir
from services.learner.config import EXPLORATION_FIELDS, LearnerConfig
from services.learner.durable import DurableIngest
from services.learner.inbox import Inbox, Received
from services.learner.ratelimit import RateLimiter
from services.learner.state import load_service_state, write_service_state
from services.learner.stats import ActorStats, LagWindow, RateWindow
from services.learner.status import build_status
from services.ops.status import eval_summary

log = logging.getLogger("navlearn.learner")


class LearnerService:
    """One NNQL learner behind Zenoh. Built by ``run_learner``; ``run(stop)`` is the main loop."""

    def __init__(
        self, config: LearnerConfig, learner, session, run: str, inbox: Inbox, demos, sender: str, nirl=None
    ):
        from services.common.weights import WeightsBroadcaster

        self.config = config
        self.learner = learner
        self.session = session
        self.run_name = run
        self.inbox = inbox
        self.demos = demos
        self.sender = sender
        self.nirl = nirl  # services.learner.nirl.NIRLTrainer, or None
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
        self.actors: dict[str, ActorStats] = {}
        self.lags = LagWindow()
        self.update_rate = RateWindow()
        self.insert_rate = RateWindow()
        self.metrics: dict[str, float] = {}
        self.last_eval: dict[str, Any] | None = None
        self.counters: dict[str, int] = {}
        self.status_bytes: bytes = b""
        self.status_seq = 0
        self.ack_seq = 0
        self._unacked: list[tuple[str, int, str]] = []  # (key name, seq, incarnation) awaiting commit
        self.durable = (
            DurableIngest(Path(config.checkpoint_dir) / "wal", config.wal_fsync)
            if config.checkpoint_dir
            else None
        )  # write-ahead log + duplicate filter: acknowledged means durably stored
        self._replaying = False
        self.weights = WeightsBroadcaster(session, run, config.model, sender)
        self._status_queryable = session.declare_queryable(keys.status(run), self._on_status, complete=True)

    # ---------------------------------------------------------------- checkpoints

    def save_checkpoint(self) -> Path | None:
        if self.checkpoints is None:
            return None
        start = time.perf_counter()

        path = self.checkpoints.save(lambda tmp: write_service_state(self, tmp))
        if self.durable is not None:
            self.durable.checkpointed()
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
        load_service_state(self, path)
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
            item = Received(record.channel, record.name, record.message, time.time())
            if record.channel == "transitions":
                self._insert(item)
            else:
                self.inbox.other.put(item)
                self._drain_other()
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
            busy = self._drain_other()
            busy |= self._ingest(max_batches=16)
            busy |= self._train(max_updates=32)
            busy |= self._train_nirl()
            if not busy:
                self._wait_for_data(0.05)
            now = time.monotonic()
            if now >= next_status:
                self.refresh_status()
                next_status = now + 0.5
            if now >= next_log:
                self._log_progress()
                next_log = now + cfg.log_every
            if now >= next_checkpoint:
                self.save_checkpoint()
                next_checkpoint = time.monotonic() + cfg.checkpoint_every
        self.broadcast()
        self.save_checkpoint()
        self.refresh_status()
        return 0

    def _wait_for_data(self, timeout: float) -> None:
        if not self.limiter.can_insert():
            time.sleep(timeout)  # cannot happen with tolerance >= 1, kept as a guard against a busy loop
            return
        try:
            item = self.inbox.transitions.get(timeout=timeout)
        except queue.Empty:
            return
        self._insert(item)
        self._commit()

    def _ingest(self, max_batches: int) -> bool:
        done = 0
        while done < max_batches and self.limiter.can_insert():
            try:
                item = self.inbox.transitions.get_nowait()
            except queue.Empty:
                break
            self._insert(item)
            done += 1
        self._commit()
        return done > 0

    def _insert(self, item: Received) -> None:
        batch: TransitionBatch = item.message
        obs_dim = self.learner.architecture["obs_dim"]
        if batch.obs.shape[1] != obs_dim:
            self.inbox.reject(
                "shape", f"batch from {item.name} has obs_dim {batch.obs.shape[1]}, not {obs_dim}"
            )
            return
        if self.durable is not None and not self._replaying and not self.durable.admit(batch):
            self._ack(item.name, batch.seq, batch.sender)  # a resend of a stored batch: ack it again
            return
        n = self.learner.add(batch)
        self.limiter.inserted(n)
        self.insert_rate.add(n)
        self.lags.add(self.learner.version - batch.policy_version)
        self.actors.setdefault(item.name, ActorStats()).add(n, batch.seq, item.arrived)
        self._count("transitions_received", n)
        self._count("batches_received")
        self._ack(item.name, batch.seq, batch.sender)

    def _ack(self, actor: str, seq: int, incarnation: str) -> None:
        """Acknowledge batch ``seq`` of ``incarnation`` (its envelope sender, ``<id>#<start>``), so a
        restarted actor with the same id never takes its predecessor's acks for its own seqs. The ack
        goes out at the next ``_commit``, once the write-ahead log holds the batch durably."""
        self._unacked.append((actor, seq, incarnation))

    def _commit(self) -> None:
        """Group commit: one write-ahead-log sync for the batches logged since the last commit,
        then their acknowledgements."""
        if not self._unacked:
            return
        if self.durable is not None:
            self.durable.sync()
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

    def _train(self, max_updates: int) -> bool:
        ran = 0
        replay_size = len(self.learner.replay)
        while ran < max_updates and self.limiter.can_update(replay_size):
            self.metrics = self.learner.update()
            self.limiter.updated()
            self.update_rate.add()
            ran += 1
            if self.learner.version % self.config.broadcast_every == 0:
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

    def _drain_other(self) -> bool:
        busy = False
        while True:
            try:
                item = self.inbox.other.get_nowait()
            except queue.Empty:
                self._commit()
                return busy
            busy = True
            if isinstance(item.message, DemoBatch):
                if item.message.obs.shape[1] != self.learner.architecture["obs_dim"]:
                    self.inbox.reject("shape", f"demos from {item.name} have the wrong obs_dim")
                    continue
                if self.durable is not None and not self._replaying and not self.durable.admit(item.message):
                    self._ack(item.name, item.message.seq, item.message.sender)  # a resend: ack again
                    continue
                steps = self.demos.add(item.message)
                self._ack(item.name, item.message.seq, item.message.sender)
                self._count("demo_steps", steps)
                self._count("demo_batches")
                self._count(f"demo_steps/{item.message.source}", steps)
                self._count(f"demo_episodes/{item.message.source}", len(item.message.episode_lengths))
            elif isinstance(item.message, EvalReport):
                self._on_eval(item)

    def _on_eval(self, item: Received) -> None:
        self._count("eval_reports")
        self.last_eval = eval_summary(item.name, item.message, item.arrived)
        families = self.last_eval["families"]
        log.info(
            "eval report from %s for version %d: %s",
            item.name,
            item.message.policy_version,
            ", ".join(f"{f} success {s['success']}" for f, s in families.items()),
        )

    def broadcast(self) -> None:
        nnql: NNQLConfig = self.learner.config
        architecture = dict(self.learner.architecture)
        architecture["exploration"] = {name: getattr(nnql, name) for name in EXPLORATION_FIELDS}
        self.weights.publish(self.learner.get_weights(), self.learner.version, architecture)
        self._count("weights_broadcast")
        if self.nirl is not None:
            self.nirl.broadcast()

    def _count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + int(n)

    # ---------------------------------------------------------------- status

    def status(self) -> LearnerStatus:
        self.status_seq += 1
        return build_status(self, self.status_seq)

    def refresh_status(self) -> None:
        status = self.status()
        self.status_bytes = encode(status)
        charts = {
            "charts/updates_per_s": status.rates["updates_per_s"],
            "charts/transitions_per_s": status.rates["transitions_per_s"],
            "charts/policy_lag": status.rates["policy_lag"],
            "charts/replay_size": status.replay_sizes["transitions"],
            "charts/update_to_data": status.rates["update_to_data"],
        }
        charts.update({k: v for k, v in self.metrics.items() if k.startswith("losses/")})
        charts.update({k: v for k, v in status.losses.items() if k.startswith("nirl/")})  # learned reward too
        self.scalars.add(charts, self.learner.version)

    def _on_status(self, query) -> None:
        query.reply(keys.status(self.run_name), self.status_bytes)

    def _log_progress(self) -> None:
        s = self.status()
        log.info(
            "version %d | replay %d | %.0f upd/s | %.0f transitions/s | lag %.1f | actors %d | rejected %d"
            " | td %.4g",
            self.learner.version,
            s.replay_sizes["transitions"],
            s.rates["updates_per_s"],
            s.rates["transitions_per_s"],
            s.rates["policy_lag"],
            len(self.actors),
            s.counters["transitions_rejected"],
            self.metrics.get("losses/td_loss", float("nan")),
        )

    def close(self) -> None:
        self._status_queryable.undeclare()
        if self.durable is not None:
            self.durable.close()
        self.weights.close()
        if self.nirl is not None:
            self.nirl.close()
        self.scalars.close()


def run_learner(
    config: LearnerConfig, nnql: NNQLConfig, settings: ZenohSettings, stop: threading.Event, nirl=None
) -> int:
    """Process set-up: learner, Zenoh session (hosting the router unless told to connect), the loop.
    ``nirl`` (an agents.nirl NIRLConfig) configures NIRL when ``config.nirl`` is on."""
    from agents.nnql.learner import NNQLLearner
    from services.learner.demo_buffer import DemoBuffer
    from worlds.config import NavConfig
    from worlds.env import observation_space

    nav = NavConfig()
    obs_dim, n_actions = int(observation_space(nav).shape[0]), nav.robot.n_actions
    learner = NNQLLearner(nnql, obs_dim, n_actions)
    demos = DemoBuffer(config.demo_capacity, obs_dim, seed=nnql.seed)
    limits = Limits(n_actions=n_actions, max_obs_dim=obs_dim)
    inbox = Inbox(limits, config.inbox_size, settings.run, log_every=config.log_every)
    session = connect(settings, stop)
    if session is None:
        return 0
    sender = f"{config.id}#{int(time.time())}"
    trainer = None
    if config.nirl:
        from agents.nirl.config import NIRLConfig
        from services.learner.nirl import NIRLTrainer

        nirl = nirl or NIRLConfig(seed=nnql.seed)
        trainer = NIRLTrainer(
            nirl, learner.replay, demos.replay, session, settings.run, sender, config.broadcast_every
        )
    service = LearnerService(config, learner, session, settings.run, inbox, demos, sender, nirl=trainer)
    try:
        if config.resume and service.checkpoints is not None and (latest := service.checkpoints.latest()):
            service.resume(latest)
        service.replay_log()
        subscribers = inbox.subscribe(session)
        token = declare_alive(session, settings.run, "learner", config.id)
        log.info(
            "learner %s up (%s mode), run %s, version %d",
            config.id,
            settings.mode,
            settings.run,
            learner.version,
        )
        code = service.run(stop)
        token.undeclare()
        for subscriber in subscribers:
            subscriber.undeclare()
        return code
    finally:
        service.close()
        session.close()
        log.info("learner stopped")
