"""Where a `navlearn up` run can be reached, written into its run directory for `navlearn status`.

`up` picks a free port and its own run name, which `status` cannot guess: so `up` locks its run
directory (services.common.dirlock, file ``up.lock``: one `up` per directory, and a live lock
says the run is live) and writes ``up.json`` there (run name, endpoint, pid). `status` with no
--connect/--run reads it from ``--dir``, else from the directory it is started in and the
``runs/*`` below it (where `up` writes by default), and asks the live run it finds.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from services.common.dirlock import DirLock, holder_pid

RECORD = "up.json"
"""the file in a run directory that says where its `up` listens"""
LOCK = "up.lock"
"""the file in a run directory whose OS lock its `up` holds while it runs"""


@dataclass
class RunRecord:
    """One `up` run: its name, the endpoint of its learner's router, its directory and pid."""

    run: str
    endpoint: str
    out: str
    pid: int
    started: float

    def live(self) -> bool:
        """Is this run's `up` still running (does it hold its directory's lock)?"""
        return holder_pid(self.out, LOCK) is not None

    def status_command(self) -> str:
        """The exact `navlearn status` command for this run from anywhere."""
        return f"navlearn status --connect {self.endpoint} --run {self.run}"


def run_lock(out: str | Path) -> DirLock:
    """The lock `up` holds on its run directory for its lifetime."""
    return DirLock(out, LOCK, "run directory", "give this run another --run or --out")


def write_record(out: str | Path, run: str, endpoint: str) -> RunRecord:
    """Write ``<out>/up.json`` for this process (atomically: temp file + rename)."""
    record = RunRecord(run, endpoint, str(out), os.getpid(), time.time())
    path = Path(out) / RECORD
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(asdict(record), indent=2) + "\n")
    tmp.replace(path)
    return record


def read_record(out: str | Path) -> RunRecord | None:
    """The record in ``out``, or None if there is none (or it is not a record)."""
    try:
        data = json.loads((Path(out) / RECORD).read_text())
        return RunRecord(str(data["run"]), str(data["endpoint"]), str(out), int(data["pid"]),
                         float(data["started"]))  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError):
        return None


def find_records(here: str | Path = ".") -> list[RunRecord]:
    """The records in ``here`` and in ``here/runs/*`` (up's default --out), newest first."""
    base = Path(here)
    candidates = [base, *sorted((base / "runs").glob("*"))] if (base / "runs").is_dir() else [base]
    found = [r for d in candidates if d.is_dir() and (r := read_record(d)) is not None]
    return sorted(found, key=lambda r: r.started, reverse=True)


def choose_record(directory: str | None, here: str | Path = ".") -> RunRecord | None:
    """The run `status` asks when no --connect/--run is given: ``directory``'s record (ValueError if
    it has none), else the one live run found from ``here`` (ValueError naming them when several
    are live), else None (status then asks the defaults)."""
    if directory:
        record = read_record(directory)
        if record is None:
            raise ValueError(
                f"--dir {directory}: no {RECORD} there (it is written by `navlearn up` into its --out "
                "directory); give the directory a `navlearn up` run writes to"
            )
        return record
    live = [r for r in find_records(here) if r.live()]
    if len(live) > 1:
        names = ", ".join(f"{r.out} (run {r.run})" for r in live)
        raise ValueError(f"several `navlearn up` runs are live here: {names}; pick one with --dir")
    return live[0] if live else None
