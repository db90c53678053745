"""What `navlearn actor` and `navlearn evaluator` share: a Zenoh client service on an env (navlearn's
world, or a Gymnasium env with --env), configured by one dataclass of its own.

Both take the same flags besides their config's (the env's, --verbose and the Zenoh ones, as a client
by default), turn a bad argument into one line and exit code 2 before anything starts, and stop
cleanly on SIGTERM or Ctrl-C; each command module keeps its description and what it runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from services.common.env_options import add_env_options, env_from_args
from services.common.options import add_options
from services.common.transport import add_zenoh_args


def register_env_service(
    subparsers: argparse._SubParsersAction,
    name: str,
    help_text: str,
    description: str,
    config_cls: type,
    env_prefix: str,
    main: Callable[[argparse.Namespace], int],
) -> argparse.ArgumentParser:
    """The ``navlearn <name>`` subcommand: ``config_cls``' flags (reading ``<env_prefix>_<FIELD>``),
    the env's, --verbose and the Zenoh flags; ``main`` runs it."""
    parser = subparsers.add_parser(
        name, help=help_text, description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_options(parser, config_cls, env_prefix, name)
    add_env_options(parser)
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    add_zenoh_args(parser, default_mode="client")
    parser.set_defaults(func=main)
    return parser


def run_env_service(
    args: argparse.Namespace, name: str, config_cls: type, env_prefix: str, run: Callable
) -> int:
    """``run(config, zenoh settings, stop event, env config)`` from the parsed ``args``: a bad argument
    (or an error ``run`` raises as a TransportError or ValueError) is one line on stderr and exit code 2."""
    import sys

    from services.common.options import OptionError, options_from_args
    from services.common.process import setup_logging, stop_on_signals
    from services.common.transport import TransportError, settings_from_args

    try:
        config = options_from_args(config_cls, args, env_prefix)
        env = env_from_args(args)
        settings = settings_from_args(args)
    except (OptionError, TransportError, OSError, ValueError) as exc:
        print(f"navlearn {name}: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose)
    stop = stop_on_signals()
    try:
        return run(config, settings, stop, env)
    except (TransportError, ValueError) as exc:
        print(f"navlearn {name}: {exc}", file=sys.stderr)
        return 2
