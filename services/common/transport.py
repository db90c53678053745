"""The one way navlearn processes join Zenoh: flags and NAVLEARN_* environment variables -> a Session.

Defaults: the learner hosts a router on ``tcp/127.0.0.1:7447`` and every other
process connects there as a client; multicast scouting is off. Flags beat
environment variables, which beat a base Zenoh config file (``--zenoh-config``),
which beats these defaults. Passwords never travel on the command line (where
``ps`` shows them): they come from a credentials file or environment variables.

Open sessions only after forking: a forked child of a process that already has
a session never delivers a message (use subprocesses or ``spawn``).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from protocols import keys
from services.common.endpoints import TransportError, check_endpoints, plain_zenoh_error, refusal
from services.common.options import OptionError, add_options, options_from_args
from services.common.waiting import WaitLog

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("client", "peer", "router")
log = logging.getLogger("navlearn.transport")


def _opt(default: object, flag: str, env: str, metavar: str | None = None, **more: object):
    return field(default=default, metadata={"flag": flag, "env": env, "metavar": metavar, **more})


@dataclass
class ZenohSettings:
    """How a process joins the Zenoh network; ``None`` means "not given" (config file or default applies)."""

    mode: str | None = _opt("client", "--mode", "NAVLEARN_ZENOH_MODE", choices=MODES)
    """client, peer or router; a --zenoh-config file's mode is kept unless this is given"""
    connect: list[str] | None = field(
        default=None,
        metadata={
            "flag": "--connect",
            "env": "NAVLEARN_CONNECT",
            "metavar": "ENDPOINT",
            "shown": f"{DEFAULT_ENDPOINT} for clients",
        },
    )
    """endpoint to connect to, repeatable (env: comma-separated), e.g. tcp/HOST:7447"""
    listen: list[str] | None = field(
        default=None,
        metadata={
            "flag": "--listen",
            "env": "NAVLEARN_LISTEN",
            "metavar": "ENDPOINT",
            "shown": f"{DEFAULT_ENDPOINT} for routers",
        },
    )
    """endpoint to listen on, repeatable (env: comma-separated), e.g. tcp/0.0.0.0:7447"""
    run: str = _opt("default", "--run", "NAVLEARN_RUN", "NAME")
    """run name; every key is under navlearn/<run>/"""
    config_file: str | None = _opt(None, "--zenoh-config", "NAVLEARN_ZENOH_CONFIG", "FILE")
    """base Zenoh JSON5 config file; the other flags override it"""
    multicast_scouting: bool = _opt(False, "--multicast-scouting", "NAVLEARN_ZENOH_MULTICAST")
    """discover routers and peers by UDP multicast"""
    tls_root_ca: str | None = _opt(None, "--tls-root-ca", "NAVLEARN_TLS_ROOT_CA", "FILE")
    """CA certificate (PEM) used to verify the other side"""
    tls_cert: str | None = _opt(None, "--tls-cert", "NAVLEARN_TLS_CERT", "FILE")
    """this process's certificate (PEM), for tls/ listeners and mutual TLS"""
    tls_key: str | None = _opt(None, "--tls-key", "NAVLEARN_TLS_KEY", "FILE")
    """private key (PEM) of --tls-cert"""
    tls_mtls: bool = _opt(False, "--tls-mtls", "NAVLEARN_TLS_MTLS")
    """mutual TLS: require and present client certificates"""
    credentials_file: str | None = _opt(None, "--credentials", "NAVLEARN_ZENOH_CREDENTIALS", "FILE")
    """file with one user:password line for Zenoh authentication (never pass a password as a flag;
    NAVLEARN_ZENOH_USER and NAVLEARN_ZENOH_PASSWORD also work)"""
    auth_dictionary: str | None = _opt(None, "--auth-dictionary", "NAVLEARN_ZENOH_AUTH_DICTIONARY", "FILE")
    """router: file of user:password lines allowed to connect"""
    acl_file: str | None = _opt(None, "--acl", "NAVLEARN_ZENOH_ACL", "FILE")
    """router: Zenoh JSON5 file whose access_control section is enforced"""
    connect_timeout: float = _opt(0.0, "--connect-timeout", "NAVLEARN_CONNECT_TIMEOUT", "SECONDS")
    """seconds to wait for a router before giving up with the reason (0: keep waiting, saying so)"""

    def where(self) -> str:
        """The endpoints a client connects to, for messages (``--connect``, else the default)."""
        return ", ".join(self.connect or [DEFAULT_ENDPOINT])


