"""The figures RESULTS.md and README.md quote, read back from the recorded files they cite.

A table that quotes figures has a ``Source`` column. In each row, every figure is written in bold
(``**98.8%**``, ``**130k**``, ``**0.27x**``) in the cells before ``Source``, and ``Source`` lists,
in the same order, where each comes from: one backquoted expression per bold figure, each
``FILE:EXPR`` or, after the first, ``:EXPR`` for the same file as the previous one.

``EXPR`` on a ``.json`` file is a dotted path (``metrics.unseen.success.value``); a list step may
pick its element by a field (``results[robots=64].ours.robot_steps_per_cpu_s``) or by position
(``rounds.0``), and ``*`` steps into the one value of an object that has exactly one (a key with dots
in it, such as an env's ``module:callable`` name: ``saved_policy.metrics.*.success.value``), ``*NAME``
into the one value whose key contains NAME (a map file's path: ``maps.*nav2_depot.policy.success``). On a
``.jsonl`` file (one JSON object per line) it is an aggregate over the lines that match
``| key=value ...``:

- ``mean(PATH | ...)``: the mean of PATH over the matching lines (pooled success over seeds with the
  same episodes each);
- ``median_first(CURVE >= T | ...)``: per line, the first x of the ``[x, y]`` points of CURVE with
  y >= T; the median over the lines (robot-steps to a validation success);
- ``count( | ...)``: how many lines match.

A quoted figure's unit says how to compare: ``%`` multiplies the file's fraction by 100, ``k`` and
``M`` divide by 10^3 and 10^6, anything else (``x``, ``ms``, none) compares as written; a number in
scientific notation (``4e-40``) compares its mantissa. The file's value, rounded to the quoted
number of decimals, must equal the quoted number.
"""

from __future__ import annotations

import json
import math
import re
import statistics
from dataclasses import dataclass
from pathlib import Path

CELL = re.compile(r"(?<!\\)\|")
"""a cell border: a pipe not escaped (a ``\\|`` inside a cell is a pipe of its text)"""
BOLD = re.compile(r"\*\*([^*]+)\*\*")
NUMBER = re.compile(r"^[<>~≈]?\s*(?P<num>\d[\d,]*(?:\.\d+)?(?:e-?\d+)?)\s*(?P<unit>%|k|M|x|ms|us|s)?$")
SOURCE = re.compile(r"`([^`]+)`")
AGGREGATE = re.compile(r"^(?P<fn>mean|median_first|count)\((?P<arg>[^|]*?)\s*(?:\|\s*(?P<where>[^)]*))?\)$")
STEP = re.compile(r"^(?P<key>[^\[\]]+)(?:\[(?P<field>[^=\]]+)=(?P<value>[^\]]+)\])?$")


@dataclass(frozen=True)
class Quote:
    """One bold figure of a table row and where the row says it comes from."""

    doc: str
    line: int
    text: str
    source: str


@dataclass(frozen=True)
class Check:
    quote: Quote
    value: float | None
    error: str | None

    @property
    def ok(self) -> bool:
        return self.error is None


def quotes(doc: Path) -> list[Quote]:
    """Every bold figure of every table row with a Source column; a row whose bold figures and
    sources do not pair up one to one is a ValueError naming the line."""
    found: list[Quote] = []
    source_col: int | None = None
    for number, line in enumerate(doc.read_text().splitlines(), 1):
        if not line.startswith("|"):
            source_col = None
            continue
        cells = [c.strip().replace("\\|", "|") for c in CELL.split(line.strip().strip("|"))]
        if "Source" in cells:
            source_col = cells.index("Source")
            continue
        if source_col is None or set(line) <= set("|-: "):
            continue
        figures = [b for cell in cells[:source_col] for b in BOLD.findall(cell)]
        sources = SOURCE.findall(cells[source_col]) if source_col < len(cells) else []
        if len(figures) != len(sources):
            raise ValueError(
                f"{doc.name}:{number}: {len(figures)} bold figures but {len(sources)} sources ({figures})"
            )
        previous_file = ""
        for text, source in zip(figures, sources, strict=True):
            if source.startswith(":"):
                source = previous_file + source
            previous_file = source.split(":", 1)[0]
            found.append(Quote(doc.name, number, text, source))
    return found


