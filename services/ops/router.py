"""The stand-alone Zenoh router: a router-mode session that joins hosts, logging who comes and goes.

On one machine the learner hosts the router itself; across machines run
``navlearn router`` (or ``zenohd -c deploy/router.json5``) where every process can reach it.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import replace

from services.common.transport import ZenohSettings, build_config, config_endpoints, open_session

log = logging.getLogger("navlearn.router")


def run_router(settings: ZenohSettings, stop: threading.Event) -> int:
    """Serve as a Zenoh router until ``stop`` is set; returns the exit code."""
    import zenoh

    settings = replace(settings, mode="router")
    listen = config_endpoints(build_config(settings), "listen")
    with open_session(settings) as session:
        log.info("router %s listening on %s", session.zid(), ", ".join(listen))

        def on_transport(event) -> None:
            verb = "joined" if event.kind == zenoh.SampleKind.PUT else "left"
            log.info("%s %s %s", event.transport.whatami, event.transport.zid, verb)

        with session.info.declare_transport_events_listener(on_transport):
            # Wake up now and then: a SIGTERM delivered to one of Zenoh's threads runs the handler
            # only when the main thread next runs Python, and an untimed wait never returned then
            # (1 in 5 routers stopped together with the router they were linked to hung until
            # SIGKILL).
            while not stop.wait(0.5):
                pass
    log.info("router stopped")
    return 0
