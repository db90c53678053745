"""The actor service: N robots stepped with the newest policy, transition batches out over Zenoh.

The actor is handed its weight source (a WeightsReceiver) and its outbox (Acme's
actor/variable-source split); ``run_actor`` does the set-up and SEED RL's outer
loop: it builds the env from a factory and retries the Zenoh connection until a
router answers. Once connected, Zenoh itself re-establishes a lost router link
(subscriptions, queryables and the liveliness token come back with it); batches
made meanwhile wait in the outbox and the newest weights are asked for again.
Until the first weights arrive the robots act uniformly at random (version 0).
The actor answers ``status/actor:<id>`` (services.actor.status): outbox, acknowledgements,
back-pressure, robot-steps and weights version. When batches wait and nothing is
acknowledged for ``silence_warning`` seconds it says so and why (services.actor.silence).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import socket
import threading
import time
import zlib
from collections import deque

import numpy as np
from threadpoolctl import threadpool_limits

from agents.nnql.config import NNQLConfig
from agents.nnql.policy import NNQLPolicy
from agents.nnql.rollout import VectorRollout
from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import ExplorationSchedule, TransitionBatch
from services.actor.config import ActorConfig
from services.actor.silence import SilenceWatch
from services.actor.status import BACKPRESSURE_SHARE, ActorView, BlockedShare, actor_status
from services.common.outbox import Outbox, decode_ack
from services.common.transport import ZenohSettings, declare_alive, open_session
from services.common.warmup import COMPILE_NOTE
from services.common.weights import WeightsReceiver
from worlds.config import OBSERVATIONS, with_moving_discs
from worlds.own_env import EnvConfig, make_vector_env
from worlds.vector_env import NavigationVectorEnv

log = logging.getLogger("navlearn.actor")


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

    def __init__(
        self,
        config: ActorConfig,
        env,
        session,
        run: str,
        seed: int,
        limits: Limits,
        where: str = "",
        env_config: EnvConfig | None = None,
    ) -> None:
        """``where``: the router endpoints, named in the actor's warnings; ``env_config``: which env
        ``env`` is (announced in every batch; default navlearn's world)."""
        import zenoh

        self.config = config
        self.env_config = env_config or EnvConfig()
        self.env_signature = self.env_config.signature()
        self.run_name = run
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.n_actions = int(env.single_action_space.n)
        self.policy = None
        self.version = 0
        self.exploration: ExplorationSchedule | None = None
        self.rollout = VectorRollout(env, self.act)
        self._declared = contextlib.ExitStack()
        """everything declared on the session, undeclared by close() in reverse order"""
        self.receiver = self._declared.enter_context(
            contextlib.closing(
                WeightsReceiver(
                    session,
                    run,
                    config.model,
                    limits,
                    config.observation if self.env_config.own_world else None,
                    self.env_signature,
                )
            )
        )
        self.publisher = self._declared.enter_context(
            session.declare_publisher(
                keys.transitions(run, config.id), congestion_control=zenoh.CongestionControl.BLOCK
            )
        )
        self.outbox = Outbox(
            self.publisher.put,
            lambda: self.publisher.matching_status.matching,
            capacity=config.outbox_size,
            window=config.ack_window,
            ack_timeout=config.ack_timeout,
        )
        self.silence = SilenceWatch(session, run, where, lambda: len(self.outbox), config.silence_warning)
        self._declared.callback(self.silence.close)
        self.acks = self._declared.enter_context(
            session.declare_subscriber(keys.acks(run, config.id), self._on_ack)
        )
        self.blocked = BlockedShare()
        """share of time waiting for the learner (back-pressure), for the status and the log"""
        self.status_seq = 0
        self.status_key = keys.actor_status(run, config.id)
        self._status = self._declared.enter_context(
            session.declare_queryable(self.status_key, self._on_status, complete=True)
        )
        self._steps_window: deque[tuple[float, int]] = deque(maxlen=64)
        self.learner_version = 0
        self.seq = 0
        self.sender = f"{config.id}#{time.time_ns() // 1_000_000}"
        """this incarnation: the learner de-duplicates by (sender, seq), and seq restarts with the process"""
        self.weights_applied = 0
        self.episodes: deque[int] = deque(maxlen=100)
        """1 per recent episode that succeeded (the world's goal outcome, or the env's is_success)"""
        self.returns: deque[float] = deque(maxlen=100)
        """the returns of the recent episodes"""
        self.episodes_done = 0
        self.reachable = True

    def _on_status(self, query) -> None:
        self.status_seq += 1
        view = ActorView(
            sender=self.sender,
            model=self.config.model,
            version=self.version,
            learner_version=self.learner_version,
            reachable=self.reachable,
            robot_steps=self.rollout.steps,
            episodes=self.episodes_done,
            weights_applied=self.weights_applied,
            recent_successes=tuple(self.episodes),
            steps_per_s=self.steps_rate(),
        )
        query.reply(self.status_key, encode(actor_status(view, self.outbox, self.blocked, self.status_seq)))

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
            self.silence.acknowledged()
            self.learner_version = max(self.learner_version, ack.policy_version)
            self.outbox.on_ack(ack.accepted_seq)

    def apply_weights(self) -> bool:
        """Swap in the newest weights if any arrived; True if the policy changed."""
        received = self.receiver.take()
        if received is None:
            return False
        message = received.message
        network = message.architecture
        try:
            if self.policy is None or self.policy.architecture != network:
                self.policy = NNQLPolicy(message.tensors, network, version=message.version, seed=self.seed)
            else:
                self.policy.set_weights(message.tensors, message.version)
        except (ValueError, TypeError, KeyError) as exc:
            log.warning("ignoring weights version %d: %s", message.version, exc)
            return False
        self.exploration = message.exploration or ExplorationSchedule.of(NNQLConfig())  # none sent: defaults
        self.policy.explore_as(self.exploration, message.version)
        self.version = message.version
        self.weights_applied += 1
        if self.rollout.obs is not None:  # act on the next step with it already
            self.rollout.actions = self.act(self.rollout.obs)
        return True

    def step_batch(self) -> TransitionBatch:
        """``batch_steps`` vector steps as one TransitionBatch (all from one policy version)."""
        pieces = []
        for _ in range(self.config.batch_steps):
            batch, ended = self.rollout.step()
            pieces.append(batch)
            for episode in ended:
                self.episodes.append(int(episode.solved))
                self.returns.append(episode.episode_return)
            self.episodes_done += len(ended)
        flat = concat_batches(pieces, self.rollout.num_envs)
        self.seq += 1
        return TransitionBatch(
            sender=self.sender,
            seq=self.seq,
            actor=self.config.id,
            model=self.config.model,
            env=self.env_signature,
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
        self.silence.start()
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
        mean_return = np.mean(self.returns) if self.returns else float("nan")
        log.info(
            "%.0f robot-steps/s (%d in all) | version %d (learner %d, lag %d) | episodes %d, success %.0f%%, "
            "return %.1f (last %d) | "
            "sent %d, outbox %d (unacknowledged %d, resent %d)%s%s",
            rate,
            self.rollout.steps,
            self.version,
            self.learner_version,
            max(self.learner_version - self.version, 0),
            self.episodes_done,
            100 * success,
            mean_return,
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
        self._declared.close()

    def __enter__(self) -> Actor:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def build_env(config: ActorConfig, env_config: EnvConfig, seed: int):
    """The actor's vector env: navlearn's compiled world on ``config.maps``, or ``config.envs`` copies
    of a Gymnasium ``--env`` (worlds.own_env), and the wire limits that follow from its spaces."""
    if env_config.own_world:
        log.info("actor %s: building %d robots on %s (%s)", config.id, config.envs, config.maps, COMPILE_NOTE)
        nav = with_moving_discs(OBSERVATIONS[config.observation], config.moving_discs)
        env = NavigationVectorEnv(config.envs, config=nav, maps=config.maps, seed=seed)
    else:
        log.info("actor %s: building %d copies of %s (%s)", config.id, config.envs, env_config.signature(),
                 env_config.env_vector)  # fmt: skip
        env = make_vector_env(env_config, config.envs)
    obs_dim = int(np.prod(env.single_observation_space.shape))
    limits = Limits(n_actions=int(env.single_action_space.n), max_obs_dim=max(Limits.max_obs_dim, obs_dim))
    return env, limits


def run_actor(
    config: ActorConfig, settings: ZenohSettings, stop: threading.Event, env_config: EnvConfig | None = None
) -> int:
    """Process set-up: env (from the config; ``env_config``: a Gymnasium env instead of navlearn's
    world), Zenoh session (retried until a router answers), loop."""
    env_config = env_config or EnvConfig()
    if not config.id:
        config.id = default_actor_id()
    keys.check_name(config.id, "actor id")
    seed = config.seed if config.seed is not None else seed_for(config.id)
    env, limits = build_env(config, env_config, seed)
    with contextlib.closing(env):
        session = open_session(settings, stop=stop)
        if session is None:
            return 0
        where = settings.where()
        with (
            session,
            Actor(config, env, session, settings.run, seed, limits, where, env_config) as actor,
            declare_alive(session, settings.run, "actor", config.id),
        ):
            log.info(
                "actor %s up: %d robots on %s, seed %d, run %s via %s",
                config.id,
                config.envs,
                config.maps if env_config.own_world else env_config.signature(),
                seed,
                settings.run,
                where,
            )
            # The policy multiplies a few dozen rows per step: OpenBLAS split that over every core
            # and its threads spun between calls, many times the CPU per robot-step on a busy
            # machine (bench/capacity.py measures it). One BLAS thread, as
            # agents.evaluation does.
            with threadpool_limits(limits=1, user_api="blas"):
                return actor.run(stop)
