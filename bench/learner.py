"""Distributed-NNQL overheads: learner updates/s, actor robot-steps/s, weight broadcast latency.

(a) Learner: updates/s of a `navlearn learner` subprocess (router, Zenoh ingest, decoding,
    replay inserts, acknowledgements, status, weight broadcasts all running), kept saturated
    by a feeder process that replays pre-built TransitionBatches under the acknowledgement
    window, against the update step `train --local` times (NNQLLearner.update on a full
    replay), same network and batch size, measured in this process before and after.
    Target: <= 10% overhead.
(b) Actor: robot-steps/s of the actor service (services.actor.actor.Actor: vector env, NNQL
    Boltzmann policy, batching, encoding, publishing, acknowledgement window) towards a sink
    that acknowledges every batch, against the same env and policy stepped without any
    publishing, before and after. Target: <= 15% overhead.
(c) Weight broadcast to 4 receiver processes (services.common.weights.WeightsReceiver + the actor's
    NNQLPolicy.set_weights): p50/p99 from publish to applied.

    python bench/learner.py         # human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import TransitionBatch
from services.common.outbox import Outbox
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status

RUN = "bench"
OBS_DIM, N_ACTIONS = 11, 5


@dataclass
class Args:
    rounds: int = 3
    """Measurement windows of each kind, interleaved with the baseline's; medians are reported."""
    measure_seconds: float = 15.0
    """Length of each learner-service window."""
    baseline_seconds: float = 6.0
    """Length of each baseline window and of each actor window (short: the paused learner's Zenoh
    links must not reach their 10 s lease)."""
    feeder_batch: int = 256
    """Transitions per batch the feeder sends to the learner."""
    actor_envs: int = 8
    """Robots in the benchmarked actor (the service default)."""
    receivers: int = 4
    """Weight receiver processes."""
    broadcasts: int = 200
    """Weight versions published for the latency figure (after 20 warm-up ones)."""
    broadcast_interval: float = 0.05
    """Seconds between two published versions."""


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def settings(endpoint: str, mode: str = "client") -> ZenohSettings:
    if mode == "router":
        return ZenohSettings(mode="router", listen=[endpoint], run=RUN)
    return ZenohSettings(mode="client", connect=[endpoint], run=RUN, connect_timeout=120)


