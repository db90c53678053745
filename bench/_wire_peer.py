"""The subscriber and echo side of bench/wire.py, a process of its own (started by it).

python -m bench._wire_peer ENDPOINT     # prints "ready", then one JSON line per finished round
"""

from __future__ import annotations

import json
import sys
import threading
import time

import zenoh

from bench.wire import ECHO, ECHO_BACK, END, LIMITS, MSG, RAW
from protocols.codec import decode, encode
from services.common.transport import ZenohSettings, open_session


def peer_main(endpoint: str) -> None:
    """Subscriber and echo side; one JSON line per finished round on stdout."""
    session = open_session(ZenohSettings(connect=[endpoint]))
    lock = threading.Lock()
    state = {"count": 0, "transitions": 0, "bytes": 0, "first": 0.0, "last": 0.0, "rejected": 0}
    state["handler_cpu_s"] = 0.0  # CPU time of the subscriber callbacks (payload copy + decode)

    def count(nbytes: int, transitions: int) -> None:
        now = time.perf_counter()
        with lock:
            if state["count"] == 0:
                state["first"] = now
            state["count"] += 1
            state["transitions"] += transitions
            state["bytes"] += nbytes
            state["last"] = now

    def subscriber(handle):
        # Decoding runs in Zenoh's callback thread, as a service's subscriber would (a FIFO channel
        # drained by a Python thread was slower here: the two threads contend for the GIL).
        def on_sample(sample) -> None:
            start = time.thread_time()
            data = sample.payload.to_bytes()
            try:
                transitions = handle(data)
            except ValueError:
                state["rejected"] += 1
            else:
                count(len(data), transitions)
            state["handler_cpu_s"] += time.thread_time() - start

        return on_sample

    echo_pub = session.declare_publisher(ECHO_BACK, congestion_control=zenoh.CongestionControl.BLOCK)

    def on_echo(sample) -> None:
        data = sample.payload.to_bytes()
        if data[:1] == b"R":  # raw echo: bytes straight back
            echo_pub.put(data)
        else:
            echo_pub.put(encode(decode(data, LIMITS)))

    def on_end(sample) -> None:
        threading.Thread(target=report, args=(int(sample.payload.to_string()),)).start()

    def report(expected: int) -> None:
        deadline = time.monotonic() + 60
        while state["count"] < expected and time.monotonic() < deadline:
            time.sleep(0.01)
        with lock:
            print(json.dumps(state), flush=True)
            state.update(count=0, transitions=0, bytes=0, first=0.0, last=0.0, rejected=0, handler_cpu_s=0.0)

    subs = [
        session.declare_subscriber(END, on_end),
        session.declare_subscriber(ECHO, on_echo),
        session.declare_subscriber(RAW, subscriber(lambda data: 0)),
        session.declare_subscriber(MSG, subscriber(lambda data: len(decode(data, LIMITS)))),
    ]
    print("ready", flush=True)
    sys.stdin.read()  # runs until the parent closes our stdin
    for sub in subs:
        sub.undeclare()
    session.close()


if __name__ == "__main__":
    peer_main(sys.argv[1])
