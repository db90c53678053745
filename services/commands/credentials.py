"""`navlearn credentials`: per-process passwords and the per-process ACL of a deployment."""

from __future__ import annotations

import argparse
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "credentials",
        help="create per-process Zenoh credentials and the access control rules of a deployment",
        description=(
            "Write, for one run: users.txt (the router's user:password dictionary), one "
            "<id>.credentials file per process (a fresh random password, mode 0600; give it to that "
            "process with --credentials) and acl.json5 (deny by default; every actor may only publish "
            "transitions/<its id>, each demonstrator only demos/<its source>, each evaluator only "
            "eval/<its id>; only the learner publishes weights and acknowledgements and answers "
            "status/learner). Each process's user name is its id, so start it with the same --id. "
            "Example: navlearn credentials --out deploy/secrets --run r1 --actors a1 a2 "
            "--demonstrators astar --evaluators ev1; then navlearn router --auth-dictionary "
            "deploy/secrets/users.txt --acl deploy/secrets/acl.json5 ..."
        ),
    )
    parser.add_argument("--out", required=True, help="directory to write the files into (created)")
    parser.add_argument("--run", default="default", help="run name the rules are for (default: default)")
    parser.add_argument(
        "--learner", default="learner", help="the learner's id and user name (default learner)"
    )
    parser.add_argument("--actors", nargs="*", default=[], metavar="ID", help="actor ids, one user each")
    parser.add_argument(
        "--demonstrators",
        nargs="*",
        default=[],
        metavar="ID[=SOURCE]",
        help="demonstrator ids; ID publishes demos/ID, ID=SOURCE publishes demos/SOURCE",
    )
    parser.add_argument("--evaluators", nargs="*", default=[], metavar="ID", help="evaluator ids")
    parser.add_argument(
        "--operators",
        nargs="*",
        default=["status"],
        metavar="USER",
        help="users that may only run navlearn status (default: status)",
    )
    parser.add_argument(
        "--cert-names",
        action="store_true",
        help="also require each process's TLS client certificate common name to be its id (mutual TLS; "
        "make the certificates with navlearn certs --clients <the same ids>)",
    )
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from protocols.errors import ProtocolError
    from services.ops.acl import Deployment, write_deployment

    deployment = Deployment(
        run=args.run,
        learner=args.learner,
        actors=args.actors,
        demonstrators=args.demonstrators,
        evaluators=args.evaluators,
        operators=args.operators,
        cert_names=args.cert_names,
    )
    try:
        written = write_deployment(args.out, deployment)
    except (ValueError, ProtocolError, OSError) as exc:
        print(f"navlearn credentials: {exc}", file=sys.stderr)
        return 2
    for path in written.values():
        print(f"wrote {path}")
    print(
        f"router: --auth-dictionary {written['users.txt']} --acl {written['acl.json5']}; "
        f"each process: --id <id> --credentials {args.out}/<id>.credentials"
    )
    return 0
