"""The first hour of a new user (issue 43), through the real `navlearn` command line:
a misspelled flag gets the sub-command's usage and the closest flag; one learner per checkpoint
directory and one `up` per run directory (a second one is refused naming the first's pid and
leaves its files alone); `navlearn status` with no flags, started where `up` runs, finds that run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import free_port

from services.common.dirlock import holder_pid

REPO = Path(__file__).resolve().parents[1]


def navlearn(*argv: str, cwd: Path | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "services.cli", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


def start(argv: list[str], log: Path, cwd: Path | None = None) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH", "")]))
    with open(log, "wb") as out:
        return subprocess.Popen([sys.executable, "-m", "services.cli", *argv], cwd=cwd, env=env,
                                stdout=out, stderr=subprocess.STDOUT)  # fmt: skip


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(60)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.2)


def snapshot(directory: Path) -> dict[str, tuple[int, int]]:
    """Every file below ``directory`` with its size and modification time (ns)."""
    return {str(p.relative_to(directory)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(directory.rglob("*")) if p.is_file()}  # fmt: skip


@pytest.mark.parametrize(
    ("argv", "usage", "suggestion"),
    [
        (["up", "--duraton", "30"], "usage: navlearn up ", "--duraton (did you mean --duration?)"),
        (["status", "--jsn"], "usage: navlearn status ", "--jsn (did you mean --json?)"),
        (["learner", "--checkpoint-dri=x"], "usage: navlearn learner ", "(did you mean --checkpoint-dir?)"),
    ],
)
def test_a_misspelled_flag_shows_the_sub_commands_usage_and_the_closest_flag(argv, usage, suggestion):
    result = navlearn(*argv)
    assert result.returncode == 2
    assert result.stderr.startswith(usage), result.stderr
    assert suggestion in result.stderr, result.stderr
    assert "usage: navlearn [-h] COMMAND" not in result.stderr


def test_a_flag_nothing_resembles_gets_no_suggestion():
    result = navlearn("up", "--zzzzzz")
    assert result.returncode == 2 and "usage: navlearn up " in result.stderr
    assert "unrecognized arguments: --zzzzzz;" in result.stderr and "did you mean" not in result.stderr


@pytest.mark.integration
@pytest.mark.timeout(300)
def test_a_second_learner_on_the_same_checkpoint_directory_is_refused_and_touches_nothing(tmp_path):
    ckpt = tmp_path / "ckpt"
    common = ["--checkpoint-dir", str(ckpt), "--hidden-sizes", "16", "--checkpoint-every", "600"]
    port = free_port()
    first = start(["learner", "--listen", f"tcp/127.0.0.1:{port}", "--run", f"lock{port}", *common],
                  tmp_path / "first.log")  # fmt: skip
    try:
        wait_for(lambda: " up (" in (tmp_path / "first.log").read_text(), 90, "the first learner to be up")
        before, log_before = snapshot(ckpt), (tmp_path / "first.log").read_bytes()
        assert (ckpt / "wal").is_dir() and before  # its write-ahead log is there to be protected
        other = free_port()
        second = navlearn(
            "learner", "--listen", f"tcp/127.0.0.1:{other}", "--run", f"lock{port}", *common, timeout=180
        )
        assert second.returncode == 2, second.stdout + second.stderr
        message = second.stderr.strip().splitlines()[-1]
        assert f"checkpoint directory {ckpt} is in use by process {first.pid}" in message, message
        assert "stop that one first, or give this learner another --checkpoint-dir" in message
        assert snapshot(ckpt) == before
        assert (tmp_path / "first.log").read_bytes().startswith(log_before)  # its own lines only
        assert b"in use" not in (tmp_path / "first.log").read_bytes()
        assert first.poll() is None
    finally:
        stop(first)
    assert first.returncode == 0
    # the lock dies with its process: nobody holds it once the first learner has gone
    assert holder_pid(ckpt, "learner.lock") is None


@pytest.mark.integration
@pytest.mark.timeout(600)
def test_status_with_no_flags_finds_the_up_running_here_and_a_second_up_is_refused(tmp_path):
    """`up` with its defaults (free port, run `local`, runs/local); `status` from the same directory."""
    small = ["--actors", "1", "--envs", "2", "--eval-episodes", "1", "--hidden-sizes", "16",
             "--duration", "600"]  # fmt: skip
    first = start(["up", *small], tmp_path / "up.log", cwd=tmp_path)
    run_dir = tmp_path / "runs" / "local"
    try:
        wait_for(lambda: "navlearn status --connect" in (tmp_path / "up.log").read_text(), 60, "up's banner")
        banner = (tmp_path / "up.log").read_text()
        assert "(or, from this directory, `navlearn status`)" in banner, banner
        learner_log = run_dir / "logs" / "learner.log"
        logs_before = snapshot(run_dir / "logs") if (run_dir / "logs").exists() else {}

        second = navlearn("up", *small, cwd=tmp_path)
        assert second.returncode == 2, second.stdout + second.stderr
        assert f"run directory runs/local is in use by process {first.pid}" in second.stderr, second.stderr
        assert "give this run another --run or --out" in second.stderr
        now = snapshot(run_dir / "logs") if (run_dir / "logs").exists() else {}
        assert {k: v for k, v in now.items() if k in logs_before} == logs_before

        def answered() -> bool:
            result = navlearn("status", "--json", cwd=tmp_path, timeout=30)
            return result.returncode == 0 and '"learner": {' in result.stdout

        # a cold numba cache compiles first (minutes on a busy machine); a warm one answers in seconds
        wait_for(answered, 420, "`navlearn status` (no flags) to get the learner's answer")
        assert learner_log.exists()
        by_dir = navlearn("status", "--json", "--dir", str(run_dir), timeout=30)
        assert by_dir.returncode == 0 and '"learner": {' in by_dir.stdout, by_dir.stderr
    finally:
        stop(first)
    after = navlearn("status", cwd=tmp_path, timeout=30)
    assert after.returncode != 0
    assert "the newest `navlearn up` here, in runs/local, has exited; its run was local" in after.stderr


def test_a_small_final_evaluation_says_it_rests_on_few_episodes_and_its_interval_is_wide():
    from services.commands.up import small_evaluation

    def final(episodes: int) -> dict:
        success = {"value": 0.85, "low": 0.64, "high": 0.95}
        return {"metrics": {"unseen": {"success": success, "episodes": episodes, "spl": 0.6}}}

    line = small_evaluation({"nnql": final(20)})
    assert line is not None and "20 episodes per family" in line and "wide" in line
    assert "--eval-episodes 200" in line
    assert small_evaluation({"nnql": final(500)}) is None
