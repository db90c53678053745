"""Generated secrets are private (0600) even when they overwrite files that were readable by all.

`navlearn credentials` and `navlearn certs` run as real commands over an output directory
that already holds 0644 files of the same names (an earlier run, a copy, a checkout): the new
passwords and keys must not land in those modes.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from services.ops.secret_files import write_private

CREDENTIALS = [
    "users.txt",
    "learner.credentials",
    "a1.credentials",
    "astar.credentials",
    "status.credentials",
]
KEYS = ["ca.key", "server.key", "learner.key", "a1.key"]


def _navlearn(*argv: str) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", *argv], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr


def _plant(out: Path, names: list[str]) -> None:
    out.mkdir(exist_ok=True)
    for name in names:
        (out / name).write_text("old, world-readable\n")
        (out / name).chmod(0o644)


def _mode(path: Path) -> int:
    return path.stat().st_mode & 0o777


def test_credentials_over_existing_files_are_0600(tmp_path):
    out = tmp_path / "secrets"
    _plant(out, CREDENTIALS)
    _navlearn("credentials", "--out", str(out), "--run", "r1", "--actors", "a1", "--demonstrators", "astar")
    for name in CREDENTIALS:
        assert _mode(out / name) == 0o600, f"{name} is {oct(_mode(out / name))}"
        assert "old" not in (out / name).read_text()
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


def test_certificate_keys_over_existing_files_are_0600(tmp_path):
    pytest.importorskip("cryptography")
    out = tmp_path / "tls"
    _plant(out, KEYS)
    _navlearn("certs", "--out", str(out), "--hosts", "127.0.0.1", "--clients", "learner", "a1")
    for name in KEYS:
        assert _mode(out / name) == 0o600, f"{name} is {oct(_mode(out / name))}"
        assert (out / name).read_text().startswith("-----BEGIN PRIVATE KEY-----")


def test_write_private_replaces_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "secret"
    target.write_text("old")
    target.chmod(0o666)
    write_private(target, "new")
    assert (target.read_text(), _mode(target)) == ("new", 0o600)
    assert [p.name for p in tmp_path.iterdir()] == ["secret"]
