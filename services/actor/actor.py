"""The actor service: N robots stepped with the newest policy, transition batches out over Zenoh.

The actor is handed its weight source (a WeightsReceiver) and its outbox (Acme's
actor/variable-source split); ``run_actor`` does the set-up and SEED RL's outer
loop: it builds the env from a factory and retries the Zenoh connection until a
router answers. Once connected, Zenoh itself re-establishes a lost router link
(subscriptions, queryables and the liveliness token come back with it); batches
made meanwhile wait in the outbox and the newest weights are asked for again.
Until the first weights arrive the robots act uniformly at random (version 0).
The actor answers ``status/actor:<id>`` (services.actor.status): outbox, acknowledgements,
back-pressure, robot-steps and weights version.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
import socket
import threading
import time
import zlib
from collections import deque

import numpy as np

from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import TransitionBatch
from services.actor.config import ActorConfig
from services.actor.status import BACKPRESSURE_SHARE, BlockedShare, actor_status
from services.common.outbox import Outbox, decode_ack
from services.common.process import connect
from services.common.transport import ZenohSettings, declare_alive
from services.common.weights import WeightsReceiver, split_architecture
from services.ops.acl import actor_status_key

log = logging.getLogger("navlearn.actor")
SUCCESS = 1  # worlds.outcomes.Outcome.GOAL


def default_actor_id() -> str:
    """``<hostname>-<pid>`` reduced to the characters a key chunk allows."""
    host = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname()).strip(".-") or "actor"
    return f"{host[:40]}-{os.getpid()}"


def seed_for(actor_id: str) -> int:
    """A stable seed per actor id, so actors started without --seed do not repeat each other."""
    return zlib.crc32(actor_id.encode()) % (2**31)


def concat_batches(pieces: list[dict[str, np.ndarray]], num_envs: int) -> dict[str, np.ndarray]:
    """K rollout batches of ``num_envs`` transitions as one flat batch, plus ``env_ids``."""
    out = {name: np.concatenate([p[name] for p in pieces]) for name in pieces[0] if name != "next_action"}
    out["env_ids"] = np.tile(np.arange(num_envs, dtype=np.int32), len(pieces))
    return out


class Actor:
    """Steps a VectorRollout, publishes TransitionBatches through an Outbox, swaps in new weights."""

    def __init__(self, config: ActorConfig, env, session, run: str, seed: int, limits: Limits) -> None:
        import zenoh

        from agents.nnql.rollout import VectorRollout

        self.config = config
        self.run_name = run
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.n_actions = int(env.single_action_space.n)
        self.policy = None
        self.version = 0
        self.exploration = None
        self.rollout = VectorRollout(env, self.act)
        self.receiver = WeightsReceiver(session, run, config.model, limits)
        self.publisher = session.declare_publisher(
            keys.transitions(run, config.id), congestion_control=zenoh.CongestionControl.BLOCK
        )
        self.outbox = Outbox(
            self.publisher.put,
            lambda: self.publisher.matching_status.matching,
            capacity=config.outbox_size,
            window=config.ack_window,
            ack_timeout=config.ack_timeout,
        )
        self.acks = session.declare_subscriber(keys.acks(run, config.id), self._on_ack)
        self.blocked = BlockedShare()
        """share of time waiting for the learner (back-pressure), for the status and the log"""
        self.status_seq = 0
        self.status_key = actor_status_key(run, config.id)
        self._status = session.declare_queryable(self.status_key, self._on_status, complete=True)
        self._steps_window: deque[tuple[float, int]] = deque(maxlen=64)
        self.learner_version = 0
        self.seq = 0
        self.sender = f"{config.id}#{time.time_ns() // 1_000_000}"
        """this incarnation: the learner de-duplicates by (sender, seq), and seq restarts with the process"""
        self.weights_applied = 0
        self.episodes: deque[int] = deque(maxlen=100)
        self.episodes_done = 0
        self.reachable = True

    def _on_status(self, query) -> None:
        self.status_seq += 1
        query.reply(self.status_key, encode(actor_status(self, self.status_seq)))

    def steps_rate(self) -> float:
        """Robot-steps per second over the last ticks."""
        if len(self._steps_window) < 2:
            return 0.0
        (t0, s0), (t1, s1) = self._steps_window[0], self._steps_window[-1]
        return (s1 - s0) / (t1 - t0) if t1 > t0 else 0.0

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.policy is None:
            return self.rng.integers(0, self.n_actions, size=len(obs), dtype=np.int64)
        return self.policy(obs)

    def _on_ack(self, sample) -> None:
        ack = decode_ack(sample.payload.to_bytes(), self.sender)
        if ack is not None:
            self.learner_version = max(self.learner_version, ack.policy_version)
            self.outbox.on_ack(ack.accepted_seq)

    def apply_weights(self) -> bool:
        """Swap in the newest weights if any arrived; True if the policy changed."""
        from agents.nnql.config import NNQLConfig
        from agents.nnql.policy import NNQLPolicy

        received = self.receiver.take()
        if received is None:
            return False
        message = received.message
        network, exploration = split_architecture(message.architecture)
        try:
            if self.policy is None or self.policy.architecture != network:
                self.policy = NNQLPolicy(message.tensors, network, version=message.version, seed=self.seed)
            else:
                self.policy.set_weights(message.tensors, message.version)
            known = {f.name for f in dataclasses.fields(NNQLConfig)}  # a newer learner may send more
            self.exploration = NNQLConfig(**{k: v for k, v in exploration.items() if k in known})
        except (ValueError, TypeError, KeyError) as exc:
            log.warning("ignoring weights version %d: %s", message.version, exc)
            return False
        self.policy.explore_as(self.exploration, message.version)
        self.version = message.version
        self.weights_applied += 1
        if self.rollout.obs is not None:  # act on the next step with the new policy already
            self.rollout.actions = self.act(self.rollout.obs)
        return True

    def step_batch(self) -> TransitionBatch:
        """``batch_steps`` vector steps as one TransitionBatch (all from one policy version)."""
        pieces = []
        for _ in range(self.config.batch_steps):
            batch, ended = self.rollout.step()
            pieces.append(batch)
            for episode in ended:
                self.episodes.append(int(episode.outcome == SUCCESS))
            self.episodes_done += len(ended)
        flat = concat_batches(pieces, self.rollout.num_envs)
        self.seq += 1
        return TransitionBatch(
            sender=self.sender,
            seq=self.seq,
            actor=self.config.id,
            model=self.config.model,
            policy_version=self.version,
            **flat,
        )

    def tick(self, stop: threading.Event) -> None:
        """One round: newest weights in, ``batch_steps`` vector steps, the batch out (waiting for the
        learner's acknowledgements while the window is full)."""
        reachable = self.publisher.matching_status.matching
        if reachable and not self.reachable:
            log.info("learner reachable again; asking for its newest weights")
            self.receiver.request_latest()
        self.reachable = reachable
        self.apply_weights()
        batch = self.step_batch()
        self.outbox.put(batch.seq, encode(batch))
        self.outbox.flush(stop)
        now = time.monotonic()
        self.blocked.add(self.outbox.blocked_s, now)
        self._steps_window.append((now, self.rollout.steps))

    def run(self, stop: threading.Event) -> int:
        cfg = self.config
        self.receiver.request_latest()
        self.rollout.reset(seed=self.seed)
        start = last_log = time.monotonic()
        steps_at_log = 0
        while not stop.is_set() and not (cfg.max_steps and self.rollout.steps >= cfg.max_steps):
            self.tick(stop)
            now = time.monotonic()
            if now - last_log >= cfg.log_every:
                rate = (self.rollout.steps - steps_at_log) / (now - last_log)
                self._log_progress(rate, self.reachable)
                last_log, steps_at_log = now, self.rollout.steps
        log.info(
            "actor %s done: %d robot-steps in %.0f s, %d batches sent, %d unsent",
            cfg.id,
            self.rollout.steps,
            time.monotonic() - start,
            self.outbox.sent,
            len(self.outbox),
        )
        return 0

    def _log_progress(self, rate: float, reachable: bool) -> None:
        success = np.mean(self.episodes) if self.episodes else float("nan")
        log.info(
            "%.0f robot-steps/s | version %d (learner %d, lag %d) | episodes %d, success %.0f%% (last %d) | "
            "sent %d, outbox %d (unacknowledged %d, resent %d)%s%s",
            rate,
            self.version,
            self.learner_version,
            max(self.learner_version - self.version, 0),
            self.episodes_done,
            100 * success,
            len(self.episodes),
            self.outbox.sent,
            len(self.outbox),
            self.outbox.in_flight,
            self.outbox.resent,
            "" if reachable else " | learner unreachable",
            f" | back-pressure: waiting for the learner {100 * share:.0f}% of the time"
            if (share := self.blocked.share()) > BACKPRESSURE_SHARE
            else "",
        )

    def close(self) -> None:
        self._status.undeclare()
        self.acks.undeclare()
        self.receiver.close()
        self.publisher.undeclare()


def run_actor(config: ActorConfig, settings: ZenohSettings, stop: threading.Event) -> int:
    """Process set-up: env (from the config), Zenoh session (retried until a router answers), loop."""
    from worlds.vector_env import NavigationVectorEnv

    if not config.id:
        config.id = default_actor_id()
    keys.check_name(config.id, "actor id")
    seed = config.seed if config.seed is not None else seed_for(config.id)
    env = NavigationVectorEnv(config.envs, maps=config.maps, seed=seed)
    limits = Limits(n_actions=int(env.single_action_space.n))
    session = connect(settings, stop)
    if session is None:
        return 0
    actor = Actor(config, env, session, settings.run, seed, limits)
    token = declare_alive(session, settings.run, "actor", config.id)
    log.info(
        "actor %s up: %d robots on %s, seed %d, run %s",
        config.id,
        config.envs,
        config.maps,
        seed,
        settings.run,
    )
    try:
        return actor.run(stop)
    finally:
        token.undeclare()
        actor.close()
        session.close()
        env.close()
