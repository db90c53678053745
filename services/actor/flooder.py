"""A flooding actor in its own process: the load a misbehaving actor puts on the learner, for
bench/chaos.py and tests/test_reliability_fairness.py.

It publishes, as fast as Zenoh takes them and never waiting for an acknowledgement, valid
TransitionBatches of ``--rows`` rows on its own key ``transitions/<id>`` (a new seq each, so
none is a duplicate), and every ``--big-every`` of them one valid batch of about ``--big-mb`` MB
on one of ``--big-keys`` more keys (``<id>-big0``, ...). Prints ``flooding`` once its publishers are
up and one JSON line when stopped (SIGTERM or ``--seconds``): what it published. :func:`launch`
starts it and returns once it floods.

    python -m services.actor.flooder --connect tcp/127.0.0.1:7447 --run r --id flood --rows 1000 --big-mb 60
"""

from __future__ import annotations

import argparse
import json
import select
import signal
import subprocess
import sys
import threading
import time
import zlib

import numpy as np
import zenoh

from protocols import keys
from protocols.codec import encode
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim

OBS_DIM, N_ACTIONS = (
    observation_dim(LEARNING_NAV),
    5,
)  # what the learner takes


READY = "flooding"
"""the line the flooder prints once its publishers are up, before it floods"""


def launch(args: list[str], nice: int = 0, timeout: float = 120.0) -> subprocess.Popen:
    """This script in its own process with ``args`` (under ``nice -n NICE`` when NICE > 0), returned
    once it prints :data:`READY`: a phase timed from then on is flooded, however slowly the process
    started on a busy machine. Its stdout (text) then holds the summary line it prints when stopped.
    RuntimeError if it does not get there within ``timeout`` seconds (it is killed)."""
    niced = ["nice", "-n", str(nice)] if nice > 0 else []
    command = [*niced, sys.executable, "-m", "services.actor.flooder", *args]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        line = proc.stdout.readline() if left > 0 and select.select([proc.stdout], [], [], left)[0] else ""
        if line.strip() == READY:
            return proc
        if not line:  # timed out, or it exited
            proc.kill()
            proc.wait()
            raise RuntimeError(
                f"the flooder did not start flooding within {timeout:.0f} s (exit {proc.returncode})"
            )


def make_batch(actor: str, rows: int, seq: int) -> TransitionBatch:
    """A batch of random rows, distinct per (actor, seq): the learner stores a batch once by its
    content (services.learner.dedup), so two actors' batches must differ as real robots' do."""
    rng = np.random.default_rng([zlib.crc32(actor.encode()), seq])
    return TransitionBatch(
        sender=f"{actor}#{time.time_ns()}",
        seq=seq,
        actor=actor,
        model="nnql",
        policy_version=0,
        env_ids=np.zeros(rows, np.int32),
        obs=rng.random((rows, OBS_DIM), dtype=np.float32),
        action=rng.integers(0, N_ACTIONS, rows),
        reward=np.zeros(rows, np.float32),
        next_obs=rng.random((rows, OBS_DIM), dtype=np.float32),
        terminated=np.zeros(rows, bool),
        truncated=np.zeros(rows, bool),
    )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", required=True)
    p.add_argument("--run", required=True)
    p.add_argument("--id", default="flood")
    p.add_argument("--rows", type=int, default=1000, help="rows of each batch on its own key (0: none)")
    p.add_argument("--big-mb", type=float, default=0.0, help="size of the large batches (0: none)")
    p.add_argument("--big-keys", type=int, default=4, help="keys the large batches rotate over")
    p.add_argument("--big-every", type=int, default=20, help="one large batch per this many small ones")
    p.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: on SIGTERM)")
    args = p.parse_args(argv)
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    session = open_session(ZenohSettings(connect=[args.connect], run=args.run, connect_timeout=60))
    block = zenoh.CongestionControl.BLOCK
    own = session.declare_publisher(keys.transitions(args.run, args.id), congestion_control=block)
    big_names = [f"{args.id}-big{i}" for i in range(args.big_keys)] if args.big_mb > 0 else []
    big = {
        name: (
            session.declare_publisher(keys.transitions(args.run, name), congestion_control=block),
            encode(make_batch(name, int(args.big_mb * 2**20 / (8 * OBS_DIM + 18)), 1)),
        )
        for name in big_names
    }
    deadline = time.monotonic() + args.seconds if args.seconds else float("inf")
    seq, sent, sent_big, sent_bytes = 0, 0, 0, 0
    template = make_batch(args.id, args.rows, 0) if args.rows else None
    print(READY, flush=True)
    while not stop.is_set() and time.monotonic() < deadline:
        if template is not None:
            seq += 1
            template.seq = seq
            payload = encode(template)
            own.put(payload)
            sent, sent_bytes = sent + 1, sent_bytes + len(payload)
        if big and (template is None or seq % args.big_every == 0):
            publisher, payload = big[big_names[sent_big % len(big_names)]]
            publisher.put(payload)
            sent_big, sent_bytes = sent_big + 1, sent_bytes + len(payload)
    session.close()
    print(json.dumps({"batches": sent, "rows": args.rows, "big_batches": sent_big, "bytes": sent_bytes}))


if __name__ == "__main__":
    main()
