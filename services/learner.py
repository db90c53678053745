"""The learner service: transitions in over Zenoh, NNQL updates at a bounded ratio, weights out.

Main thread only: it drains the inbox (filled by Zenoh callbacks) into the NNQL
learner's TorchRL replay while the rate limiter lets it insert, runs updates
while the limiter lets it train, broadcasts weights every ``broadcast_every``
updates, acknowledges each inserted batch to its actor (flow control), keeps the
status snapshot that the ``status/learner`` queryable serves, writes TensorBoard
scalars and checkpoints. ``run_learner`` does the process set-up around it.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.nnql.config import NNQLConfig
from protocols import keys
from protocols.codec import encode
from protocols.flow import Ack
from protocols.limits import Limits
from protocols.messages import DemoBatch, EvalReport, LearnerStatus, TransitionBatch
from services.checkpoint import CheckpointDir
from services.durable import DurableIngest
from services.inbox import Inbox, Received
from services.process import Scalars, connect
from services.ratelimit import RateLimiter
from services.stats import ActorStats, LagWindow, RateWindow
from services.status import eval_summary
from services.transport import ZenohSettings, declare_alive

log = logging.getLogger("navlearn.learner")
EXPLORATION_FIELDS = (
    "exploration",
    "temperature_start",
    "temperature_end",
    "temperature_decay_updates",
    "epsilon_start",
    "epsilon_end",
    "epsilon_decay_updates",
)


@dataclass
class LearnerConfig:
    """The learner service (NNQL hyper-parameters, incl. the update-to-data ratio, are NNQLConfig's)."""

    id: str = "learner"
    """learner id: its liveliness token is alive/learner/<id>"""
    model: str = "nnql"
    """model name: weights go out on weights/<model>"""
    checkpoint_dir: str = "runs/default/checkpoints"
    """where checkpoints go (ckpt-NNNNNNNN directories); empty: no checkpoints"""
    checkpoint_every: float = 300.0
    """seconds between checkpoints; one is also written on SIGTERM/SIGINT (0: only then)"""
    keep_checkpoints: int = 3
    """checkpoints kept; older ones are deleted"""
    resume: bool = True
    """resume from the newest checkpoint in checkpoint_dir if there is one"""
    broadcast_every: int = 50
    """updates between weight broadcasts (M)"""
    rate_tolerance: float = 64.0
    """updates the learner may run ahead of or fall behind the update-to-data ratio before waiting"""
    inbox_size: int = 256
    """transition batches waiting to be inserted; more are dropped and counted (dropped/inbox_full)"""
    demo_capacity: int = 200_000
    """demonstration steps kept (a separate buffer: actor transitions never evict demonstrations)"""
    tensorboard: str = ""
    """directory for TensorBoard scalars (charts/, losses/); empty: none"""
    log_every: float = 10.0
    """seconds between progress lines on stdout"""
    max_updates: int = 0
    """stop (with a checkpoint) after this many updates; 0: run until stopped"""
    wal_fsync: str = "always"
    """write-ahead log (checkpoint_dir/wal) fsync: always, never, or milliseconds between fsyncs"""
    nirl: bool = False
    """also train NIRL (thesis ch. 5) on the demonstrations and the actors' experience; weights/nirl"""
    nirl_updates: int = 1
    """NIRL updates per NNQL update once NIRL's warm start on the demonstrations is done"""


class LearnerService:
    """One NNQL learner behind Zenoh. Built by ``run_learner``; ``run(stop)`` is the main loop."""

    def __init__(
        self, config: LearnerConfig, learner, session, run: str, inbox: Inbox, demos, sender: str, nirl=None
    ):
        from services.weights import WeightsBroadcaster

        self.config = config
        self.learner = learner
        self.session = session
        self.run_name = run
        self.inbox = inbox
        self.demos = demos
        self.sender = sender
        self.nirl = nirl  # services.nirl_trainer.NIRLTrainer, or None
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

        def write(tmp: Path) -> None:
            self.learner.save_checkpoint(tmp / "nnql")
            self.demos.save(tmp / "demos")
            if self.nirl is not None:
                self.nirl.save(tmp / "nirl")
            state = {
                "limiter": self.limiter.state(),
                "counters": self.counters,
                "inbox_counts": self.inbox.counts(),
                "actors": {
                    a: {"transitions": s.transitions, "batches": s.batches} for a, s in self.actors.items()
                },
                "demo_episodes": self.demos.episodes,
                "last_eval": self.last_eval,
                "durable": self.durable.checkpoint_state() if self.durable else None,
            }
            (tmp / "service.json").write_text(json.dumps(state, indent=1) + "\n")

        path = self.checkpoints.save(write)
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
        self.learner.load_checkpoint(path / "nnql")
        state = json.loads((path / "service.json").read_text())
        self.limiter.load_state(state["limiter"])
        self.counters = {k: int(v) for k, v in state["counters"].items()}
        self.inbox.load_counts(state["inbox_counts"])
        for actor, saved in state["actors"].items():
            self.actors[actor] = ActorStats(transitions=saved["transitions"], batches=saved["batches"])
        self.demos.load(path / "demos", state["demo_episodes"])
        if self.nirl is not None:
            self.nirl.load(path / "nirl")
        self.last_eval = state["last_eval"]
        if self.durable is not None:
            self.durable.load_state(state.get("durable"))
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

    def _ingest(self, max_batches: int) -> bool:
        done = 0
        while done < max_batches and self.limiter.can_insert():
            try:
                item = self.inbox.transitions.get_nowait()
            except queue.Empty:
                break
            self._insert(item)
            done += 1
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
        restarted actor with the same id never takes its predecessor's acks for its own seqs."""
        self.ack_seq += 1
        ack = Ack(
            sender=self.sender,
            seq=self.ack_seq,
            actor=incarnation,
            accepted_seq=seq,
            policy_version=self.learner.version,
        )
        self.session.put(keys.acks(self.run_name, actor), encode(ack))

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
        counters = {**self.counters, **self.inbox.counts(), "updates": self.learner.version}
        if self.durable is not None:
            counters.update(self.durable.status_counters())
        counters["transitions_rejected"] = sum(v for k, v in counters.items() if k.startswith("rejected/"))
        rates = {
            "updates_per_s": self.update_rate.rate(),
            "transitions_per_s": self.insert_rate.rate(),
            "policy_lag": self.lags.mean(),
            "update_to_data": self.limiter.updates / max(self.limiter.inserts, 1),
        }
        for actor, stats in self.actors.items():
            rates[f"transitions_per_s/{actor}"] = stats.rate.rate()
            counters[f"transitions/{actor}"] = stats.transitions
        versions = {self.config.model: self.learner.version}
        losses = {k.removeprefix("losses/"): v for k, v in self.metrics.items() if k.startswith("losses/")}
        if self.nirl is not None:
            nirl_counters, nirl_losses = self.nirl.status_fields()
            counters.update(nirl_counters)
            losses.update(nirl_losses)
            versions["nirl"] = self.nirl.version
        self.status_seq += 1
        return LearnerStatus(
            sender=self.sender,
            seq=self.status_seq,
            counters=counters,
            rates=rates,
            versions=versions,
            replay_sizes={"transitions": len(self.learner.replay), "demos": len(self.demos)},
            actors_last_seen={a: s.last_seen for a, s in self.actors.items() if s.last_seen},
            losses=losses,
            last_eval=self.last_eval,
        )

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
    from services.demo_buffer import DemoBuffer
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
        from services.nirl_trainer import NIRLTrainer

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
