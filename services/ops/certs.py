"""A private CA and the certificates of one deployment (TLS and mutual TLS between navlearn hosts).

``make_certs(out, hosts, clients)`` writes, with the ``cryptography`` package:
``ca.pem``/``ca.key`` (the deployment's own certificate authority), ``server.pem``/
``server.key`` (the router's, valid for every name or IP address in ``hosts``) and
``<client>.pem``/``<client>.key`` per client (common name = the client name, which
Zenoh's ACL can match as ``cert_common_names``). Keys are ECDSA P-256, written
0600 (also over an existing file: services.ops.secret_files). Point routers at
``--tls-root-ca ca.pem --tls-cert server.pem --tls-key server.key``, clients at
``--tls-root-ca ca.pem`` (plus their own pair for mTLS).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
from pathlib import Path

from services.ops.secret_files import write_private


def _key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _write_key(path: Path, key) -> None:
    from cryptography.hazmat.primitives import serialization

    data = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    write_private(path, data)


def _write_cert(path: Path, cert) -> None:
    from cryptography.hazmat.primitives import serialization

    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _alt_names(hosts: list[str]) -> list:
    from cryptography import x509

    names = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def _certificate(subject: str, key, issuer_name, issuer_key, days: int, *, ca: bool, hosts=(), client=False):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = dt.datetime.now(dt.UTC)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)])
    builder = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(issuer_name or name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=ca, path_length=0 if ca else None), critical=True)
    )
    if ca:
        builder = builder.add_extension(
            x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True
        )
    else:
        usage = ExtendedKeyUsageOID.CLIENT_AUTH if client else ExtendedKeyUsageOID.SERVER_AUTH
        builder = builder.add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
        if hosts:
            builder = builder.add_extension(x509.SubjectAlternativeName(_alt_names(list(hosts))), False)
    return builder.sign(issuer_key or key, hashes.SHA256())


def make_certs(out: str | Path, hosts: list[str], clients: list[str], days: int = 365) -> dict[str, Path]:
    """Write the CA, the server pair (valid for ``hosts``) and one pair per client; returns the paths."""
    if not hosts:
        raise ValueError("give at least one host name or IP address for the server certificate")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    ca_key = _key()
    ca = _certificate("navlearn CA", ca_key, None, None, days, ca=True)
    _write_key(written.setdefault("ca.key", out / "ca.key"), ca_key)
    _write_cert(written.setdefault("ca.pem", out / "ca.pem"), ca)
    server_key = _key()
    server = _certificate(hosts[0], server_key, ca.subject, ca_key, days, ca=False, hosts=hosts)
    _write_key(written.setdefault("server.key", out / "server.key"), server_key)
    _write_cert(written.setdefault("server.pem", out / "server.pem"), server)
    for client in clients:
        key = _key()
        cert = _certificate(client, key, ca.subject, ca_key, days, ca=False, hosts=[client], client=True)
        _write_key(written.setdefault(f"{client}.key", out / f"{client}.key"), key)
        _write_cert(written.setdefault(f"{client}.pem", out / f"{client}.pem"), cert)
    return written
