"""Every `navlearn ...` command the guides show parses: the lines of README.md's and docs/*.md's
```bash blocks are run through the real command-line parser (nothing is started), so a renamed or
removed flag fails here, not in a reader's terminal. docs/notebook.md is history and is skipped."""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import re
import shlex
from pathlib import Path

import pytest

from services.cli import build_parser

parser = functools.cache(build_parser)
"""one parser for every case (building it imports every command)"""

ROOT = Path(__file__).resolve().parents[1]
GUIDES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "notebook.md")]
SEPARATORS = {"&&", "||", "|", ";", "&"}
ASSIGNMENT = re.compile(r"^[A-Z_][A-Z0-9_]*=")


def commands(doc: Path) -> list[tuple[int, list[str]]]:
    """(line, argv after `navlearn`) of every navlearn command in the doc's bash blocks."""
    found: list[tuple[int, list[str]]] = []
    fenced, pending, start = False, "", 0
    for number, line in enumerate(doc.read_text().splitlines(), 1):
        if line.startswith("```"):
            fenced = line.strip() in ("```bash", "```sh", "```console")
            continue
        if not fenced:
            continue
        if not pending:
            start = number
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        text, pending = pending + line, ""
        try:
            words = shlex.split(text, comments=True)
        except ValueError:
            continue
        segment: list[str] = []
        for word in [*words, ";"]:
            if word not in SEPARATORS:
                segment.append(word)
                continue
            while segment and ASSIGNMENT.match(segment[0]):
                segment.pop(0)
            if segment and segment[0] == "navlearn" and "..." not in segment:
                found.append((start, segment[1:]))
            segment = []
    return found


def cases() -> list[tuple[str, int, list[str]]]:
    return [(doc.name, line, argv) for doc in GUIDES for line, argv in commands(doc)]


def test_the_guides_show_commands():
    assert len(cases()) >= 40


@pytest.mark.parametrize(("doc", "line", "argv"), cases(), ids=lambda v: v if isinstance(v, str) else None)
def test_command_parses(doc, line, argv):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser().parse_args(argv)
        except SystemExit as exc:
            assert exc.code == 0, f"{doc}:{line}: navlearn {' '.join(argv)}\n{err.getvalue()}"


def test_a_flag_the_parser_does_not_know_fails():
    with contextlib.redirect_stderr(io.StringIO()), pytest.raises(SystemExit) as exc:
        parser().parse_args(["up", "--no-such-flag"])
    assert exc.value.code == 2


def test_the_extractor_joins_continuations_and_skips_other_programs(tmp_path):
    doc = tmp_path / "g.md"
    doc.write_text(
        "```bash\nnavlearn up --run a \\\n  --duration 5   # comment\n"
        "export X=1 && NAVLEARN_RUN=r navlearn status\n"
        "supervisord -c x.conf\nnavlearn actor ...\n```\n\n```\nnavlearn not-bash\n```\n"
    )
    assert commands(doc) == [(2, ["up", "--run", "a", "--duration", "5"]), (4, ["status"])]


OTHER_PROGRAMS = {
    "--nav", "--robots", "--runs", "--only", "--only-flood", "--compare-tree", "--against",  # bench/ programs
    "--replicas",  # kubectl
    "--short",  # git rev-parse
    "--once",  # ros2 topic
    "--index-url",  # pip (a CPU-only torch, docs/install.md)
    "--before",  # bench/first_run.py
    "--sizes", "--expert-episodes", "--throughput-seconds",  # bench/map_sizes.py
    "--tls-",  # the --tls-* family, named as a prefix
}  # fmt: skip
"""flags the guides name that belong to other programs than navlearn"""


def navlearn_options() -> set[str]:
    found: set[str] = set()

    def walk(p: argparse.ArgumentParser) -> None:
        for action in p._actions:
            found.update(action.option_strings)
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    walk(sub)

    walk(parser())
    return found


def test_every_flag_the_guides_name_exists():
    known = navlearn_options() | OTHER_PROGRAMS
    unknown = [
        f"{doc.name}:{number}: {flag}"
        for doc in GUIDES
        for number, line in enumerate(doc.read_text().splitlines(), 1)
        for flag in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", line)
        if flag not in known
    ]
    assert not unknown, "flags no navlearn command has:\n" + "\n".join(unknown)
