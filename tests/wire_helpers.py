"""Shared test helpers for the wire: hypothesis strategies for every message kind, deep equality,
raw envelopes for malformed-input tests, and subprocess helpers for Zenoh tests."""

from __future__ import annotations

import contextlib
import dataclasses
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import msgpack
import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from protocols.arrays import default
from protocols.messages import (
    DemoBatch,
    EpisodeMeta,
    EvalReport,
    Message,
    StatusReport,
    TransitionBatch,
    WeightsUpdate,
)

REPO = Path(__file__).resolve().parents[1]
N_ACTIONS = 5

names = st.text(
    st.characters(codec="utf-8", categories=("L", "N", "P", "S"), include_characters=" "),
    min_size=1,
    max_size=24,
)
finite32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
json_leaves = (
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | names
)
json_values = st.recursive(
    json_leaves,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(names, inner, max_size=4),
    max_leaves=12,
)
header = {"sender": st.text(max_size=10).filter(str.isprintable), "seq": st.integers(0, 2**63 - 1)}


def f32(shape) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float32, shape, elements=finite32)


@st.composite
def transition_batches(draw) -> TransitionBatch:
    n, dim = draw(st.integers(0, 40)), draw(st.integers(1, 16))
    return TransitionBatch(
        actor=draw(names),
        model=draw(names),
        policy_version=draw(st.integers(0, 2**63 - 1)),
        env_ids=draw(hnp.arrays(np.int32, n)),
        obs=draw(f32((n, dim))),
        action=draw(hnp.arrays(np.int64, n, elements=st.integers(0, N_ACTIONS - 1))),
        reward=draw(f32(n)),
        next_obs=draw(f32((n, dim))),
        terminated=draw(hnp.arrays(np.bool_, n)),
        truncated=draw(hnp.arrays(np.bool_, n)),
        **{k: draw(v) for k, v in header.items()},
    )


@st.composite
def demo_batches(draw) -> DemoBatch:
    lengths = draw(st.lists(st.integers(1, 6), max_size=5))
    steps, dim = sum(lengths), draw(st.integers(1, 12))
    cell = st.tuples(st.integers(0, 2**31 - 1), st.integers(0, 2**31 - 1))
    episodes = [
        EpisodeMeta(
            map_id=draw(st.text(max_size=12).filter(str.isprintable)),
            start=draw(cell),
            goal=draw(cell),
            seed=draw(st.none() | st.integers(-(2**63), 2**63 - 1)),
        )
        for _ in lengths
    ]
    return DemoBatch(
        source=draw(st.sampled_from(["astar", "human", "file"])),
        quality=draw(st.none() | names),
        episode_lengths=np.array(lengths, np.int32),
        obs=draw(f32((steps + len(lengths), dim))),
        actions=draw(hnp.arrays(np.int64, steps, elements=st.integers(0, N_ACTIONS - 1))),
        rewards=draw(f32(steps)),
        terminations=draw(hnp.arrays(np.bool_, steps)),
        truncations=draw(hnp.arrays(np.bool_, steps)),
        episodes=episodes,
        **{k: draw(v) for k, v in header.items()},
    )


tensor_dtypes = st.sampled_from(
    ["<f2", "<f4", "<f8", "|u1", "|i1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "|b1"]
)


@st.composite
def tensors(draw) -> np.ndarray:
    dtype = np.dtype(draw(tensor_dtypes))
    shape = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))
    elements = (
        st.floats(width=8 * dtype.itemsize, allow_nan=False, allow_infinity=False)
        if dtype.kind == "f"
        else None
    )
    return draw(hnp.arrays(dtype, shape, elements=elements))


@st.composite
def weights_updates(draw) -> WeightsUpdate:
    return WeightsUpdate(
        model=draw(names),
        version=draw(st.integers(0, 2**63 - 1)),
        tensors=draw(st.dictionaries(names, tensors(), max_size=5)),
        architecture=draw(st.dictionaries(names, json_values, max_size=4)),
        **{k: draw(v) for k, v in header.items()},
    )