def spawn(*argv: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    return subprocess.Popen(
        [sys.executable, *argv], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )


def stop(process: subprocess.Popen, timeout: float = 60) -> str:
    process.send_signal(signal.SIGTERM)
    try:
        out, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out or ""


def random_transitions(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        "obs": rng.random((n, OBS_DIM), dtype=np.float32),
        "action": rng.integers(0, N_ACTIONS, n),
        "reward": rng.normal(size=n).astype(np.float32),
        "next_obs": rng.random((n, OBS_DIM), dtype=np.float32),
        "terminated": rng.random(n) < 0.02,
        "truncated": np.zeros(n, bool),
    }


# ---------------------------------------------------------------- helper processes


def feeder_main(endpoint: str, batch: int) -> None:
    """Sends pre-encoded TransitionBatches as fast as the learner acknowledges them."""
    rng = np.random.default_rng(1)
    session = open_session(settings(endpoint))
    publisher = session.declare_publisher(keys.transitions(RUN, "feeder"))
    outbox = Outbox(publisher.put, lambda: publisher.matching_status.matching, capacity=8, window=4)
    session.declare_subscriber(
        keys.acks(RUN, "feeder"), lambda s: outbox.on_ack(decode(s.payload.to_bytes()).accepted_seq)
    )
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    payloads = []
    for _ in range(16):
        fields = random_transitions(batch, rng)
        message = TransitionBatch(
            sender="feeder",
            seq=0,
            actor="feeder",
            model="nnql",
            policy_version=0,
            env_ids=np.zeros(batch, np.int32),
            **fields,
        )
        payloads.append(message)
    seq = 0
    while not done.is_set():
        seq += 1
        message = payloads[seq % len(payloads)]
        message.seq = seq
        outbox.put(seq, encode(message))
        outbox.flush(done)
    session.close()


def sink_main(endpoint: str) -> None:
    """A router that acknowledges every transition batch at once (the actor's ideal learner)."""
    session = open_session(settings(endpoint, "router"))
    count = [0]

    def on_batch(sample) -> None:
        batch = decode(sample.payload.to_bytes())
        count[0] += len(batch)
        ack = Ack(sender="sink", seq=batch.seq, actor=batch.actor, accepted_seq=batch.seq, policy_version=0)
        session.put(keys.acks(RUN, batch.actor), encode(ack))

    session.declare_subscriber(keys.everything(RUN, "transitions"), on_batch)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    print("ready", flush=True)
    done.wait()
    print(json.dumps({"transitions": count[0]}), flush=True)
    session.close()


def receiver_main(endpoint: str) -> None:
    """Applies weights as they arrive (as an actor does) and prints version and applied time."""
    from agents.nnql.policy import NNQLPolicy
    from services.common.weights import WeightsReceiver, split_architecture

    session = open_session(settings(endpoint))
    receiver = WeightsReceiver(session, RUN, "nnql")
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    policy = None
    print("ready", flush=True)
    lines = []
    while not done.is_set():
        received = receiver.take()
        if received is None:
            time.sleep(0.0005)
            continue
        message = received.message
        network, _ = split_architecture(message.architecture)
        if policy is None:
            policy = NNQLPolicy(message.tensors, network, version=message.version)
        else:
            policy.set_weights(message.tensors, message.version)
        lines.append(f"{message.version} {time.time():.6f}")
    print("\n".join(lines), flush=True)
    session.close()


def wait_ready(process: subprocess.Popen, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.stdout.readline().strip() == "ready":
            return
    raise RuntimeError("helper process did not start")


# ---------------------------------------------------------------- (a) learner


@dataclass
class Rate:
    """Work done over a window: per wall-clock second and per CPU second of the process doing it."""

    count: float
    wall: float
    cpu: float

    @property
    def per_s(self) -> float:
        return self.count / self.wall

    @property
    def per_cpu_s(self) -> float:
        return self.count / self.cpu


def process_cpu(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def median_rate(rates: list[Rate]) -> dict:
    return {
        "per_s": round(float(np.median([r.per_s for r in rates])), 2),
        "per_cpu_s": round(float(np.median([r.per_cpu_s for r in rates])), 2),
        "windows": len(rates),
    }


def overheads(service: dict, baseline: dict) -> dict:
    return {
        "wall": round(1 - service["per_s"] / baseline["per_s"], 4),
        "cpu": round(1 - service["per_cpu_s"] / baseline["per_cpu_s"], 4),
    }


def make_baseline_learner():
    """The learner `train --local` updates, default config, replay filled with random transitions."""
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner

    learner = NNQLLearner(NNQLConfig(), OBS_DIM, N_ACTIONS)
    learner.add(random_transitions(20_000, np.random.default_rng(0)))
    for _ in range(30):
        learner.update()
    return learner


def baseline_window(learner, seconds: float) -> Rate:
    """The update step `train --local` times (NNQLLearner.update), for ``seconds``."""
    count, wall, cpu = 0, time.perf_counter(), time.process_time()
    while time.perf_counter() - wall < seconds:
        learner.update()
        count += 1
    return Rate(count, time.perf_counter() - wall, time.process_time() - cpu)


def bench_learner(args: Args) -> dict:
    """Baseline and service windows interleaved (the service paused with SIGSTOP meanwhile)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    local = make_baseline_learner()
    baseline = [baseline_window(local, args.baseline_seconds)]
    learner = spawn(
        "-m", "services.cli", "learner", "--listen", endpoint, "--run", RUN, "--checkpoint-dir", ""
    )
    feeder = spawn(__file__, "--role", "feeder", "--endpoint", endpoint, "--batch", str(args.feeder_batch))
    session = open_session(settings(endpoint))
    service, transitions = [], []
    try:

        def snapshot() -> tuple[float, float, int, int]:
            while (status := query_status(session, RUN, timeout=2.0)) is None:
                time.sleep(0.5)
            received = status.counters.get("transitions_received", 0)
            return time.monotonic(), process_cpu(learner.pid), status.versions["nnql"], received

        while snapshot()[2] < 200:  # past learning_starts and warmed up
            time.sleep(1.0)
        for _ in range(args.rounds):
            t0, c0, v0, n0 = snapshot()
            time.sleep(args.measure_seconds)
            t1, c1, v1, n1 = snapshot()
            service.append(Rate(v1 - v0, t1 - t0, c1 - c0))
            transitions.append((n1 - n0) / (t1 - t0))
            for process in (learner, feeder):  # paused: the baseline gets the machine to itself
                process.send_signal(signal.SIGSTOP)
            baseline.append(baseline_window(local, args.baseline_seconds))
            for process in (learner, feeder):
                process.send_signal(signal.SIGCONT)
            time.sleep(2.0)  # let the pipeline refill before the next window
    finally:
        session.close()
        stop(feeder)
        stop(learner)
    result = {"service": median_rate(service), "baseline": median_rate(baseline)}
    result["transitions_per_s"] = round(float(np.median(transitions)), 1)
    result["overhead"] = overheads(result["service"], result["baseline"])
    result["target_met"] = result["overhead"]["cpu"] <= 0.10
    ours, base, extra = result["service"], result["baseline"], result["overhead"]
    print(
        f"(a) learner service {ours['per_s']:.1f} updates/s ({ours['per_cpu_s']:.1f} per CPU s, "
        f"{result['transitions_per_s']:.0f} transitions/s ingested) vs update step {base['per_s']:.1f} "
        f"({base['per_cpu_s']:.1f} per CPU s): overhead {100 * extra['wall']:.1f}% wall, "
        f"{100 * extra['cpu']:.1f}% CPU (target <= 10%)"
    )
    return result


# ---------------------------------------------------------------- (b) actor and (c) weights


def bench_actor(args: Args, endpoint: str) -> dict:
    """Plain stepping and the actor service in alternating windows, same env and policy."""
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner
    from agents.nnql.rollout import VectorRollout
    from protocols.limits import Limits
    from services.actor.actor import Actor, ActorConfig
    from worlds.vector_env import NavigationVectorEnv

    nnql = NNQLConfig()
    policy = NNQLLearner(nnql, OBS_DIM, N_ACTIONS).policy(seed=0)
    policy.explore_as(nnql, 0)
    env = NavigationVectorEnv(args.actor_envs, maps="mixed:16", seed=0)
    plain = VectorRollout(env, policy)
    plain.reset(seed=0)
    session = open_session(settings(endpoint))
    actor = Actor(
        ActorConfig(id="bench-actor", envs=args.actor_envs), env, session, RUN, 0, Limits(n_actions=N_ACTIONS)
    )
    actor.policy = policy
    actor.rollout.reset(seed=0)
    while not actor.publisher.matching_status.matching:
        time.sleep(0.1)
    done = threading.Event()
    for _ in range(100):  # warm up both paths (numba, encoder buffers)
        plain.step()
    actor.tick(done)

    def window(step, steps_of) -> Rate:
        first, wall, cpu = steps_of(), time.perf_counter(), time.process_time()
        while time.perf_counter() - wall < args.baseline_seconds:
            step()
        return Rate(steps_of() - first, time.perf_counter() - wall, time.process_time() - cpu)

    baseline, service = [], []
    for _ in range(args.rounds + 1):
        baseline.append(window(plain.step, lambda: plain.steps))
        service.append(window(lambda: actor.tick(done), lambda: actor.rollout.steps))
    sent = actor.outbox.sent
    actor.close()
    session.close()
    result = {"service": median_rate(service), "baseline": median_rate(baseline), "batches_sent": sent}
    result["overhead"] = overheads(result["service"], result["baseline"])
    result["target_met"] = result["overhead"]["cpu"] <= 0.15
    print(
        f"(b) actor {result['service']['per_s']:.0f} robot-steps/s publishing ({sent} batches) vs "
        f"{result['baseline']['per_s']:.0f} without: overhead {100 * result['overhead']['wall']:.1f}% wall, "
        f"{100 * result['overhead']['cpu']:.1f}% CPU (target <= 15%)"
    )
    return result


def bench_broadcast(args: Args, endpoint: str) -> dict:
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner
    from services.common.weights import WeightsBroadcaster

    receivers = [spawn(__file__, "--role", "receiver", "--endpoint", endpoint) for _ in range(args.receivers)]
    session = open_session(settings(endpoint))
    try:
        for receiver in receivers:
            wait_ready(receiver)
        learner = NNQLLearner(NNQLConfig(), OBS_DIM, N_ACTIONS)
        weights, architecture = learner.get_weights(), learner.architecture
        broadcaster = WeightsBroadcaster(session, RUN, "nnql", "bench")
        time.sleep(1.0)
        published = {}
        for version in range(1, args.broadcasts + 21):
            published[version] = time.time()
            size = broadcaster.publish(weights, version, architecture)
            time.sleep(args.broadcast_interval)
        time.sleep(1.0)
        broadcaster.close()
    finally:
        session.close()
        outputs = [stop(r) for r in receivers]
    latencies, applied = [], 0
    for out in outputs:
        for line in out.splitlines():
            version, at = line.split()
            applied += 1
            if int(version) > 20:
                latencies.append(float(at) - published[int(version)])
    ms = 1000 * np.array(latencies)
    expected = args.receivers * args.broadcasts
    p50, p99 = np.percentile(ms, 50), np.percentile(ms, 99)
    print(
        f"(c) weights ({size / 1024:.0f} KiB) to {args.receivers} receivers: p50 {p50:.2f} ms, "
        f"p99 {p99:.2f} ms, {len(ms)}/{expected} applied"
    )
    return {
        "message_bytes": size,
        "receivers": args.receivers,
        "applied": len(ms),
        "expected": expected,
        "p50_ms": round(float(p50), 3),
        "p99_ms": round(float(p99), 3),
        "max_ms": round(float(ms.max()), 3),
    }


def main(args: Args) -> dict:
    print(f"bench/learner.py {asdict(args)}")
    result = {"learner": bench_learner(args)}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = spawn(__file__, "--role", "sink", "--endpoint", endpoint)
    try:
        wait_ready(sink)
        result["actor"] = bench_actor(args, endpoint)
        result["broadcast"] = bench_broadcast(args, endpoint)
    finally:
        stop(sink)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--role", choices=("feeder", "sink", "receiver"), help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    parser.add_argument("--batch", type=int, default=256, help=argparse.SUPPRESS)
    parser.add_argument(
        "--quick", action="store_true", help="short windows (a smoke run, not for RESULTS.md)"
    )
    cli = parser.parse_args()
    if cli.role == "feeder":
        feeder_main(cli.endpoint, cli.batch)
    elif cli.role == "sink":
        sink_main(cli.endpoint)
    elif cli.role == "receiver":
        receiver_main(cli.endpoint)
    else:
        bench_args = (
            Args(rounds=1, measure_seconds=6, baseline_seconds=3, broadcasts=40) if cli.quick else Args()
        )
        print(json.dumps(main(bench_args)))
