"""bench/map_size_parts.py at finer cells: every --cell-variants variant runs on the split maps."""

import json

from bench.map_size_parts import main


def test_cell_variants_each_run_on_the_split_maps(tmp_path, capsys):
    out = tmp_path / "parts.jsonl"
    argv = ["--sizes", "16", "--families", "mixed", "--variants", "long", "--cells", "2",
            "--cell-variants", "long", "long+known", "--episodes", "4", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["variant"], r["cell"]) for r in rows] == [
        ("long", 1.0), ("long, cell 1/2", 0.5), ("long+known, cell 1/2", 0.5),
    ]  # fmt: skip
    assert all(r["episodes"] == 4 for r in rows)
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["rows"] == rows
