"""Wire benchmark: codec throughput, end-to-end throughput through a router, weights round-trip latency.

(a) encode+decode of a TransitionBatch (1024 transitions, 8 beams -> obs dim 11),
    against msgpack of plain Python lists and pickle (reference only: never on the wire);
(b) through a `navlearn router` subprocess on loopback, publisher (this process) ->
    subscriber (a second process) with CongestionControl.BLOCK: our encoded, decoded
    and validated TransitionBatches against raw Zenoh puts of byte payloads of the
    same size, in the same run, counted on the subscriber (both kinds copy the payload out
    of Zenoh with ``to_bytes()``; rounds interleaved, each kind first in every other round).
    CPU time per message of the three processes, and of the subscriber's callback, is
    reported for both kinds: it shows where the time goes;
(c) WeightsUpdate of a 2x256 MLP: publish, the peer decodes and echoes it re-encoded,
    we decode the echo; p50/p99 against a raw echo of the same bytes.
The peer (subscriber and echo side) is bench/_wire_peer.py, started as a process of its own.

    python -m bench.wire            # prints human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import pickle
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import msgpack
import numpy as np
import zenoh

from protocols.codec import _decode, _encode, decode, encode
from protocols.limits import Limits
from protocols.messages import TransitionBatch, WeightsUpdate
from services.common.transport import ZenohSettings, free_port, open_session

RAW, MSG, END, ECHO, ECHO_BACK = "bench/raw", "bench/msg", "bench/end", "bench/echo", "bench/echo_back"
LIMITS = Limits(n_actions=5)


@dataclass
class Args:
    batch: int = 1024
    """Transitions per TransitionBatch."""
    obs_dim: int = 11
    """8 range beams + goal distance + sin/cos of the goal bearing."""
    codec_seconds: float = 2.0
    """Time spent on each codec measurement."""
    messages: int = 3000
    """Messages per end-to-end round."""
    rounds: int = 5
    """End-to-end rounds of each kind (raw, ours), interleaved; the median is reported."""
    pings: int = 300
    """Weights round trips measured (after 20 warm-up ones)."""


def make_batch(n: int, obs_dim: int, rng: np.random.Generator, seq: int = 0) -> TransitionBatch:
    return TransitionBatch(
        actor="bench",
        model="nnql",
        policy_version=1,
        env_ids=np.arange(n) % 64,
        obs=rng.random((n, obs_dim), dtype=np.float32),
        action=rng.integers(0, 5, n),
        reward=rng.standard_normal(n).astype(np.float32),
        next_obs=rng.random((n, obs_dim), dtype=np.float32),
        terminated=rng.random(n) < 0.01,
        truncated=rng.random(n) < 0.005,
        sender="bench",
        seq=seq,
    )


def make_weights(
    rng: np.random.Generator, obs_dim: int, hidden: int = 256, n_actions: int = 5
) -> WeightsUpdate:
    sizes = [obs_dim, hidden, hidden, n_actions]
    tensors = {}
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        tensors[f"layers.{i}.weight"] = rng.standard_normal((b, a)).astype(np.float32)
        tensors[f"layers.{i}.bias"] = np.zeros(b, np.float32)
    return WeightsUpdate(
        model="nnql",
        version=1,
        tensors=tensors,
        architecture={"hidden": [hidden, hidden], "activation": "relu"},
    )


def timed_rate(fn, seconds: float) -> float:
    """Calls of ``fn`` per second over about ``seconds``."""
    fn()
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        for _ in range(20):
            fn()
        calls += 20
    return calls / elapsed


def bench_codec(args: Args, batch: TransitionBatch) -> dict:
    wire = encode(batch)
    lists = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in batch.to_body().items()}
    packed_lists = msgpack.packb(lists)
    pickled = pickle.dumps(batch, protocol=pickle.HIGHEST_PROTOCOL)
    out = {}
    for name, size, fn in (
        ("ours", len(wire), lambda: decode(encode(batch), LIMITS)),
        ("msgpack_lists", len(packed_lists), lambda: msgpack.unpackb(msgpack.packb(lists))),
        ("pickle", len(pickled), lambda: pickle.loads(pickle.dumps(batch, protocol=pickle.HIGHEST_PROTOCOL))),
    ):
        rate = timed_rate(fn, args.codec_seconds)
        out[name] = {
            "bytes": size,
            "transitions_per_s": rate * args.batch,
            "mb_per_s": rate * size / 1e6,
        }
        print(
            f"codec {name:14s} {size:8d} B  {rate * args.batch / 1e6:7.2f} M transitions/s  "
            f"{rate * size / 1e6:8.1f} MB/s (encode+decode)"
        )
    out["ratio_vs_msgpack_lists"] = (
        out["ours"]["transitions_per_s"] / out["msgpack_lists"]["transitions_per_s"]
    )
    out["ratio_vs_pickle"] = out["ours"]["transitions_per_s"] / out["pickle"]["transitions_per_s"]
    out["per_call_us"] = per_call(args)
    return out


def per_call(args: Args) -> dict:
    """Encode and decode alone, (min, median) us per call over 20 rounds, on 8 different batches in
    turn; the general path (msgpack + schema checks, no protocols.fastpath) is the same-run baseline."""
    rng = np.random.default_rng(1)
    batches = [make_batch(args.batch, args.obs_dim, rng, seq=i) for i in range(8)]
    wires = [encode(b) for b in batches]
    calls = {
        "encode": (lambda i: encode(batches[i % 8]), lambda i: _encode(batches[i % 8], fast=False)),
        "decode": (
            lambda i: decode(wires[i % 8], LIMITS),
            lambda i: _decode(wires[i % 8], LIMITS, fast=False),
        ),
    }
    rounds, per_round = 20, 200
    out = {}
    for op, (fast, general) in calls.items():
        times: dict[str, list[float]] = {"fast": [], "general": []}
        for _ in range(rounds):  # interleaved, so both see the same machine
            for name, fn in (("fast", fast), ("general", general)):
                start = time.perf_counter()
                for i in range(per_round):
                    fn(i)
                times[name].append((time.perf_counter() - start) / per_round * 1e6)
        out[op] = {name: [min(t), float(np.median(t))] for name, t in times.items()}
        (fast_min, fast_median), (general_min, general_median) = out[op]["fast"], out[op]["general"]
        print(
            f"codec {op} alone (min / median us per call): fast path {fast_min:.1f} / {fast_median:.1f}, "
            f"general path {general_min:.1f} / {general_median:.1f}"
        )
    return out


# ----------------------------------------------------------------------------- publisher side


def wait_line(proc: subprocess.Popen, timeout: float) -> str:
    result: list[str] = []
    reader = threading.Thread(target=lambda: result.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    if not result or not result[0]:
        raise RuntimeError(f"no answer from {proc.args[:4]} within {timeout} s")
    return result[0]


def cpu_seconds(pid: int | None = None) -> float:
    """CPU time (user + system, all threads) used so far by this process or by process ``pid``."""
    if pid is None:
        return time.process_time()
    with open(f"/proc/{pid}/stat") as f:  # fields 14 and 15 (utime, stime), after the "(comm)" field
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_round(session, peer, router, key: str, payloads, args: Args) -> dict:
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    pids = {"publisher": None, "router": router.pid, "subscriber": peer.pid}
    cpu_start = {name: cpu_seconds(pid) for name, pid in pids.items()}
    start = time.perf_counter()
    for i in range(args.messages):
        pub.put(payloads(i))
    publish_s = time.perf_counter() - start
    session.put(END, str(args.messages), congestion_control=zenoh.CongestionControl.BLOCK)
    stats = json.loads(wait_line(peer, 90))
    stats["cpu_us_per_msg"] = {
        name: (cpu_seconds(pid) - cpu_start[name]) / args.messages * 1e6 for name, pid in pids.items()
    }
    stats["cpu_us_per_msg"]["subscriber_callback"] = stats["handler_cpu_s"] / args.messages * 1e6
    pub.undeclare()
    span = max(stats["last"] - stats["first"], 1e-9)
    stats["msgs_per_s"] = (stats["count"] - 1) / span
    stats["bytes_per_s"] = stats["msgs_per_s"] * stats["bytes"] / max(stats["count"], 1)
    stats["transitions_per_s"] = stats["msgs_per_s"] * args.batch
    stats["lost"] = args.messages - stats["count"]
    stats["publish_s"] = publish_s
    return stats


def bench_end_to_end(args: Args, session, peer, router, rng: np.random.Generator) -> dict:
    batches = [make_batch(args.batch, args.obs_dim, rng, seq=i) for i in range(8)]
    size = len(encode(batches[0]))
    raw_payloads = [bytes(rng.integers(0, 256, size, dtype=np.uint8)) for _ in range(8)]
    rounds: dict[str, list[dict]] = {"raw": [], "ours": []}
    kinds = {
        "raw": lambda: run_round(session, peer, router, RAW, lambda i: raw_payloads[i % 8], args),
        "ours": lambda: run_round(session, peer, router, MSG, lambda i: encode(batches[i % 8]), args),
    }
    for r in range(args.rounds):  # interleaved, and each kind goes first in every other round
        for name in ("raw", "ours") if r % 2 == 0 else ("ours", "raw"):
            rounds[name].append(kinds[name]())
    out = {"message_bytes": size, "messages_per_round": args.messages}
    ratios = [o["msgs_per_s"] / r["msgs_per_s"] for r, o in zip(rounds["raw"], rounds["ours"], strict=True)]
    for name, results in rounds.items():
        results.sort(key=lambda r: r["msgs_per_s"])
        median = results[len(results) // 2]
        out[name] = {
            "msgs_per_s": median["msgs_per_s"],
            "bytes_per_s": median["bytes_per_s"],
            "lost": sum(r["lost"] for r in results),
            "rejected": sum(r["rejected"] for r in results),
            "rounds_msgs_per_s": [r["msgs_per_s"] for r in results],
            "cpu_us_per_msg": {
                proc: float(np.median([r["cpu_us_per_msg"][proc] for r in results]))
                for proc in ("publisher", "router", "subscriber", "subscriber_callback")
            },
        }
        if name == "ours":
            out[name]["transitions_per_s"] = median["transitions_per_s"]
        print(
            f"e2e   {name:5s} {size} B  {median['msgs_per_s']:9.0f} msgs/s  "
            f"{median['bytes_per_s'] / 1e9:6.2f} GB/s  lost {out[name]['lost']}  "
            f"(rounds: {', '.join(f'{r:.0f}' for r in out[name]['rounds_msgs_per_s'])})"
        )
        cpu = out[name]["cpu_us_per_msg"]
        print(
            f"      {name:5s} CPU per message: publisher {cpu['publisher']:.0f} us, router "
            f"{cpu['router']:.0f} us, subscriber {cpu['subscriber']:.0f} us of which its callback "
            f"(payload copy + decode) {cpu['subscriber_callback']:.0f} us (medians over rounds)"
        )
    out["ratio_vs_raw"] = out["ours"]["msgs_per_s"] / out["raw"]["msgs_per_s"]
    out["ratio_rounds"] = ratios  # ours/raw of each round's pair (same round, one after the other)
    print(
        f"e2e   ours/raw = {out['ratio_vs_raw']:.2f} (of the medians; each round's pair "
        f"{min(ratios):.2f}-{max(ratios):.2f}), {out['ours']['transitions_per_s'] / 1e6:.2f} M transitions/s"
    )
    return out


def bench_latency(args: Args, session, rng: np.random.Generator) -> dict:
    weights = make_weights(rng, args.obs_dim)
    wire = encode(weights)
    raw = b"R" + bytes(len(wire) - 1)
    replies: list[bytes] = []
    arrived = threading.Event()

    def on_reply(sample) -> None:
        replies.append(sample.payload.to_bytes())
        arrived.set()

    sub = session.declare_subscriber(ECHO_BACK, on_reply)
    pub = session.declare_publisher(ECHO, congestion_control=zenoh.CongestionControl.BLOCK)
    out = {"weights_bytes": len(wire), "parameters": int(sum(t.size for t in weights.tensors.values()))}
    for name, make, check in (
        ("raw", lambda: raw, lambda data: len(data) == len(raw)),
        ("ours", lambda: encode(weights), lambda data: decode(data, LIMITS).version == weights.version),
    ):
        times = []
        for i in range(args.pings + 20):
            arrived.clear()
            replies.clear()
            start = time.perf_counter()
            pub.put(make())
            if not arrived.wait(10):
                raise RuntimeError("weights echo timed out")
            ok = check(replies[0])
            if i >= 20:
                times.append(time.perf_counter() - start)
            assert ok
        p50, p99 = np.percentile(np.array(times) * 1e3, [50, 99])
        out[name] = {"p50_ms": float(p50), "p99_ms": float(p99)}
        print(f"rtt   {name:5s} {len(wire)} B  p50 {p50:6.3f} ms  p99 {p99:6.3f} ms")
    out["p50_ratio_vs_raw"] = out["ours"]["p50_ms"] / out["raw"]["p50_ms"]
    pub.undeclare()
    sub.undeclare()
    return out


def main(args: Args) -> dict:
    rng = np.random.default_rng(0)
    result: dict = {"bench": "wire", "config": args.__dict__}
    result["codec"] = bench_codec(args, make_batch(args.batch, args.obs_dim, rng))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cli = [sys.executable, "-m", "services.cli"]
    root = str(Path(__file__).resolve().parents[1])
    router = subprocess.Popen([*cli, "router", "--listen", endpoint], cwd=root, stdout=subprocess.DEVNULL)
    peer = None
    try:
        peer = subprocess.Popen(
            [sys.executable, "-m", "bench._wire_peer", endpoint],
            cwd=root,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        if wait_line(peer, 30).strip() != "ready":
            raise RuntimeError("bench peer did not start")
        with open_session(ZenohSettings(connect=[endpoint], connect_timeout=20)) as session:
            time.sleep(0.5)  # let the peer's subscriptions reach us through the router
            result["end_to_end"] = bench_end_to_end(args, session, peer, router, rng)
            result["latency"] = bench_latency(args, session, rng)
    finally:
        for proc in (peer, router):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
    e2e = result["end_to_end"]
    result["targets"] = {
        "ratio_vs_raw_ge_0.8": e2e["ratio_vs_raw"] >= 0.8,
        "transitions_per_s_ge_5M": e2e["ours"]["transitions_per_s"] >= 5e6,
        "zero_lost": e2e["ours"]["lost"] == 0 and e2e["raw"]["lost"] == 0 and e2e["ours"]["rejected"] == 0,
    }
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    for name, value in Args().__dict__.items():
        parser.add_argument(f"--{name.replace('_', '-')}", type=type(value), default=value)
    print(json.dumps(main(Args(**vars(parser.parse_args())))))
