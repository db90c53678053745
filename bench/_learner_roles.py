"""The helper processes of bench/learner.py, each started as ``python -m bench._learner_roles ROLE``.

feeder: sends pre-built TransitionBatches to a learner as fast as it acknowledges them;
sink: a router that acknowledges every transition batch at once (an actor's ideal learner), addressed
to the batch's incarnation (its envelope sender) as the learner addresses them;
receiver: applies weights as they arrive (as an actor does) and prints version and time applied.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time

import numpy as np

from agents.nnql.policy import NNQLPolicy
from bench._common import LEARNER_OBS_DIM, random_transitions, settings
from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import TransitionBatch
from services.common.outbox import Outbox
from services.common.transport import open_session
from services.common.weights import WeightsReceiver, split_architecture

RUN = "bench"


def feeder_main(endpoint: str, batch: int) -> None:
    rng = np.random.default_rng(1)
    session = open_session(settings(endpoint, RUN))
    publisher = session.declare_publisher(keys.transitions(RUN, "feeder"))
    outbox = Outbox(publisher.put, lambda: publisher.matching_status.matching, capacity=8, window=4)
    session.declare_subscriber(
        keys.acks(RUN, "feeder"), lambda s: outbox.on_ack(decode(s.payload.to_bytes()).accepted_seq)
    )
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    payloads = [
        TransitionBatch(
            sender="feeder",
            seq=0,
            actor="feeder",
            model="nnql",
            policy_version=0,
            env_ids=np.zeros(batch, np.int32),
            **random_transitions(batch, rng, obs_dim=LEARNER_OBS_DIM),
        )
        for _ in range(16)
    ]
    seq = 0
    while not done.is_set():
        seq += 1
        message = payloads[seq % len(payloads)]
        message.seq = seq
        outbox.put(seq, encode(message))
        outbox.flush(done)
    session.close()


def sink_main(endpoint: str) -> None:
    session = open_session(settings(endpoint, RUN, "router"))
    count = [0]

    def on_batch(sample) -> None:
        batch = decode(sample.payload.to_bytes())
        count[0] += len(batch)
        ack = Ack(sender="sink", seq=batch.seq, actor=batch.sender, accepted_seq=batch.seq, policy_version=0)
        session.put(keys.acks(RUN, batch.actor), encode(ack))

    session.declare_subscriber(keys.everything(RUN, "transitions"), on_batch)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    print("ready", flush=True)
    done.wait()
    print(json.dumps({"transitions": count[0]}), flush=True)
    session.close()


def receiver_main(endpoint: str) -> None:
    session = open_session(settings(endpoint, RUN))
    receiver = WeightsReceiver(session, RUN, "nnql")
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    policy = None
    print("ready", flush=True)
    lines = []
    while not done.is_set():
        received = receiver.take()
        if received is None:
            time.sleep(0.0005)
            continue
        message = received.message
        network, _ = split_architecture(message.architecture)
        if policy is None:
            policy = NNQLPolicy(message.tensors, network, version=message.version)
        else:
            policy.set_weights(message.tensors, message.version)
        lines.append(f"{message.version} {time.time():.6f}")
    print("\n".join(lines), flush=True)
    session.close()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("role", choices=("feeder", "sink", "receiver"))
    parser.add_argument("--endpoint", required=True)
    parser.add_argument("--batch", type=int, default=256, help="feeder: transitions per batch")
    cli = parser.parse_args()
    if cli.role == "feeder":
        feeder_main(cli.endpoint, cli.batch)
    elif cli.role == "sink":
        sink_main(cli.endpoint)
    else:
        receiver_main(cli.endpoint)
