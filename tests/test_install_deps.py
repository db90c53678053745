"""Every third-party import is declared in pyproject.toml.

A module that happens to be installed on the machine (``cryptography`` once was)
passes a local test run and then fails on a user's fresh install. The shared
checker reads every import in the packages, tests and benches and maps it to the
distribution that provides it; this test fails with its list.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKER = ROOT.parent / "shared" / "tools" / "check_deps.py"


def test_every_import_is_declared_in_pyproject() -> None:
    if not CHECKER.exists():
        pytest.skip(f"the dependency checker is not beside the project ({CHECKER} missing)")
    run = subprocess.run(
        [sys.executable, str(CHECKER)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, f"undeclared imports:\n{run.stdout}{run.stderr}"
