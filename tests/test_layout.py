"""Results apart from code: bench/ holds benchmark programs (and their own tests) and no recorded
data, the test suite under tests/ imports nothing from bench/, and every results/ folder is indexed
with a README that names its files."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def imported_modules(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_the_test_suite_imports_nothing_from_bench():
    offenders = {
        str(path.relative_to(ROOT)): sorted(m for m in imported_modules(path) if m.split(".")[0] == "bench")
        for path in sorted((ROOT / "tests").glob("**/*.py"))
    }
    assert not {k: v for k, v in offenders.items() if v}


def test_bench_holds_programs_not_data():
    data = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "bench").rglob("*")
        if p.is_file() and p.suffix != ".py" and "__pycache__" not in p.parts
    ]
    assert not data, f"recorded files belong in results/<area>/: {data}"


def test_every_results_folder_is_indexed_and_explains_its_files():
    index = (ROOT / "results" / "INDEX.md").read_text()
    for folder in sorted(p for p in (ROOT / "results").iterdir() if p.is_dir()):
        assert f"({folder.name}/)" in index, f"results/{folder.name}/ is missing from results/INDEX.md"
        readme = folder / "README.md"
        assert readme.is_file(), f"results/{folder.name}/ has no README.md"
        text = readme.read_text()
        for path in folder.iterdir():
            if path.is_file() and path.name != "README.md":
                assert path.name in text, f"results/{folder.name}/README.md does not name {path.name}"
