"""The `navlearn` command line: one entry point, one sub-command per module.

Sub-commands live in ``services/commands/<name>.py`` and are discovered here,
so adding a command never means editing this file.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import pkgutil
import sys

from services import commands


class HelpFormatter(argparse.HelpFormatter):
    """The one --help style of every command: each option shows its default (unless its help already
    names it), and a description written in lines keeps them (one written as a paragraph is wrapped)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            not action.option_strings
            or action.default is None
            or action.default is False
            or action.default == argparse.SUPPRESS
            or "default" in text.lower()
        ):
            return text
        return f"{text} (default: %(default)s)"

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n" in text.strip():
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that always formats its help with HelpFormatter (sub-commands included)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs["formatter_class"] = HelpFormatter
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="navlearn",
        description=(
            "Distributed actor-learner training for mobile-robot navigation: "
            "robot worlds, MDP toolkit, planners, NNQL and NIRL learners, and the "
            "Zenoh services that run them. `navlearn COMMAND --help` explains each command."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def closest_flag(parser: argparse.ArgumentParser, given: str) -> str | None:
    """The option of ``parser`` nearest to ``given`` (``--duraton`` -> ``--duration``), or None if
    none is close (difflib's ratio under 0.6)."""
    flag = given.split("=", 1)[0]
    options = [o for action in parser._actions for o in action.option_strings if o.startswith("--")]
    found = difflib.get_close_matches(flag, options, n=1, cutoff=0.6)
    return found[0] if found else None


def unknown_arguments(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """One sentence for arguments ``parser`` does not take, naming the nearest valid flag of each
    misspelled one."""
    flags = [extra for extra in extras if extra.startswith("-")]
    parts = []
    for extra in flags or extras:  # a misspelled flag's value is not worth naming beside it
        near = closest_flag(parser, extra) if extra.startswith("-") else None
        parts.append(f"{extra} (did you mean {near}?)" if near else extra)
    return f"unrecognized arguments: {', '.join(parts)}; `{parser.prog} --help` lists them all"


def parse(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """Parse ``argv``; arguments that no parser takes are refused by the sub-command's own parser,
    so its usage is shown (not the top level's) with the closest valid flag. One place for every
    sub-command: argparse itself would hand a sub-command's leftovers to the top-level parser."""
    args, extras = parser.parse_known_args(argv)
    if extras:
        sub = parser._subparsers._group_actions[0].choices.get(getattr(args, "command", None), parser)
        sub.error(unknown_arguments(sub, extras))
    return args


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse(parser, argv)
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
