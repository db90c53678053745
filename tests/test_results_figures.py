"""Every figure RESULTS.md and README.md quote agrees with the recorded file it cites
(tests/figures.py says how a row names its sources), and the checker itself catches a changed
number, a changed file and a figure without a source."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.figures import agrees, check, evaluate, quotes

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "RESULTS.md", ROOT / "README.md"]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_quoted_figure_matches_its_file(doc):
    checks = check(doc, ROOT)
    wrong = [f"{c.quote.doc}:{c.quote.line}: {c.quote.text!r}: {c.error}" for c in checks if not c.ok]
    assert not wrong, "\n".join(wrong)


def test_results_quotes_figures_from_every_table_that_has_files():
    checks = check(ROOT / "RESULTS.md", ROOT)
    files = {c.quote.source.split(":", 1)[0] for c in checks}
    assert len(checks) >= 40
    assert {
        "results/world/env_throughput.json",
        "results/wire/wire.json",
        "pretrained/nnql/eval/eval.json",
    } <= files
    assert any(f.startswith("results/nirl/") for f in files)


def test_results_md_stays_a_short_page_headline_first_one_table_per_area():
    text = (ROOT / "RESULTS.md").read_text()
    assert len(text.splitlines()) < 300
    headings = [line[3:] for line in text.splitlines() if line.startswith("## ")]
    assert headings[0] == "Headline"
    areas = ["World", "Wire", "Learner", "Training against Stable-Baselines3", "Your own environment"]
    areas += ["Navigation", "NIRL"]
    areas.append("Reliability")
    assert all(area in headings for area in areas), headings


def write_doc(tmp_path: Path, row: str) -> Path:
    (tmp_path / "r.json").write_text(
        json.dumps({"a": {"success": 0.988, "rate": 130243.7}, "rows": [{"n": 64, "x": 7.68}]})
    )
    curve = [[1, 0.5], [2, 0.9], [3, 0.95]]
    lines = [{"method": "nirl", "seed": s, "ok": v, "curve": curve} for s, v in enumerate([0.97, 0.98, 0.99])]
    (tmp_path / "r.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))
    doc = tmp_path / "DOC.md"
    doc.write_text("| Figure | Source |\n| --- | --- |\n" + row + "\n")
    return doc


def test_a_true_row_passes(tmp_path):
    doc = write_doc(
        tmp_path,
        "| **98.8%** at **130k**, **7.7x**; **98.0%** pooled, **2** to 90%, **3** runs | `r.json:a.success` "
        "`:a.rate` `:rows[n=64].x` `r.jsonl:mean(ok \\| method=nirl)` "
        "`:median_first(curve >= 0.9 \\| method=nirl)` `:count( \\| method=nirl)` |",
    )
    checks = check(doc, tmp_path)
    assert [c.ok for c in checks] == [True] * 6, [c.error for c in checks]


@pytest.mark.parametrize("quoted", ["**98.7%**", "**97%**", "**131k**"])
def test_a_changed_number_fails(tmp_path, quoted):
    source = "`r.json:a.rate`" if quoted.endswith("k**") else "`r.json:a.success`"
    doc = write_doc(tmp_path, f"| {quoted} | {source} |")
    assert not check(doc, tmp_path)[0].ok


def test_a_changed_file_fails(tmp_path):
    doc = write_doc(tmp_path, "| **98.8%** | `r.json:a.success` |")
    assert check(doc, tmp_path)[0].ok
    (tmp_path / "r.json").write_text(json.dumps({"a": {"success": 0.97}}))
    assert not check(doc, tmp_path)[0].ok
    (tmp_path / "r.json").unlink()
    assert "does not exist" in check(doc, tmp_path)[0].error


def test_a_star_step_reads_the_one_value_of_an_object_and_refuses_several(tmp_path):
    (tmp_path / "m.json").write_text(
        json.dumps({"metrics": {"pkg.mod:env": {"success": 0.95}}, "two": {"a": 1, "b": 2}})
    )
    doc = tmp_path / "DOC.md"
    doc.write_text(
        "| Figure | Source |\n| --- | --- |\n| **95%** and **1** | `m.json:metrics.*.success` `:two.*` |\n"
    )
    first, second = check(doc, tmp_path)
    assert first.ok and not second.ok and "2 values, not one" in second.error


def test_a_star_name_step_reads_the_one_value_whose_key_contains_the_name(tmp_path):
    (tmp_path / "m.json").write_text(
        json.dumps({"maps": {"/data/depot.yaml": {"ok": 0.97}, "/data/warehouse.yaml": {"ok": 0.95}}})
    )
    doc = tmp_path / "DOC.md"
    doc.write_text(
        "| Figure | Source |\n| --- | --- |\n"
        "| **95%**, **97%**, **1** | `m.json:maps.*warehouse.ok` `:maps.*depot.ok` `:maps.*data.ok` |\n"
    )
    warehouse, depot, both = check(doc, tmp_path)
    assert warehouse.ok and depot.ok and not both.ok and "2 values, not one" in both.error


def test_a_figure_without_a_source_is_an_error(tmp_path):
    doc = write_doc(tmp_path, "| **98.8%** and **7.7x** | `r.json:a.success` |")
    with pytest.raises(ValueError, match="2 bold figures but 1 sources"):
        quotes(doc)


def test_units_and_notation():
    assert agrees("4e-40", 4.0178e-40) and not agrees("5e-40", 4.0178e-40)
    assert agrees("16.1 M", 16_076_744) and agrees("81,920", 81920.0) and agrees("0", 0)
    assert agrees("6.0%", 0.06) and not agrees("6.1%", 0.06)


def test_bad_paths_are_reported(tmp_path):
    write_doc(tmp_path, "")
    with pytest.raises(KeyError):
        evaluate("r.json:a.missing", tmp_path)
    with pytest.raises(KeyError, match="no line matches"):
        evaluate("r.jsonl:mean(ok | method=bc)", tmp_path)
