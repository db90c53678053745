"""Versioned weights on the wire: the learner's broadcaster and the actors' / evaluator's receiver.

The learner publishes a WeightsUpdate on ``weights/<model>`` every M updates and
answers queries on the same key with the newest one, so a process that joins
late (or reconnects) asks once and then follows the broadcasts. The receiver
decodes in the Zenoh callback and keeps only the newest update; the owner's
main loop takes it when it is ready to swap (Acme's variable source).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocols import keys
from protocols.codec import decode, encode
from protocols.errors import ProtocolError
from protocols.limits import DEFAULT_LIMITS, Limits
from protocols.messages import OWN_WORLD, ExplorationSchedule, WeightsUpdate
from worlds.config import OBSERVATIONS, observation_differences, observation_name

log = logging.getLogger("navlearn.weights")


class WeightsBroadcaster:
    """Publishes versioned weights and serves the newest to late joiners (learner side)."""

    def __init__(self, session, run: str, model: str, sender: str) -> None:
        import zenoh

        self.key = keys.weights(run, model)
        self.model = model
        self.sender = sender
        self.seq = 0
        self.version = -1
        self._latest: bytes | None = None
        self._publisher = session.declare_publisher(
            self.key, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._queryable = session.declare_queryable(self.key, self._on_query, complete=True)

    def publish(
        self,
        weights: dict[str, np.ndarray],
        version: int,
        architecture: dict[str, Any],
        exploration: ExplorationSchedule | None = None,
        observation: dict[str, Any] | None = None,
        env: str | None = None,
    ) -> int:
        """Broadcast ``weights`` as ``version`` (actors explore as ``exploration`` says; the network
        observes ``observation``, ``worlds.config.observation_settings``, of env ``env``, a
        ``worlds.own_env.EnvConfig.signature``); returns the encoded size in bytes."""
        self.seq += 1
        message = WeightsUpdate(
            sender=self.sender,
            seq=self.seq,
            model=self.model,
            version=int(version),
            tensors=weights,
            architecture=architecture,
            exploration=exploration,
            observation=observation,
            env=env,
        )
        payload = encode(message)
        self._latest = payload  # one reference swap: the query callback reads it without a lock
        self.version = int(version)
        self._publisher.put(payload)
        return len(payload)

    def _on_query(self, query) -> None:
        latest = self._latest
        if latest is not None:
            query.reply(self.key, latest)

    def close(self) -> None:
        self._queryable.undeclare()
        self._publisher.undeclare()


@dataclass
class ReceivedWeights:
    """A decoded update and when it arrived (``time.time()``, for publish-to-applied latency)."""

    message: WeightsUpdate
    received_at: float


class WeightsReceiver:
    """Follows ``weights/<model>``: keeps the newest update until the owner takes it.

    An update is newer when its version is higher, or when it comes from another
    learner incarnation (a learner restarted from an older checkpoint counts
    versions from there). Rejected payloads are counted by reason.
    """

    def __init__(
        self,
        session,
        run: str,
        model: str,
        limits: Limits = DEFAULT_LIMITS,
        observation: str | None = None,
        env: str = OWN_WORLD,
    ) -> None:
        """``observation``: the owner's ``--observation`` (worlds.config.OBSERVATIONS); ``env``: the
        signature of the env it runs (worlds.own_env.EnvConfig.signature). Updates whose network
        observes something else, or was trained on another env, are refused (counted as ``observation``
        or ``env``, said once per sender)."""
        self.key = keys.weights(run, model)
        self.limits = limits
        self.observation = observation
        self.env = env
        self._warned: set[str] = set()
        self.rejected: Counter[str] = Counter()
        self.received = 0
        self._lock = threading.Lock()
        self._pending: ReceivedWeights | None = None
        self._current: tuple[str, int] | None = None  # (sender, version) of the newest seen
        self._session = session
        self._subscriber = session.declare_subscriber(self.key, self._on_sample)

    def request_latest(self, timeout: float = 5.0) -> None:
        """Ask the learner's queryable for its newest weights (the answer arrives asynchronously)."""
        self._session.get(self.key, self._on_reply, timeout=timeout)

    def _on_reply(self, reply) -> None:
        if reply.ok is not None:
            self._on_sample(reply.ok)

    def _on_sample(self, sample) -> None:
        arrived = time.time()
        try:
            message = decode(sample.payload.to_bytes(), self.limits)
            if not isinstance(message, WeightsUpdate):
                raise ProtocolError("kind", f"expected weights on {self.key}, got {message.KIND}")
        except ProtocolError as exc:
            with self._lock:
                self.rejected[exc.reason] += 1
            log.warning("rejected weights on %s: %s", self.key, exc)
            return
        wrong_env = self.wrong_env(message)
        if (wrong := wrong_env or self.wrong_observation(message)) is not None:
            with self._lock:
                self.rejected["env" if wrong_env else "observation"] += 1
                first = message.sender not in self._warned
                self._warned.add(message.sender)
            if first:
                log.warning("ignoring weights on %s from %s: %s", self.key, message.sender, wrong)
            return
        with self._lock:
            self.received += 1
            stamp = (message.sender, message.version)
            current = self._current
            if current is not None and current[0] == message.sender and message.version <= current[1]:
                return
            self._current = stamp
            self._pending = ReceivedWeights(message, arrived)

    def wrong_env(self, message: WeightsUpdate) -> str | None:
        """Why ``message``'s network cannot act in this process's env (None: it can): both envs named."""
        theirs = message.env or OWN_WORLD
        if theirs == self.env:
            return None
        fix = "no --env (navlearn's world)" if theirs == OWN_WORLD else f"--env {theirs}"
        return (
            f"the learner trains on env {theirs!r}; this process runs env {self.env!r}: start it with {fix}"
        )

    def wrong_observation(self, message: WeightsUpdate) -> str | None:
        """Why ``message``'s network cannot act on this process's observation (None: it can, or
        either side does not say): the settings that differ and the --observation to start with."""
        if self.observation is None or message.observation is None:
            return None
        wrong = observation_differences(message.observation, OBSERVATIONS[self.observation], "this process")
        if not wrong:
            return None
        named = observation_name(message.observation)
        fix = f"--observation {named}" if named else "the learner's --observation"
        return (
            f"the learner's network observes {', '.join(wrong)}; this process has --observation "
            f"{self.observation}: start it with {fix}"
        )

    def take(self) -> ReceivedWeights | None:
        """The newest update not taken yet, or None."""
        with self._lock:
            pending, self._pending = self._pending, None
            return pending

    def close(self) -> None:
        self._subscriber.undeclare()


def split_architecture(architecture: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(network architecture, exploration map) out of an architecture map that may still hold the
    schedule under ``"exploration"``. A decoded WeightsUpdate already has it apart, typed
    (``WeightsUpdate.exploration``); this is for maps from elsewhere (bench/learner.py)."""
    network = dict(architecture)
    exploration = network.pop("exploration", {}) or {}
    return network, dict(exploration)
