"""`navlearn router`: a stand-alone Zenoh router for multi-host runs."""

from __future__ import annotations

import argparse

from services.common.transport import add_zenoh_args


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "router",
        help="run a stand-alone Zenoh router (multi-host setups)",
        description=(
            "Run a Zenoh router that actors, learner, demonstrator and evaluator on several hosts "
            "connect to as clients (--connect tcp/<this host>:7447). Listens on tcp/127.0.0.1:7447 "
            "unless --listen says otherwise (e.g. --listen tcp/0.0.0.0:7447, or tls/0.0.0.0:7447 with "
            "--tls-cert/--tls-key). Logs to stdout; stops cleanly on SIGTERM or Ctrl-C."
        ),
    )
    add_zenoh_args(parser, default_mode="router", modes=("router",))
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import logging
    import signal
    import sys
    import threading

    import zenoh

    from services.common.transport import TransportError, settings_from_args
    from services.ops.router import run_router

    logging.basicConfig(
        stream=sys.stdout, level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    zenoh.init_log_from_env_or("error")
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    try:
        return run_router(settings_from_args(args, mode="router"), stop)
    except TransportError as exc:
        print(f"navlearn router: {exc}", file=sys.stderr)
        return 2
