"""The stand-alone Zenoh router: a router-mode session that joins hosts, logging who comes and goes.

On one machine the learner hosts the router itself; across machines run
``navlearn router`` (or ``zenohd -c deploy/router.json5``) where every process can reach it.
"""

from __future__ import annotations

import json
import logging
import threading
from dataclasses import replace

from services.common.transport import ZenohSettings, build_config, open_session

log = logging.getLogger("navlearn.router")


def run_router(settings: ZenohSettings, stop: threading.Event) -> int:
    """Serve as a Zenoh router until ``stop`` is set; returns the exit code."""
    import zenoh

    settings = replace(settings, mode="router")
    listen = json.loads(build_config(settings).get_json("listen/endpoints"))
    if isinstance(listen, dict):  # a config file may give endpoints per mode
        listen = listen.get("router", [])
    with open_session(settings) as session:
        log.info("router %s listening on %s", session.zid(), ", ".join(listen))

        def on_transport(event) -> None:
            verb = "joined" if event.kind == zenoh.SampleKind.PUT else "left"
            log.info("%s %s %s", event.transport.whatami, event.transport.zid, verb)

        listener = session.info.declare_transport_events_listener(on_transport)
        stop.wait()
        listener.undeclare()
    log.info("router stopped")
    return 0