ROUTER_SKIPS = ("mode", "run", "connect_timeout")
"""a stand-alone router has no mode choice, no run and waits for nobody"""


def add_zenoh_args(
    parser: argparse.ArgumentParser,
    *,
    default_mode: str = "client",
    modes: tuple[str, ...] = MODES,
    connect_timeout: float = 0.0,
) -> None:
    """Add the Zenoh flags (one argument group) to ``parser``; ``modes=("router",)`` hides --mode.

    ``connect_timeout`` is the command's default wait for a router: 0 (wait, saying so) for
    supervised services, a few seconds for one-shot commands such as ``navlearn status``.
    """
    parser.set_defaults(zenoh_default_mode=default_mode)
    add_options(
        parser,
        ZenohSettings,
        "NAVLEARN_ZENOH",
        "Zenoh",
        skip=ROUTER_SKIPS if len(modes) == 1 else (),
        defaults={"mode": default_mode, "connect_timeout": connect_timeout},
        dest_prefix="zenoh_",
    )


def settings_from_args(args: argparse.Namespace | None = None, **overrides: object) -> ZenohSettings:
    """Resolve flags, then environment variables, then defaults (``args=None``: environment only).

    Endpoints are checked here (protocol, port, host name), before Zenoh sees them.
    """
    mode_given = getattr(args, "zenoh_mode", None) or os.environ.get("NAVLEARN_ZENOH_MODE", "").strip()
    try:
        settings = options_from_args(ZenohSettings, args, "NAVLEARN_ZENOH", dest_prefix="zenoh_")
    except OptionError as exc:
        raise TransportError(str(exc)) from None
    if not mode_given:
        settings.mode = None if settings.config_file else getattr(args, "zenoh_default_mode", "client")
    settings = replace(settings, **overrides)
    if settings.mode is not None and settings.mode not in MODES:
        raise TransportError(f"Zenoh mode {settings.mode!r} is not one of {', '.join(MODES)}")
    try:
        keys.check_name(settings.run, "run")
    except ValueError as exc:
        raise TransportError(str(exc)) from None
    check_endpoints(settings.connect, settings.listen, resolve=True)
    return settings


def _file(path: str | None, what: str) -> str | None:
    if path is not None and not Path(path).is_file():
        raise TransportError(f"{what} file {path!r} does not exist")
    return path


def read_credentials(settings: ZenohSettings) -> tuple[str, str] | None:
    """(user, password) from the credentials file, else NAVLEARN_ZENOH_USER/PASSWORD, else None."""
    if settings.credentials_file:
        lines = Path(_file(settings.credentials_file, "credentials")).read_text().splitlines()
        line = next((s.strip() for s in lines if s.strip() and not s.startswith("#")), "")
        user, sep, password = line.partition(":")
        if not sep or not user or not password:
            raise TransportError(
                f"credentials file {settings.credentials_file!r} must hold a user:password line"
            )
        return user, password
    user, password = os.environ.get("NAVLEARN_ZENOH_USER"), os.environ.get("NAVLEARN_ZENOH_PASSWORD")
    if bool(user) != bool(password):
        raise TransportError("set both NAVLEARN_ZENOH_USER and NAVLEARN_ZENOH_PASSWORD, or neither")
    return (user, password) if user else None


