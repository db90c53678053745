"""`navlearn up`: the whole system on one machine, as child processes, for a bounded run.

It starts the learner (hosting the Zenoh router on a free loopback port), N
actors, the evaluator and with ``--nirl`` a demonstrator (the learner then also trains NIRL and
the evaluator compares it) as separate processes (``python -m services.cli ...``,
each logging into ``<out>/logs/``), shows one live progress line read from the
learner's status, and stops everything in order when the budget is spent (counted
from the first transition the learner receives), on Ctrl-C or SIGTERM, or when a
child dies (a demonstrator that finished its episodes is not a death): actors and the
demonstrator first, then the learner (which
broadcasts its final weights and writes its checkpoint), then the evaluator
once it has measured the final version (bounded wait). Outputs in ``<out>``:
``checkpoints/``, ``policy/`` (the best-evaluated version's weights, or with ``--no-keep-best`` the
learner's last), ``eval/learning_curve.png``
and ``eval/evaluations.jsonl``, ``tb/`` (TensorBoard) and ``summary.json``.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from agents.evaluation.selection import TEST_SEED, VALIDATION_SEED
from agents.mlp import CONFIG_FILE
from agents.nnql.persistence import replace_dir
from agents.nnql.policy import load_policy_dir, save_policy_dir
from services.common.env_options import write_env_config
from services.common.transport import TransportError, ZenohSettings, free_port, open_session
from services.evaluator.keep_best import kept_record
from services.learner.checkpoint import CheckpointDir
from services.ops.run_record import RunRecord, run_lock, write_record
from services.ops.status import query_alive, query_status, status_dict
from services.ops.up_config import UpConfig
from worlds.own_env import EnvConfig
from worlds.tasks import names_files

log = logging.getLogger("navlearn.up")
PR_SET_PDEATHSIG = 1
MODEL = "nnql"
DEMO_SEED = 10_000
"""the expert demonstrator's episodes start at this seed (+ --seed), apart from the actors' seeds"""
NNQL_CONFIG_FILE = "nnql.json"
"""the run's NNQLConfig in --out, which the learner reads (`navlearn learner --nnql-config`)"""
ENV_CONFIG_FILE = "env.json"
"""the run's EnvConfig in --out, which the learner, actors and evaluator read (`--env-config`)"""
BEST_POLICY = "best-policy"
"""with keep_best: the evaluator's kept policy, in <out>/eval/ (`navlearn evaluator --best-policy`)"""
PHASES = (
    ("building", "compiling"),
    ("waiting for a Zenoh router", "awaiting router"),
    ("waiting for the first weights", "awaiting weights"),
    ("resumed from", "resuming"),
    (" up", "up"),
)
"""(what a child's log line says, the phase shown): its newest matching line is what it is doing"""


def _die_with_parent() -> None:
    """In the child, before exec: get SIGTERM if `up` dies (Linux), so nothing is left behind."""
    with contextlib.suppress(OSError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class Child:
    """One service process with its log file."""

    def __init__(self, name: str, argv: list[str], log_dir: Path, env: dict[str, str]) -> None:
        self.name = name
        self.log_path = log_dir / f"{name}.log"
        self._log = open(self.log_path, "ab")  # noqa: SIM115 - closed in wait()
        self._log_start = self._log.tell()
        """where this launch's lines start (a resumed run appends to the same log)"""
        self.process = subprocess.Popen(
            [sys.executable, "-m", "services.cli", *argv],
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,  # Ctrl-C reaches `up` only; it stops the children in order
            preexec_fn=_die_with_parent,
        )

    def alive(self) -> bool:
        return self.process.poll() is None

    def terminate(self) -> None:
        if self.alive():
            self.process.send_signal(signal.SIGTERM)

    def wait(self, timeout: float) -> int:
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            log.warning("%s did not stop within %.0f s; killing it", self.name, timeout)
            self.process.kill()
            code = self.process.wait()
        self._log.close()
        return code

    def phase(self) -> str:
        """What the process is doing: its newest log line of this launch that says (PHASES), or "starting"."""
        with open(self.log_path, "rb") as fh:
            fh.seek(max(fh.seek(0, os.SEEK_END) - 8192, self._log_start))
            lines = fh.read().decode(errors="replace").splitlines()
        for line in reversed(lines):
            for marker, phase in PHASES:
                if marker in line:
                    return phase
        return "starting"

    def tail(self, lines: int = 15) -> str:
        text = self.log_path.read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])


