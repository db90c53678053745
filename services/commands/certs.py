"""`navlearn certs`: a private CA plus server and client certificates for TLS / mutual TLS."""

from __future__ import annotations

import argparse
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "certs",
        help="create a CA and the TLS certificates of a deployment",
        description=(
            "Create a private certificate authority (ca.pem, ca.key), a server certificate for the "
            "router (server.pem, server.key) valid for every --hosts entry, and one client certificate "
            "per --clients name (<name>.pem, <name>.key, common name = the name, for mutual TLS). "
            "Keys are ECDSA P-256 written with mode 0600; keep ca.key off the hosts. Example: "
            "navlearn certs --out deploy/tls --hosts 10.0.0.5 learner.lan --clients learner actor1"
        ),
    )
    parser.add_argument("--out", required=True, help="directory to write the PEM files into (created)")
    parser.add_argument(
        "--hosts",
        nargs="+",
        required=True,
        help="DNS names and/or IP addresses the router is reached at (go into the server certificate)",
    )
    parser.add_argument(
        "--clients",
        nargs="*",
        default=["client"],
        help="client certificate names, one pair each (default: one named client)",
    )
    parser.add_argument("--days", type=int, default=365, help="validity of every certificate in days")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from services.ops.certs import make_certs

    if args.days < 1:
        print("navlearn certs: --days must be >= 1", file=sys.stderr)
        return 2
    try:
        written = make_certs(args.out, args.hosts, args.clients, args.days)
    except (ValueError, OSError) as exc:
        print(f"navlearn certs: {exc}", file=sys.stderr)
        return 2
    for path in written.values():
        print(f"wrote {path}")
    print(
        f"router: --tls-root-ca {written['ca.pem']} --tls-cert {written['server.pem']} "
        f"--tls-key {written['server.key']} [--tls-mtls]"
    )
    return 0
