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
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from protocols import keys

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("client", "peer", "router")
log = logging.getLogger("navlearn.transport")


class TransportError(RuntimeError):
    """A Zenoh session cannot be configured or opened; the message says why in one line."""


@dataclass
class ZenohSettings:
    """How a process joins the Zenoh network; ``None`` means "not given" (config file or default applies)."""

    mode: str | None = "client"
    """client, peer or router (env NAVLEARN_ZENOH_MODE); None keeps the config file's."""
    connect: list[str] | None = None
    """Endpoints to connect to (env NAVLEARN_CONNECT, comma-separated); clients: DEFAULT_ENDPOINT."""
    listen: list[str] | None = None
    """Endpoints to listen on (env NAVLEARN_LISTEN); routers default to DEFAULT_ENDPOINT."""
    run: str = "default"
    """Run name: every key lives under navlearn/<run>/ (env NAVLEARN_RUN)."""
    config_file: str | None = None
    """Base Zenoh JSON5 config file (env NAVLEARN_ZENOH_CONFIG)."""
    multicast_scouting: bool = False
    """Find routers and peers by UDP multicast (env NAVLEARN_ZENOH_MULTICAST=1); off by default."""
    tls_root_ca: str | None = None
    """CA certificate that signed the other side's certificate (env NAVLEARN_TLS_ROOT_CA)."""
    tls_cert: str | None = None
    """This process's certificate, for tls/ listeners and mutual TLS (env NAVLEARN_TLS_CERT)."""
    tls_key: str | None = None
    """Private key of tls_cert (env NAVLEARN_TLS_KEY)."""
    tls_mtls: bool = False
    """Require and present client certificates (mutual TLS) (env NAVLEARN_TLS_MTLS=1)."""
    credentials_file: str | None = None
    """File holding one ``user:password`` line (env NAVLEARN_ZENOH_CREDENTIALS); else the env vars
    NAVLEARN_ZENOH_USER and NAVLEARN_ZENOH_PASSWORD, if set."""
    auth_dictionary: str | None = None
    """Router side: file of ``user:password`` lines allowed in (env NAVLEARN_ZENOH_AUTH_DICTIONARY)."""
    acl_file: str | None = None
    """Router side: Zenoh JSON5 file whose ``access_control`` section is applied (env NAVLEARN_ZENOH_ACL)."""
    connect_timeout: float = 0.0
    """Seconds to keep retrying while no router answers; 0 waits forever (env NAVLEARN_CONNECT_TIMEOUT)."""


_ENV = {
    "mode": "NAVLEARN_ZENOH_MODE",
    "connect": "NAVLEARN_CONNECT",
    "listen": "NAVLEARN_LISTEN",
    "run": "NAVLEARN_RUN",
    "config_file": "NAVLEARN_ZENOH_CONFIG",
    "multicast_scouting": "NAVLEARN_ZENOH_MULTICAST",
    "tls_root_ca": "NAVLEARN_TLS_ROOT_CA",
    "tls_cert": "NAVLEARN_TLS_CERT",
    "tls_key": "NAVLEARN_TLS_KEY",
    "tls_mtls": "NAVLEARN_TLS_MTLS",
    "credentials_file": "NAVLEARN_ZENOH_CREDENTIALS",
    "auth_dictionary": "NAVLEARN_ZENOH_AUTH_DICTIONARY",
    "acl_file": "NAVLEARN_ZENOH_ACL",
    "connect_timeout": "NAVLEARN_CONNECT_TIMEOUT",
}
_FLAGS = {
    "mode": ("--mode", "client, peer or router"),
    "connect": ("--connect", f"endpoint to connect to, repeatable (default for clients: {DEFAULT_ENDPOINT})"),
    "listen": ("--listen", f"endpoint to listen on, repeatable (default for routers: {DEFAULT_ENDPOINT})"),
    "run": ("--run", "run name; every key is under navlearn/<run>/ (default: default)"),
    "config_file": ("--zenoh-config", "base Zenoh JSON5 config file; the other flags override it"),
    "multicast_scouting": (
        "--multicast-scouting",
        "discover routers and peers by UDP multicast (off by default)",
    ),
    "tls_root_ca": ("--tls-root-ca", "CA certificate (PEM) used to verify the other side"),
    "tls_cert": ("--tls-cert", "this process's certificate (PEM), for tls/ listeners and mutual TLS"),
    "tls_key": ("--tls-key", "private key (PEM) of --tls-cert"),
    "tls_mtls": ("--tls-mtls", "mutual TLS: require and present client certificates"),
    "credentials_file": (
        "--credentials",
        "file with one user:password line for Zenoh authentication (never pass a password as a flag; "
        "NAVLEARN_ZENOH_USER and NAVLEARN_ZENOH_PASSWORD also work)",
    ),
    "auth_dictionary": ("--auth-dictionary", "router: file of user:password lines allowed to connect"),
    "acl_file": ("--acl", "router: Zenoh JSON5 file whose access_control section is enforced"),
    "connect_timeout": ("--connect-timeout", "seconds to wait for a router before giving up (0 = forever)"),
}
_BOOLS = {"multicast_scouting", "tls_mtls"}