@st.composite
def eval_reports(draw) -> EvalReport:
    return EvalReport(
        model=draw(names),
        policy_version=draw(st.integers(0, 2**63 - 1)),
        metrics=draw(st.dictionaries(names, st.dictionaries(names, json_values, max_size=4), max_size=3)),
        **{k: draw(v) for k, v in header.items()},
    )


@st.composite
def learner_statuses(draw) -> StatusReport:
    ints = st.dictionaries(names, st.integers(-(2**63), 2**63 - 1), max_size=4)
    floats = st.dictionaries(names, st.floats(allow_nan=False, allow_infinity=False), max_size=4)
    return StatusReport(
        counters=draw(ints),
        rates=draw(floats),
        versions=draw(ints),
        replay_sizes=draw(ints),
        actors_last_seen=draw(floats),
        losses=draw(st.dictionaries(names, st.floats(), max_size=4)),
        last_eval=draw(st.none() | st.dictionaries(names, json_values, max_size=3)),
        robot=draw(st.none() | st.dictionaries(names, json_values, max_size=3)),
        **{k: draw(v) for k, v in header.items()},
    )


any_message = st.one_of(
    transition_batches(), demo_batches(), weights_updates(), eval_reports(), learner_statuses()
)


def same(a: object, b: object) -> bool:
    """Deep equality for messages: arrays equal in dtype, shape and values (NaN equal to NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
        )
    if isinstance(a, Message):
        return type(a) is type(b) and all(
            same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and a != a:
        return isinstance(b, float) and b != b
    return type(a) is type(b) and a == b


def small_transitions(n: int = 4, dim: int = 11, **overrides) -> TransitionBatch:
    rng = np.random.default_rng(0)
    fields = dict(
        actor="a1",
        model="nnql",
        policy_version=1,
        env_ids=np.arange(n),
        obs=rng.random((n, dim)),
        action=np.arange(n) % N_ACTIONS,
        reward=np.ones(n),
        next_obs=rng.random((n, dim)),
        terminated=np.zeros(n, bool),
        truncated=np.zeros(n, bool),
    )
    fields.update(overrides)
    return TransitionBatch(**fields)


def raw_envelope(kind: str = "transitions", body: object = None, version: object = 1, **extra) -> bytes:
    """An envelope packed by hand (arrays through the extension), bypassing the message classes."""
    envelope = {"v": version, "k": kind, "s": "test", "n": 0, "b": body, **extra}
    return msgpack.packb(envelope, default=default)


# ----------------------------------------------------------------------------- processes


def read_lines(proc: subprocess.Popen) -> list[str]:
    """Start collecting ``proc``'s stdout lines in the background; the list fills as lines arrive."""
    lines: list[str] = []

    def pump() -> None:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))

    threading.Thread(target=pump, daemon=True).start()
    return lines


def wait_for_line(lines: list[str], text: str, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for line in list(lines):
            if text in line:
                return line
        time.sleep(0.02)
    raise AssertionError(f"no line containing {text!r} within {timeout} s; got {lines[-20:]}")


def start(args: list[str], env: dict | None = None) -> tuple[subprocess.Popen, list[str]]:
    """A Python subprocess (stdout and stderr merged, line-collected)."""
    proc = subprocess.Popen(
        [sys.executable, *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    return proc, read_lines(proc)


def stop(proc: subprocess.Popen, timeout: float = 10) -> int:
    """SIGTERM, then SIGKILL if it does not exit in ``timeout`` s; returns the exit code."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


@contextlib.contextmanager
def small_learner(endpoint: str, run: str, checkpoints: Path) -> Iterator[list[str]]:
    """A `navlearn learner` process (16 hidden units) hosting the router on ``endpoint``, up: its
    output lines while the block runs, then stopped."""
    argv = ["-m", "services.cli", "learner", "--listen", endpoint, "--run", run,
            "--checkpoint-dir", str(checkpoints), "--hidden-sizes", "16"]  # fmt: skip
    learner, lines = start(argv)
    try:
        wait_for_line(lines, "learner learner up", timeout=240)
        yield lines
    finally:
        stop(learner, timeout=60)
