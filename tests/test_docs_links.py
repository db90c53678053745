"""The guides' links resolve: every relative link and image in README.md, RESULTS.md, docs/*.md and
results/**/README.md names a file or folder of the repository, and every #anchor a heading of the
file it points into (GitHub's heading ids). Links outside the repository (http, mailto) are not
fetched."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~)")
CODE = re.compile(r"`[^`]*`")


def guides() -> list[Path]:
    found = [ROOT / "README.md", ROOT / "RESULTS.md", *sorted((ROOT / "docs").glob("*.md"))]
    found += sorted((ROOT / "results").glob("**/*.md"))
    return [p for p in found if p.is_file()]


def slug(heading: str) -> str:
    """GitHub's id for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = CODE.sub(lambda m: m.group(0).strip("`"), heading.strip().lstrip("#").strip()).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(doc: Path) -> set[str]:
    seen: dict[str, int] = {}
    ids = set()
    fenced = False
    for line in doc.read_text().splitlines():
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            base = slug(line)
            n = seen.get(base, 0)
            seen[base] = n + 1
            ids.add(base if n == 0 else f"{base}-{n}")
    return ids


def links(doc: Path) -> list[tuple[int, str]]:
    found = []
    fenced = False
    for number, line in enumerate(doc.read_text().splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            found += [(number, target) for target in LINK.findall(CODE.sub("", line))]
    return found


def broken(doc: Path) -> list[str]:
    problems = []
    for number, target in links(doc):
        if re.match(r"^[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        resolved = (doc.parent / path).resolve() if path else doc
        if not resolved.exists():
            problems.append(f"{doc.relative_to(ROOT)}:{number}: {target}: no such file")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            problems.append(f"{doc.relative_to(ROOT)}:{number}: {target}: no heading #{anchor}")
    return problems


@pytest.mark.parametrize("doc", guides(), ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(doc):
    assert not broken(doc), "\n".join(broken(doc))


def test_the_checker_finds_a_broken_link_and_a_broken_anchor(tmp_path, monkeypatch):
    monkeypatch.setattr(f"{__name__}.ROOT", tmp_path)
    (tmp_path / "b.md").write_text("# B title\n\n## Part `two`, done\n")
    doc = tmp_path / "a.md"
    doc.write_text(
        "[ok](b.md) [ok](b.md#part-two-done) [ok](#a) ![img](b.md)\n\n# A\n\n```\n[skip](nowhere.md)\n```\n"
        "[bad](c.md) [bad](b.md#part-three) `[skip](nowhere.md)` [web](https://example.org/x)\n"
    )
    assert broken(doc) == ["a.md:8: c.md: no such file", "a.md:8: b.md#part-three: no heading #part-three"]


def test_readme_is_a_short_guide_with_the_ci_commands():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    assert len(readme.splitlines()) <= 250
    for command in ('pip install -e ".[test]"', "python -m pytest -q -n 2"):
        assert command in readme and command in ci
    assert not re.search(r"\bpart \d+\b", readme), "README tells a run's history (part N)"
