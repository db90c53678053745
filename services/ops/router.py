"""The stand-alone Zenoh router: a router-mode session that joins hosts, logging who comes and goes.

On one machine the learner hosts the router itself; across machines run
``navlearn router`` (or ``zenohd -c deploy/router.json5``) where every process can reach it.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import threading
from dataclasses import replace

from services.common.transport import ZenohSettings, build_config, config_endpoints, open_session

log = logging.getLogger("navlearn.router")


def _loopback(endpoint: str) -> bool:
    host = endpoint.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a host name or an interface: reachable from elsewhere, as far as we know


def exposure_warning(settings: ZenohSettings) -> str | None:
    """A warning if a router with ``settings`` listens beyond loopback without TLS *and*
    user/password authentication (anyone who reaches it may then publish and read everything,
    in the clear); None otherwise."""
    config = build_config(replace(settings, mode="router"))
    exposed = [e for e in config_endpoints(config, "listen") if not _loopback(e)]
    if not exposed:
        return None
    plain = [e for e in exposed if not e.startswith(("tls/", "quic/"))]
    auth = json.loads(config.get_json("transport/auth/usrpwd/dictionary_file"))
    if not plain and auth:
        return None
    missing = " and ".join(
        what for what, absent in (("TLS", plain), ("authentication (--auth-dictionary)", not auth)) if absent
    )
    return (
        f"listening on {', '.join(exposed)} beyond loopback WITHOUT {missing}: anyone who reaches this "
        "port can publish transitions and weights and read everything (user names and transitions in "
        "the clear without TLS). Listen on tcp/127.0.0.1 or configure TLS, --auth-dictionary and --acl "
        "(README: Reliability and security)"
    )


def run_router(settings: ZenohSettings, stop: threading.Event) -> int:
    """Serve as a Zenoh router until ``stop`` is set; returns the exit code."""
    import zenoh

    settings = replace(settings, mode="router")
    listen = config_endpoints(build_config(settings), "listen")
    warning = exposure_warning(settings)
    if warning:
        log.warning("%s", warning)

    def on_transport(event) -> None:
        verb = "joined" if event.kind == zenoh.SampleKind.PUT else "left"
        log.info("%s %s %s", event.transport.whatami, event.transport.zid, verb)

    with open_session(settings) as session, session.info.declare_transport_events_listener(on_transport):
        # "listening" is said once the listener is declared: whoever connects after it is logged
        log.info("router %s listening on %s", session.zid(), ", ".join(listen))
        # Wake up now and then: a SIGTERM delivered to one of Zenoh's threads runs the handler
        # only when the main thread next runs Python, and an untimed wait never returned then
        # (1 in 5 routers stopped together with the router they were linked to hung until
        # SIGKILL).
        while not stop.wait(0.5):
            pass
    log.info("router stopped")
    return 0