class Up:
    """Starts, watches and stops the processes of one run."""

    def __init__(self, config: UpConfig, nnql, env: EnvConfig | None = None) -> None:
        """``env``: a Gymnasium env every process runs instead of navlearn's world (its flags passed on)."""
        self.config = config
        self.env = env or EnvConfig()
        self.map_files = self.env.own_world and names_files(config.maps)  # the evaluator measures them too
        self.out = Path(config.out or f"runs/{config.run}")
        port = config.port or free_port()
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.listen = f"tcp/0.0.0.0:{port}" if config.listen_all else self.endpoint
        self.nnql = nnql
        self.children: dict[str, Child] = {}
        self.launched = time.time()
        self.resumed_from = CheckpointDir(self.out / "checkpoints").latest()
        """the checkpoint the learner resumes from (None: a new run)"""
        self.training_s = 0.0
        """seconds from the first transition the learner received to the end of watch()"""
        self.first_transition_s: float | None = None
        """seconds from the processes' start to the first transition the learner received"""
        self._started_at = time.monotonic()
        self.lock = None
        """the OS lock on ``out`` (services.common.dirlock), held from claim() to the process's end"""
        self.best_policy = self.out / "eval" / BEST_POLICY
        """with keep_best: the evaluator's best-evaluated version (services.evaluator.keep_best)"""
        self.eval_seed = VALIDATION_SEED if config.keep_best else TEST_SEED
        """the evaluator's episodes: the validation ones when its figures choose the policy, else the test"""

    def claim(self) -> RunRecord:
        """Lock the run directory (DirectoryInUse, a ValueError naming the holder's pid, if another
        `up` holds it) and record where this run listens (``up.json``, for `navlearn status`)."""
        self.lock = run_lock(self.out).acquire()
        return write_record(self.out, self.config.run, self.endpoint)

    def start(self) -> None:
        cfg, out = self.config, self.out
        self._started_at = time.monotonic()
        (out / "logs").mkdir(parents=True, exist_ok=True)
        base = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
        base.update({"NAVLEARN_RUN": cfg.run, "PYTHONUNBUFFERED": "1"})
        # the learner reads the run's NNQLConfig itself, not re-parsed environment variables
        nnql_file = out / NNQL_CONFIG_FILE
        nnql_file.write_text(json.dumps(self.nnql.to_dict(), indent=1) + "\n")
        env_flags = write_env_config(self.env, out / ENV_CONFIG_FILE)  # the same for every process
        self._spawn(
            "learner",
            [
                "learner",
                "--listen",
                self.listen,
                "--checkpoint-dir",
                str(out / "checkpoints"),
                "--checkpoint-every",
                str(cfg.checkpoint_every),
                "--tensorboard",
                str(out / "tb"),
                "--observation",
                cfg.observation,
                *(["--nirl"] if cfg.nirl else []),
                *(["--nirl-config", cfg.nirl_config] if cfg.nirl_config else []),
                *env_flags,
                "--nnql-config",
                str(nnql_file),
            ],
            base,
        )
        if cfg.nirl:
            argv = ["demonstrator", "--connect", self.endpoint, "--observation", cfg.observation,
                    *demonstrator_argv(cfg)]  # fmt: skip
            self._spawn("demonstrator", argv, base)
        for i in range(cfg.actors):
            self._spawn(
                f"actor-{i + 1}",
                [
                    "actor",
                    "--connect",
                    self.endpoint,
                    "--id",
                    f"actor-{i + 1}",
                    "--envs",
                    str(cfg.envs),
                    "--maps",
                    cfg.maps,
                    "--moving-discs",
                    str(cfg.moving_discs),
                    "--seed",
                    str(cfg.seed + i),
                    "--observation",
                    cfg.observation,
                    *env_flags,
                ],
                base,
            )
        self._spawn(
            "evaluator",
            [
                "evaluator",
                "--connect",
                self.endpoint,
                "--episodes",
                str(cfg.eval_episodes),
                "--every-versions",
                str(cfg.eval_every),
                "--out",
                str(out / "eval"),
                "--tensorboard",
                str(out / "tb"),
                "--launched",
                str(self.launched),
                "--observation",
                cfg.observation,
                *(["--compare", "nirl"] if cfg.nirl else []),
                *(["--imitation", cfg.imitation] if cfg.imitation else []),
                *(["--maps", cfg.maps] if self.map_files else []),
                "--eval-seed",
                str(self.eval_seed),
                *(["--best-policy", str(self.best_policy)] if cfg.keep_best else []),
                *env_flags,
            ],
            base,
        )

    def _spawn(self, name: str, argv: list[str], env: dict[str, str]) -> None:
        self.children[name] = Child(name, argv, self.out / "logs", env)

    def dead_child(self) -> Child | None:
        """A child that exited, but for a demonstrator done with its episodes (exit code 0)."""
        return next(
            (c for c in self.children.values() if not c.alive() and not finished_demonstrator(c)),
            None,
        )

    def phases(self, view: dict[str, Any] | None) -> str:
        """Before the first transition: what the learner, the actors and the evaluator are doing
        (liveliness tokens say who joined; a child's own log says why it has not)."""
        alive = view["alive"] if view else {}
        learner = "up" if view and view["learner"] else self.children["learner"].phase()
        if learner == "up" and self.resumed_from is not None:
            learner = "resumed"
        actors = [c for n, c in self.children.items() if n.startswith("actor-")]
        joined = len(alive.get("actor", []))
        waiting = sorted({c.phase() for c in actors if c.alive()} - {"up"})
        actor_text = (
            f"actors {joined}/{len(actors)} up" if joined or not waiting else "actors " + "/".join(waiting)
        )
        evaluator = self.children["evaluator"].phase()
        if evaluator == "up":
            evaluator = "awaiting weights" if alive.get("evaluator") else "joining"
        return f"learner {learner}, {actor_text}, eval {evaluator}"

    def watch(self, stop: threading.Event, show) -> dict[str, Any] | None:
        """Follow the learner's status until the budget is spent, ``stop`` is set or a child dies.

        ``show(view, elapsed, phases)``: ``elapsed`` counts from the first transition the learner
        received (None before it), ``phases`` says what each process is doing until then.
        """
        cfg = self.config
        settings = ZenohSettings(mode="client", connect=[self.endpoint], run=cfg.run)
        session = None
        while session is None and not stop.is_set():  # the learner's router may take a while to come up
            if (dead := self.dead_child()) is not None:
                raise ChildFailed(dead)
            try:
                session = open_session(settings, connect_timeout=1.0)
            except TransportError:
                show(None, None, self.phases(None))
        view, started, baseline = None, None, None
        if session is None:
            return view
        with session:
            try:
                while not stop.is_set():
                    if (dead := self.dead_child()) is not None:
                        raise ChildFailed(dead)
                    status = query_status(session, cfg.run, timeout=2.0)
                    alive = query_alive(session, cfg.run, timeout=0.5)
                    view = status_dict(status, alive) if status is not None else view
                    received = received_transitions(view)
                    if baseline is None and received is not None:
                        baseline = received  # a resumed learner's totals include its earlier runs
                    if started is None and baseline is not None and received > baseline:
                        started = time.monotonic()
                        self.first_transition_s = started - self._started_at
                    elapsed = None if started is None else time.monotonic() - started
                    show(view, elapsed, None if started else self.phases(view or status_dict(None, alive)))
                    version = view["learner"]["versions"].get(MODEL, 0) if view else 0
                    if elapsed is not None and cfg.duration and elapsed >= cfg.duration:
                        break
                    if cfg.updates and version >= cfg.updates:
                        break
                    stop.wait(1.0)
            finally:
                self.training_s = time.monotonic() - started if started else 0.0
        return view

    def stop_all(self, eval_wait: float = 60.0) -> dict[str, int]:
        """Actors, then the learner (final checkpoint), then the evaluator after its last report."""
        codes = {}
        actors = [c for n, c in self.children.items() if n.startswith(("actor-", "demonstrator"))]
        for child in actors:
            child.terminate()
        for child in actors:
            codes[child.name] = child.wait(30)
        learner = self.children["learner"]
        learner.terminate()
        codes["learner"] = learner.wait(120)
        final = self.final_version()
        evaluator = self.children["evaluator"]
        deadline = time.monotonic() + eval_wait
        while final is not None and evaluator.alive() and time.monotonic() < deadline:
            if final in self.evaluated_versions():
                break
            time.sleep(1.0)
        evaluator.terminate()
        codes["evaluator"] = evaluator.wait(60)
        return codes

    def final_version(self) -> int | None:
        policy = self.latest_policy()
        return json.loads((policy / "config.json").read_text())["version"] if policy else None

    def latest_policy(self) -> Path | None:
        latest = CheckpointDir(self.out / "checkpoints").latest()
        policy = latest / "nnql" / "policy" if latest else None
        return policy if policy and (policy / "config.json").exists() else None

    def write_policy(self, last: Path | None) -> dict[str, Any] | None:
        """The run's policy in ``<out>/policy``: with keep_best the evaluator's best-evaluated version
        (returns its ``kept`` record: version, score, seed, figures), else (or before any evaluation)
        the learner's last, ``last`` (returns None). The learner's NNQL settings go with either."""
        out = self.out / "policy"
        kept = kept_record(self.best_policy) if self.config.keep_best else None
        if kept is None:
            if last is not None:
                shutil.copytree(last, out, dirs_exist_ok=True)
            return None
        weights, config = load_policy_dir(self.best_policy)
        metadata = {k: v for k, v in config.items() if k not in ("model", "kind", "version", "architecture")}
        metadata["nnql_config"] = self.nnql.to_dict()
        replace_dir(
            out,
            lambda tmp: save_policy_dir(tmp, weights, config["architecture"], kept["version"], **metadata),
        )
        return kept

    def evaluated_versions(self) -> set[int]:
        path = self.out / "eval" / "evaluations.jsonl"
        if not path.exists():
            return set()
        lines = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
        return {line["policy_version"] for line in lines if line.get("model", MODEL) == MODEL}

    def write_outputs(
        self, view: dict[str, Any] | None, codes: dict[str, int], wall: float
    ) -> dict[str, Any]:
        policy = self.latest_policy()
        kept = self.write_policy(policy)
        lines = self.out / "eval" / "evaluations.jsonl"
        evaluations = (
            [json.loads(x) for x in lines.read_text().splitlines() if x.strip()] if lines.exists() else []
        )
        last_by_model = {line.get("model", MODEL): line for line in evaluations}  # nnql, nirl, reference
        summary = {
            "run": self.config.run,
            "wall_time_s": round(wall, 1),
            "training_s": round(self.training_s, 1),
            "first_transition_s": None
            if self.first_transition_s is None
            else round(self.first_transition_s, 1),
            "resumed_from": self.resumed_from.name if self.resumed_from else None,
            "final_version": self.final_version(),
            "policy_version": json.loads((self.out / "policy" / CONFIG_FILE).read_text())["version"]
            if policy or kept
            else None,
            "kept": kept,
            "eval_seed": self.eval_seed,
            "exit_codes": codes,
            "last_status": view,
            "last_evaluation": last_by_model.get(MODEL),
            "last_evaluations": last_by_model,
            "outputs": {
                "policy": str(self.out / "policy") if policy or kept else None,
                "checkpoints": str(self.out / "checkpoints"),
                "learning_curve": str(self.out / "eval" / "learning_curve.png"),
                "evaluations": str(lines),
                "tensorboard": str(self.out / "tb"),
                "logs": str(self.out / "logs"),
            },
        }
        (self.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        return summary


def local_dir(out: Path) -> str:
    """The `navlearn status` flags that find ``out`` from the current directory: none where status
    looks by itself (here, or runs/<name> below), else ``--dir OUT``."""
    here = Path.cwd().resolve()
    where = out.resolve()
    return "" if where == here or where.parent == here / "runs" else f" --dir {out}"


def demonstrator_argv(config: UpConfig) -> list[str]:
    """The demonstrator of an ``up --nirl`` run: the --demos dataset once, or the expert on --maps."""
    if config.demos:
        return ["--id", "demonstrator", "--source", "file", "--file", config.demos]
    return [
        "--id", "demonstrator", "--source", config.demonstrator, "--maps", config.maps,
        "--episodes", str(config.demo_episodes), "--rate", "0", "--seed", str(DEMO_SEED + config.seed),
    ]  # fmt: skip


def finished_demonstrator(child: Child) -> bool:
    return child.name == "demonstrator" and child.process.returncode == 0


def received_transitions(view: dict[str, Any] | None) -> int | None:
    """Transitions the learner has received from all actors (None before it answers)."""
    if not view or not view.get("learner"):
        return None
    return sum(actor["transitions"] for actor in view["learner"]["actors"].values())


def checkpoint_number(path: Path) -> int:
    """N of ``ckpt-0000000N``."""
    return int(path.name.rsplit("-", 1)[-1])


class ChildFailed(RuntimeError):
    def __init__(self, child: Child) -> None:
        self.child = child
        super().__init__(f"{child.name} exited with code {child.process.returncode}")
