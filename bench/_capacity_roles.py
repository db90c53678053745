"""The helper processes of bench/capacity.py, each started as ``python -m bench._capacity_roles ROLE``.

sink: a router that serves the default network's weights and acknowledges every batch at once (the
actor's ideal learner);
publisher: puts one encoded actor batch as fast as BLOCK congestion control lets it through;
subscriber: counts messages and bytes, and prints the count when asked (SIGUSR1).
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time

import numpy as np
import zenoh

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from bench._common import N_ACTIONS, OBS_DIM, random_transitions, settings
from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import TransitionBatch
from services.common.transport import open_session
from services.common.weights import WeightsBroadcaster

RUN = "capacity"


def actor_batch(rows: int, rng: np.random.Generator) -> TransitionBatch:
    """A TransitionBatch as an actor sends it (5% of its transitions end an episode)."""
    return TransitionBatch(
        sender="bench#1", seq=1, actor="bench", model="nnql", policy_version=1,
        env_ids=np.arange(rows, dtype=np.int32) % 1024, **random_transitions(rows, rng, terminal_rate=0.05),
    )  # fmt: skip


def wait_for_stop(done: threading.Event) -> None:
    while not done.wait(0.1):  # a short wait lets the signal handlers run
        pass


def sink_main(endpoint: str) -> None:
    learner = NNQLLearner(NNQLConfig(), OBS_DIM, N_ACTIONS)
    with open_session(settings(endpoint, RUN, "router")) as session:
        broadcaster = WeightsBroadcaster(session, RUN, "nnql", "sink")
        broadcaster.publish(learner.get_weights(), 1, learner.architecture)

        def on_batch(sample) -> None:
            batch = decode(sample.payload.to_bytes())
            ack = Ack(
                sender="sink", seq=batch.seq, actor=batch.sender, accepted_seq=batch.seq, policy_version=1
            )
            session.put(keys.acks(RUN, batch.actor), encode(ack))

        session.declare_subscriber(keys.everything(RUN, "transitions"), on_batch)
        done = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: done.set())
        print("ready", flush=True)
        wait_for_stop(done)


def publisher_main(endpoint: str, rows: int, config_file: str | None) -> None:
    payload = encode(actor_batch(rows, np.random.default_rng(0)))
    with open_session(settings(endpoint, RUN, config_file=config_file)) as session:
        publisher = session.declare_publisher(
            keys.transitions(RUN, "bench"), congestion_control=zenoh.CongestionControl.BLOCK
        )
        done = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: done.set())
        while not publisher.matching_status.matching and not done.is_set():
            time.sleep(0.05)
        print("ready", flush=True)
        while not done.is_set():
            publisher.put(payload)


def subscriber_main(endpoint: str, config_file: str | None) -> None:
    count = [0, 0]

    def on_sample(sample) -> None:
        count[0] += 1
        count[1] += len(sample.payload)

    with open_session(settings(endpoint, RUN, config_file=config_file)) as session:
        session.declare_subscriber(keys.everything(RUN, "transitions"), on_sample)
        done = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: done.set())
        signal.signal(signal.SIGUSR1, lambda *_: print(json.dumps(count), flush=True))
        print("ready", flush=True)
        wait_for_stop(done)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("role", choices=("sink", "publisher", "subscriber"))
    parser.add_argument("--endpoint", required=True)
    parser.add_argument("--zenoh-config", help="publisher, subscriber: a Zenoh config file")
    parser.add_argument("--rows", type=int, default=1024, help="publisher: transitions per batch")
    cli = parser.parse_args()
    if cli.role == "sink":
        sink_main(cli.endpoint)
    elif cli.role == "publisher":
        publisher_main(cli.endpoint, cli.rows, cli.zenoh_config)
    else:
        subscriber_main(cli.endpoint, cli.zenoh_config)