def add_zenoh_args(
    parser: argparse.ArgumentParser, *, default_mode: str = "client", modes: tuple[str, ...] = MODES
) -> None:
    """Add the Zenoh flags (one argument group) to ``parser``; ``modes=("router",)`` hides --mode."""
    group = parser.add_argument_group("Zenoh", "every flag also reads the environment variable named in it")
    parser.set_defaults(zenoh_default_mode=default_mode)
    for name, (flag, text) in _FLAGS.items():
        if len(modes) == 1 and name in ("mode", "run", "connect_timeout"):
            continue  # a stand-alone router has no mode choice, no run and does not wait for anyone
        help_text = f"{text} [env {_ENV[name]}]"
        if name in _BOOLS:
            group.add_argument(flag, dest=f"zenoh_{name}", action="store_true", default=None, help=help_text)
        elif name in ("connect", "listen"):
            group.add_argument(
                flag, dest=f"zenoh_{name}", action="append", metavar="ENDPOINT", help=help_text
            )
        elif name == "mode":
            group.add_argument(
                flag, dest="zenoh_mode", choices=modes, help=f"{help_text} (default {default_mode})"
            )
        elif name == "connect_timeout":
            group.add_argument(
                flag, dest="zenoh_connect_timeout", type=float, metavar="SECONDS", help=help_text
            )
        else:
            group.add_argument(
                flag, dest=f"zenoh_{name}", metavar="NAME" if name == "run" else "FILE", help=help_text
            )


def settings_from_args(args: argparse.Namespace | None = None, **overrides: object) -> ZenohSettings:
    """Resolve flags, then environment variables, then defaults (``args=None``: environment only)."""
    values: dict[str, object] = {}
    for name, env in _ENV.items():
        value = getattr(args, f"zenoh_{name}", None) if args is not None else None
        if value is None and os.environ.get(env, "").strip():
            raw = os.environ[env].strip()
            if name in _BOOLS:
                value = raw.lower() in ("1", "true", "yes", "on")
            elif name in ("connect", "listen"):
                value = [e.strip() for e in raw.split(",") if e.strip()]
            elif name == "connect_timeout":
                try:
                    value = float(raw)
                except ValueError:
                    raise TransportError(f"{env}={raw!r} is not a number of seconds") from None
            else:
                value = raw
        if value is not None:
            values[name] = value
    if "mode" not in values:
        values["mode"] = None if "config_file" in values else getattr(args, "zenoh_default_mode", "client")
    values.update(overrides)
    settings = ZenohSettings(**values)
    if settings.mode is not None and settings.mode not in MODES:
        raise TransportError(f"Zenoh mode {settings.mode!r} is not one of {', '.join(MODES)}")
    try:
        keys.check_name(settings.run, "run")
    except ValueError as exc:
        raise TransportError(str(exc)) from None
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
        raise TransportError(f"invalid Zenoh configuration: {exc}") from None
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


def open_session(source: argparse.Namespace | ZenohSettings | None = None, **overrides: object):
    """Open a Zenoh session from parsed flags, settings or the environment (``overrides`` win).

    Clients and peers that find no router keep retrying (logging every ~10 s) until
    ``connect_timeout``; the learner calls ``open_session(args, mode="router")`` to host the router.
    """
    import zenoh

    if isinstance(source, ZenohSettings):
        settings = replace(source, **overrides)
    else:
        settings = settings_from_args(source, **overrides)
    conf = build_config(settings)
    mode = json.loads(conf.get_json("mode")) or "peer"
    endpoints = json.loads(conf.get_json("connect/endpoints"))
    start = last_log = time.monotonic()
    delay = 0.1
    while True:
        try:
            return zenoh.open(build_config(settings))
        except zenoh.ZError as exc:
            waited = time.monotonic() - start
            unreachable = "Unable to connect" in str(exc) and mode != "router"
            if not unreachable or (settings.connect_timeout and waited >= settings.connect_timeout):
                raise TransportError(
                    f"cannot open a Zenoh {mode} session: {str(exc).split(' at /')[0]}"
                ) from None
            if waited == 0 or time.monotonic() - last_log >= 10:
                log.info("waiting for a Zenoh router at %s (%.0f s so far)", ", ".join(endpoints), waited)
                last_log = time.monotonic()
            time.sleep(delay)
            delay = min(2 * delay, 1.0)


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
