"""The `navlearn` command line: one entry point, one sub-command per module.

Sub-commands live in ``services/commands/<name>.py`` and are discovered here,
so adding a command never means editing this file.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from services import commands


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="navlearn",
        description=(
            "Distributed actor-learner training for mobile-robot navigation: "
            "robot worlds, MDP toolkit, planners, NNQL and NIRL learners, and the "
            "Zenoh services that run them. `navlearn COMMAND --help` explains each command."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
