"""The demonstrator service: demonstrations published as DemoBatches on ``demos/<source>``.

Three sources, one publishing path:

* ``astar``: the modified-A* expert (agents.planning) drives the robot on generated
  maps at ``rate`` episodes per second, optionally replacing actions by random wall-free
  ones with probability ``noise`` (injected sub-optimality; the action taken is recorded);
* ``human``: a person drives the robot from the terminal (``services.demonstrator.teleop``), and each
  finished episode is published;
  (the astar and file sources are in ``services.demonstrator.episodes``)
* ``file``: a demonstration dataset (Minari, ``navlearn demos generate``) is imported
  and published once.

Demonstrations are only worth sending to a learner that hears them, so before each
batch the demonstrator waits (as long as it takes, or until stopped) for a learner's
liveliness token; while no learner is present nothing is lost, only delayed. Batches go
out with congestion control BLOCK through an Outbox, as the actors' transitions do
(at-least-once): each is kept until the learner acknowledges it on ``acks/<source>``
(after its write-ahead log holds it) and sent again if the learner restarted; the
learner drops duplicates by (sender, seq). Before exiting, the demonstrator waits for
the acknowledgement of everything it published. It declares ``alive/demonstrator/<id>``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Iterable

import numpy as np
from gymnasium import spaces

from agents.demos import Demo, write_demos
from protocols import keys
from protocols.codec import encode
from protocols.messages import DemoBatch, EpisodeMeta
from services.common.outbox import Outbox, decode_ack
from services.common.transport import Presence, ZenohSettings, declare_alive, open_session
from services.common.waiting import WaitLog
from services.demonstrator.config import DemonstratorConfig
from services.demonstrator.episodes import check_file, expert_episodes, file_episodes, nav_config
from services.demonstrator.teleop import drive
from worlds.config import observation_settings
from worlds.env import observation_space

log = logging.getLogger("navlearn.demonstrator")


def demo_batch(demos: list[Demo], source: str, sender: str, seq: int) -> DemoBatch:
    """Whole episodes as one DemoBatch (observations stacked, T_i + 1 rows per episode)."""
    quality = "optimal" if all(d.metadata.get("noise", 0.0) == 0.0 for d in demos) else "suboptimal"
    if source == "human":
        quality = "human"
    return DemoBatch(
        sender=sender,
        seq=seq,
        source=source,
        quality=quality,
        episode_lengths=np.array([len(d) for d in demos], dtype=np.int32),
        obs=np.concatenate([d.observations for d in demos]),
        actions=np.concatenate([d.actions for d in demos]),
        rewards=np.concatenate([d.rewards for d in demos]).astype(np.float32),
        terminations=np.concatenate([d.terminations for d in demos]),
        truncations=np.concatenate([d.truncations for d in demos]),
        episodes=[
            EpisodeMeta(
                map_id=str(d.metadata.get("map_id", "")),
                start=tuple(int(v) for v in d.metadata["start"]),
                goal=tuple(int(v) for v in d.metadata["goal"]),
                seed=d.metadata.get("seed"),
            )
            for d in demos
        ],
    )


class DemoPublisher:
    """Publishes batches of episodes on ``demos/<source>``, waiting for a learner if told to."""

    def __init__(
        self, session, run: str, config: DemonstratorConfig, stop: threading.Event, where: str = ""
    ) -> None:
        """``where``: the router endpoints, named while waiting for a learner."""
        import zenoh

        self.config = config
        self.waiting = WaitLog(
            log,
            "waiting for a learner on run %r via %s to publish demonstrations to (%.0f s so far)",
            run,
            where,
        )
        self.stop = stop
        self.sender = f"{config.id}#{int(time.time())}"
        self.publisher = session.declare_publisher(
            keys.demos(run, config.source),
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        self.outbox = Outbox(
            self.publisher.put,
            lambda: self.publisher.matching_status.matching,
            capacity=config.outbox_size,
            window=min(4, config.outbox_size),
            ack_timeout=config.ack_timeout,
        )
        self.acks = session.declare_subscriber(keys.acks(run, config.source), self._on_ack)
        self.learners = Presence(session, run, role="learner") if config.wait_learner else None
        self.seq = 0
        self.episodes = 0
        self.steps = 0
        self.published: list[Demo] = []
        """every episode published, kept for --record"""

    def _on_ack(self, sample) -> None:
        ack = decode_ack(
            sample.payload.to_bytes(), self.sender
        )  # acks/<source> is shared by its demonstrators
        if ack is not None:
            self.outbox.on_ack(ack.accepted_seq)

    def wait_for_learner(self) -> bool:
        """Block until a learner is alive (or stop); True when one is."""
        if self.learners is None:
            return True
        self.waiting.reset()
        while not self.stop.is_set():
            if self.learners.wait_for(bool, timeout=0.5):
                return True
            self.waiting.tick()
        return False

    def publish(self, demos: list[Demo]) -> bool:
        if not demos or not self.wait_for_learner():
            return False
        self.seq += 1
        batch = demo_batch(demos, self.config.source, self.sender, self.seq)
        self.outbox.put(batch.seq, encode(batch))
        self.outbox.flush(self.stop)
        self.episodes += len(demos)
        self.steps += int(batch.episode_lengths.sum())
        if self.config.record:
            self.published.extend(demos)
        log.debug("published %d episodes (%d steps) as batch %d", len(demos), len(batch.actions), self.seq)
        return True

    def publish_all(self, episodes: Iterable[Demo]) -> int:
        """Publish ``episodes`` in batches until they run out, ``episodes`` is reached, or stop."""
        cfg = self.config
        pending: list[Demo] = []
        last_log = time.monotonic()
        for demo in episodes:
            pending.append(demo)
            limit_reached = cfg.episodes and self.episodes + len(pending) >= cfg.episodes
            if len(pending) >= cfg.batch_episodes or limit_reached:
                self.publish(pending)
                pending = []
            if time.monotonic() - last_log >= cfg.log_every:
                log.info("%s: %d episodes, %d steps published", cfg.source, self.episodes, self.steps)
                last_log = time.monotonic()
            if limit_reached or self.stop.is_set():
                break
        if pending and not self.stop.is_set():
            self.publish(pending)
        return self.episodes

    def drain(self, timeout: float | None = None) -> bool:
        """Wait (until stop or ``timeout``) for the learner to acknowledge every published batch."""
        if len(self.outbox):
            log.info("waiting for the learner to acknowledge %d demo batches", len(self.outbox))
        return self.outbox.drain(self.stop, timeout)

    def close(self) -> None:
        self.acks.undeclare()
        if self.learners is not None:
            self.learners.close()
        self.publisher.undeclare()


def run_demonstrator(config: DemonstratorConfig, settings: ZenohSettings, stop: threading.Event) -> int:
    """Process set-up: Zenoh session, liveliness, the source, the publisher."""
    if config.source == "file":
        check_file(config)  # a bad dataset fails here, before joining the network
    if not config.id:
        config.id = f"{config.source}-{os.getpid()}"
    keys.check_name(config.id, "demonstrator id")
    session = open_session(settings, stop=stop)
    if session is None:
        return 0
    with (
        session,
        contextlib.closing(DemoPublisher(session, settings.run, config, stop, settings.where())) as publisher,
        declare_alive(session, settings.run, "demonstrator", config.id),
    ):
        log.info(
            "demonstrator %s (%s) up, run %s via %s", config.id, config.source, settings.run, settings.where()
        )
        if config.source == "astar":
            publisher.publish_all(expert_episodes(config, stop))
        elif config.source == "file":
            publisher.publish_all(file_episodes(config))
        else:
            drive(config, publisher, stop)
        publisher.drain()
        log.info(
            "%s: %d episodes, %d steps published; stopping",
            config.source,
            publisher.episodes,
            publisher.steps,
        )
        if config.record and publisher.published:
            record(config, publisher.published)
        return 0


def record(config: DemonstratorConfig, demos: list[Demo]) -> None:
    """The published episodes as the Minari dataset ``config.record`` (``navlearn nirl train --demos``)."""
    nav = nav_config(config)
    path = write_demos(config.record, demos, observation_space(nav), spaces.Discrete(nav.robot.n_actions),
                       description=f"navlearn demonstrator --source {config.source}",
                       observation=observation_settings(nav))  # fmt: skip
    log.info("%d episodes recorded in %s", len(demos), path)