def _walk(data: object, path: str) -> object:
    for step in path.split("."):
        match = STEP.match(step)
        if match is None:
            raise KeyError(f"bad path step {step!r}")
        key, field, value = match["key"], match["field"], match["value"]
        if key.startswith("*"):
            part = key[1:]
            values = [v for k, v in data.items() if part in k]  # type: ignore[union-attr]
            if len(values) != 1:
                raise KeyError(f"{key}: {len(values)} values, not one")
            data = values[0]
        else:
            data = data[int(key)] if isinstance(data, list) else data[key]  # type: ignore[index]
        if field is not None:
            picked = [item for item in data if str(item.get(field)) == value]  # type: ignore[union-attr]
            if len(picked) != 1:
                raise KeyError(f"{step}: {len(picked)} elements match")
            data = picked[0]
    return data


def _lines(path: Path, where: str | None) -> list[dict]:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    for condition in (where or "").split():
        key, _, value = condition.partition("=")
        rows = [row for row in rows if str(row.get(key)) == value]
    if not rows:
        raise KeyError(f"no line matches {where!r}")
    return rows


def evaluate(source: str, root: Path) -> float:
    """The number ``FILE:EXPR`` names, read from FILE under ``root``."""
    file, _, expr = source.partition(":")
    path = root / file
    if not path.is_file():
        raise FileNotFoundError(f"{file} does not exist")
    if path.suffix == ".jsonl":
        match = AGGREGATE.match(expr.strip())
        if match is None:
            raise ValueError(f"{expr!r}: a .jsonl needs mean(...), median_first(...) or count(...)")
        rows = _lines(path, match["where"])
        if match["fn"] == "count":
            return float(len(rows))
        if match["fn"] == "mean":
            return statistics.fmean(float(_walk(row, match["arg"])) for row in rows)  # type: ignore[arg-type]
        curve, _, threshold = match["arg"].partition(">=")
        firsts = []
        for row in rows:
            points = _walk(row, curve.strip())
            hit = [x for x, y in points if y >= float(threshold)]  # type: ignore[union-attr]
            firsts.append(hit[0] if hit else math.inf)
        return float(statistics.median(firsts))
    return float(_walk(json.loads(path.read_text()), expr.strip()))  # type: ignore[arg-type]


def agrees(text: str, value: float) -> bool:
    """Whether the quoted ``text`` is ``value`` as written (unit and decimals)."""
    match = NUMBER.match(text.strip())
    if match is None:
        raise ValueError(f"{text!r} is not a figure")
    number, unit = match["num"].replace(",", ""), match["unit"]
    if "e" in number:
        mantissa = len(number.split("e")[0].partition(".")[2])
        return f"{value:.{mantissa}e}" == f"{float(number):.{mantissa}e}"
    scaled = (
        value * 100 if unit == "%" else value / 1e3 if unit == "k" else value / 1e6 if unit == "M" else value
    )
    decimals = len(number.partition(".")[2])
    return round(scaled, decimals) == round(float(number), decimals)


def check(doc: Path, root: Path) -> list[Check]:
    """Every quoted figure of ``doc`` against its file under ``root``."""
    checks = []
    for quote in quotes(doc):
        try:
            value = evaluate(quote.source, root)
        except (OSError, KeyError, ValueError, IndexError, TypeError) as exc:
            checks.append(Check(quote, None, f"{quote.source}: {exc}"))
            continue
        ok = agrees(quote.text, value)
        checks.append(Check(quote, value, None if ok else f"{quote.source} is {value:g}"))
    return checks
