"""Zenoh endpoints checked before Zenoh sees them, and Zenoh's errors without their Rust wrapping.

Zenoh takes ``<protocol>/<address>[?<metadata>][#<config>]``; given ``127.0.0.1:7447`` it fails
with a Rust ``Json5Err`` quoting cargo paths, and given ``tcp/127.0.0.1`` (no port) or an
unresolvable host it waits for ever. :func:`check_endpoint` says what is wrong and how to
write it instead, in one sentence.
"""

from __future__ import annotations

import re
import socket

PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream")
"""Zenoh link protocols an endpoint may name (``<protocol>/<address>``)."""


class TransportError(RuntimeError):
    """A Zenoh session cannot be configured or opened; the message says why in one line."""


_HOST_PORT = re.compile(r"^(?:\[(?P<v6>[0-9A-Fa-f:.%]+)\]|(?P<host>[^:/\[\]]+)):(?P<port>[^:]*)$")


def check_endpoint(endpoint: str, side: str = "connect", resolve: bool = False) -> None:
    """Raise TransportError, in one plain sentence, if ``endpoint`` is not ``<protocol>/<host>:<port>``
    (or, with ``resolve``, if its host name does not resolve)."""
    flag = f"--{side}"
    locator = re.split(r"[?#]", endpoint, maxsplit=1)[0]
    protocol, slash, address = locator.partition("/")
    if not slash:
        raise TransportError(
            f"{flag} {endpoint!r} has no protocol: write it as tcp/{endpoint} (protocol/host:port)"
        )
    if protocol not in PROTOCOLS:
        raise TransportError(
            f"{flag} {endpoint!r} names protocol {protocol!r}, which Zenoh does not know: "
            f"use one of {', '.join(p + '/' for p in PROTOCOLS)} (e.g. tcp/{address or 'HOST:7447'})"
        )
    if protocol == "unixsock-stream":
        return
    match = _HOST_PORT.match(address)
    if match is None:
        raise TransportError(
            f"{flag} {endpoint!r} has no port: write it as {protocol}/{address or 'HOST'}:7447 "
            "(host:port, IPv6 addresses in [brackets])"
        )
    port = match["port"]
    if not port.isdigit() or not (0 if side == "listen" else 1) <= int(port) <= 65535:
        raise TransportError(f"{flag} {endpoint!r}: port {port!r} is not a number from 1 to 65535")
    host = match["v6"] or match["host"]
    if resolve and not match["v6"]:
        try:
            socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)
        except socket.gaierror as exc:
            why = (
                "could not be resolved now (no DNS answer)"
                if exc.errno == socket.EAI_AGAIN
                else "does not resolve"
            )
            raise TransportError(
                f"{flag} {endpoint!r}: host name {host!r} {why}; check the spelling and the DNS, "
                "or give an IP address"
            ) from None


def check_endpoints(connect: list[str] | None, listen: list[str] | None, resolve: bool = False) -> None:
    """Every ``connect`` and ``listen`` endpoint through :func:`check_endpoint`."""
    for side, endpoints in (("connect", connect), ("listen", listen)):
        for endpoint in endpoints or ():
            check_endpoint(endpoint, side, resolve)


def plain_zenoh_error(exc: BaseException) -> str:
    """Zenoh's message without its Rust wrapping (``Json5Err(Message { msg: ...``, ``at /root/...rs``)."""
    text = str(exc)
    if 'msg: "' in text:
        text = text.split('msg: "', 1)[1]
    text = re.split(r" at /\S+\.rs:\d+|\s+at /|\\?\", location", text)[0]
    return text.strip().rstrip(".!") or type(exc).__name__


def listening(endpoint: str, timeout: float = 0.5) -> bool | None:
    """Does something accept TCP connections at ``endpoint`` (tcp/ or tls/ ``host:port``)? None
    where that cannot be told from here (udp/, quic/, ws/, unix sockets, a bad address)."""
    locator = re.split(r"[?#]", endpoint, maxsplit=1)[0]
    protocol, _, address = locator.partition("/")
    match = _HOST_PORT.match(address)
    if protocol not in ("tcp", "tls") or match is None or not match["port"].isdigit():
        return None
    try:
        with socket.create_connection((match["v6"] or match["host"], int(match["port"])), timeout):
            return True
    except OSError:
        return False


def refusal(endpoints: list[str], user: str | None) -> str | None:
    """Why a client could not open a session, told from the endpoints themselves: a router that
    listens but refused the session turned down its credentials (``user``: the user it sent, None if
    none), and nothing listening means no router; None when neither can be told (Zenoh's error says
    "Unable to connect" in both cases)."""
    probes = {endpoint: listening(endpoint) for endpoint in endpoints}
    open_ = [e for e, up in probes.items() if up]
    if open_:
        sent = f"as user {user!r}" if user else "without a user and password"
        tls = " (or, on tls/, its TLS certificates do not match ours)" if open_[0].startswith("tls/") else ""
        return (
            f"a router listens at {open_[0]} but refused this session {sent}: the user or password is "
            f"wrong{' or missing' if not user else ''}{tls}; check --credentials (or NAVLEARN_ZENOH_USER "
            "and NAVLEARN_ZENOH_PASSWORD) against the router's --auth-dictionary"
        )
    if probes and all(up is False for up in probes.values()):
        return "nothing listens there"
    return None