def build_config(settings: ZenohSettings):
    """The ``zenoh.Config`` for ``settings`` (raises TransportError on a bad file or value)."""
    import zenoh

    def put(key: str, value: object) -> None:
        conf.insert_json5(key, json.dumps(value))

    check_endpoints(settings.connect, settings.listen)
    try:
        conf = (
            zenoh.Config.from_file(_file(settings.config_file, "Zenoh config"))
            if settings.config_file
            else zenoh.Config()
        )
        if settings.mode is not None:
            put("mode", settings.mode)
        mode = json.loads(conf.get_json("mode")) or "peer"
        if settings.connect is not None:
            put("connect/endpoints", settings.connect)
        elif mode != "router" and not json.loads(conf.get_json("connect/endpoints")):
            put("connect/endpoints", [DEFAULT_ENDPOINT])
        if settings.listen is not None:
            put("listen/endpoints", settings.listen)
        elif mode == "router" and isinstance(json.loads(conf.get_json("listen/endpoints")), dict):
            put("listen/endpoints", [DEFAULT_ENDPOINT])
        if settings.multicast_scouting or json.loads(conf.get_json("scouting/multicast/enabled")) is None:
            put("scouting/multicast/enabled", settings.multicast_scouting)
        _apply_security(conf, settings, put)
    except zenoh.ZError as exc:
        log.debug("Zenoh rejected the configuration: %s", exc)
        raise TransportError(f"invalid Zenoh configuration: {plain_zenoh_error(exc)}") from None
    return conf


def _apply_security(conf, settings: ZenohSettings, put: Callable[[str, object], None]) -> None:
    import zenoh

    tls = "transport/link/tls/"
    if settings.tls_root_ca:
        put(tls + "root_ca_certificate", _file(settings.tls_root_ca, "TLS root CA"))
    if bool(settings.tls_cert) != bool(settings.tls_key):
        raise TransportError("--tls-cert and --tls-key go together")
    if settings.tls_cert:
        for side in ("listen", "connect"):
            put(f"{tls}{side}_certificate", _file(settings.tls_cert, "TLS certificate"))
            put(f"{tls}{side}_private_key", _file(settings.tls_key, "TLS key"))
    if settings.tls_mtls:
        if not (settings.tls_cert and settings.tls_root_ca):
            raise TransportError("mutual TLS needs --tls-root-ca, --tls-cert and --tls-key")
        put(tls + "enable_mtls", True)
    credentials = read_credentials(settings)
    if credentials:
        put("transport/auth/usrpwd/user", credentials[0])
        put("transport/auth/usrpwd/password", credentials[1])
    if settings.auth_dictionary:
        put("transport/auth/usrpwd/dictionary_file", _file(settings.auth_dictionary, "auth dictionary"))
    if settings.acl_file:
        acl = json.loads(zenoh.Config.from_file(_file(settings.acl_file, "ACL")).get_json("access_control"))
        if not acl.get("enabled"):
            raise TransportError(
                f"ACL file {settings.acl_file!r} has no access_control section with enabled: true"
            )
        put("access_control", acl)


def config_endpoints(conf, side: str) -> list[str]:
    endpoints = json.loads(conf.get_json(f"{side}/endpoints"))
    if isinstance(endpoints, dict):  # a config file may give endpoints per mode
        endpoints = [e for per_mode in endpoints.values() for e in per_mode]
    return list(endpoints or [])


