"""Building the `navlearn` parser stays light: no torch, TorchRL, numba or Zenoh is imported to
show `--help` or to parse a `status` call (torch alone is seconds; `navlearn status` once paid
3.5 s of imports before it asked anything, and a loaded machine made it time out in tests)."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("torch", "torchrl", "tensordict", "numba", "zenoh", "matplotlib")


def test_building_every_parser_imports_nothing_heavy() -> None:
    probe = (
        "import json, sys\n"
        "from services.cli import build_parser\n"
        "build_parser()\n"
        f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
