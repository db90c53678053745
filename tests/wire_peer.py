"""A small Zenoh client process for the wire tests: ``python tests/wire_peer.py ROLE ENDPOINT [ARGS]``.

alive RUN ID     declare the liveliness token navlearn/RUN/alive/actor/ID, print "alive", wait forever
listen KEY       connect (retrying until a router is up), subscribe to KEY, print "subscribed",
                 print "got <payload>" for the first sample, exit 0 (exit 3 after 60 s without one)
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.common.transport import ZenohSettings, declare_alive, open_session


def main(role: str, endpoint: str, *rest: str) -> int:
    logging.basicConfig(stream=sys.stdout, level=logging.INFO, format="%(name)s %(message)s")
    session = open_session(ZenohSettings(connect=[endpoint], connect_timeout=60))
    if role == "alive":
        run, ident = rest
        with declare_alive(session, run, "actor", ident):
            print("alive", flush=True)
            while True:
                time.sleep(1)
    got = threading.Event()

    def on_sample(sample) -> None:
        print(f"got {sample.payload.to_string()}", flush=True)
        got.set()

    subscriber = session.declare_subscriber(rest[0], on_sample)
    print("subscribed", flush=True)
    ok = got.wait(60)
    subscriber.undeclare()
    session.close()
    return 0 if ok else 3


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