def open_session(
    source: argparse.Namespace | ZenohSettings | None = None,
    *,
    stop: threading.Event | None = None,
    **overrides: object,
):
    """Open a Zenoh session from parsed flags, settings or the environment (``overrides`` win).

    The one connect loop (SEED RL's outer retry: a process may start before its router). A
    client or peer that finds no router says so at once, naming the endpoints and the run, then
    again with back-off (services.common.waiting), and keeps trying until ``connect_timeout`` (0: for
    ever), when it raises TransportError with the reason, or until ``stop`` is set (returns None).
    A router that cannot listen fails at once. The learner calls ``open_session(args,
    mode="router")`` to host the router.
    """
    import zenoh

    if isinstance(source, ZenohSettings):
        settings = replace(source, **overrides)
        check_endpoints(settings.connect, settings.listen, resolve=True)
    else:
        settings = settings_from_args(source, **overrides)
    conf = build_config(settings)
    mode = json.loads(conf.get_json("mode")) or "peer"
    where = ", ".join(config_endpoints(conf, "connect")) or "any router (multicast scouting)"
    waiting = WaitLog(
        log,
        "waiting for a Zenoh router at %s for run %r (%.0f s so far; is the learner or "
        "`navlearn router` running there?)",
        where,
        settings.run,
    )
    delay = 0.05
    why: str | None = None
    """why the session does not open, where the endpoints tell (services.common.endpoints.refusal)"""
    while True:
        try:
            return zenoh.open(build_config(settings))
        except zenoh.ZError as exc:
            log.debug("zenoh.open: %s", exc)
            if mode == "router":
                listen = ", ".join(config_endpoints(conf, "listen"))
                raise TransportError(
                    f"cannot listen on {listen} ({plain_zenoh_error(exc)}): another router or learner "
                    "may hold that port; stop it or give --listen another endpoint"
                ) from None
        if why is None:  # once: a router that refuses this session is no missing router
            why = refusal(config_endpoints(conf, "connect"), (read_credentials(settings) or (None,))[0]) or ""
            if why.startswith("a router listens"):
                log.error("%s (run %r)", why, settings.run)
        if settings.connect_timeout and waiting.waited >= settings.connect_timeout:
            raise TransportError(no_session(where, settings, why))
        waiting.tick()
        if stop is not None:
            if stop.wait(delay):
                return None
        else:
            time.sleep(delay)
        delay = min(2 * delay, 1.0)


def no_session(where: str, settings: ZenohSettings, why: str) -> str:
    """The one sentence for a client that found no session in ``connect_timeout`` seconds: refused
    credentials, nothing listening, or (where the endpoints cannot tell) both causes and how to
    tell them apart."""
    waited = f"within {settings.connect_timeout:g} s (run {settings.run!r})"
    start = (
        "start the learner (navlearn learner or navlearn up) or `navlearn router` there, or point "
        "--connect at one"
    )
    if why.startswith("a router listens"):
        return f"no Zenoh session at {where} {waited}: {why}"
    if why:
        return f"no Zenoh router answered at {where} {waited}: {why}; {start}"
    return (
        f"no Zenoh router answered at {where} {waited}: {start}; or, if a router runs there, it refused "
        "our credentials (Zenoh reports both the same way over this protocol: a router that logs "
        "an authentication failure, or a tcp/ endpoint, tells them apart)"
    )


def declare_alive(session, run: str, role: str, ident: str):
    """Declare the liveliness token ``navlearn/<run>/alive/<role>/<ident>``; it vanishes with the process."""
    return session.liveliness().declare_token(keys.alive(run, role, ident))


class Presence:
    """The set of live (role, id) pairs under ``navlearn/<run>/alive/``, kept current by liveliness.

    Tokens present when it starts are reported too. A killed process's token
    disappears once its router notices the broken link (immediately for a closed
    socket, within the lease, 10 s by default, for a silent host).
    """

    def __init__(
        self,
        session,
        run: str,
        role: str | None = None,
        on_change: Callable[[str, str, bool], None] | None = None,
    ) -> None:
        self._members: set[tuple[str, str]] = set()
        self._changed = threading.Condition()
        self._on_change = on_change
        key = keys.alive_role(run, role) if role else keys.everything(run, "alive")
        self._subscriber = session.liveliness().declare_subscriber(key, self._on_sample, history=True)

    def _on_sample(self, sample) -> None:
        import zenoh

        try:
            role, ident = keys.parse(sample.key_expr).names
        except ValueError:
            log.warning("ignoring liveliness token %s outside the navlearn key space", sample.key_expr)
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._changed:
            (self._members.add if alive else self._members.discard)((role, ident))
            self._changed.notify_all()
        if self._on_change is not None:
            self._on_change(role, ident, alive)

    def present(self) -> set[tuple[str, str]]:
        with self._changed:
            return set(self._members)

    def wait_for(self, predicate: Callable[[set[tuple[str, str]]], bool], timeout: float) -> bool:
        """Block until ``predicate(present set)`` holds or ``timeout`` s pass; return whether it holds."""
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self._members), timeout)

    def close(self) -> None:
        self._subscriber.undeclare()

    def __enter__(self) -> Presence:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for a loopback endpoint)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])
