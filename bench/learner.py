"""Learner and actor costs: the update step against bare PyTorch, the services' overheads, weight latency.

(u) Update step, one process, interleaved windows, per CPU-second: a bare-PyTorch double-DQN
    update written plainly here (tensors indexed directly, nn.Sequential, Adam, Polyak) against
    ``NNQLLearner.update(n)`` (TorchRL sampler and storage, the lean hot loop of
    agents/nnql/lean.py) and against the TorchRL path as it ran before that loop existed
    (``train_step(replay.sample())``: DQNLoss + SoftUpdate on TensorDicts, per-tensor Adam).
    Same 128x128 MLP, batch 256, replay of 20,000 random transitions. Target: >= 0.9 of bare.
(a) Learner service: updates/s of a `navlearn learner` subprocess (router, Zenoh ingest,
    decoding, replay inserts, acknowledgements, status, weight broadcasts all running), kept
    saturated by a feeder process that replays pre-built TransitionBatches under the
    acknowledgement window, against ``NNQLLearner.update`` in this process (same network and
    batch size), measured before and after. Target: <= 10% overhead.
(b) Actor: robot-steps/s of the actor service (services.actor.Actor: vector env, NNQL Boltzmann
    policy, batching, encoding, publishing, acknowledgement window) towards a sink that
    acknowledges every batch, against the same env and policy stepped without any publishing,
    before and after. Target: <= 15% overhead.
(c) Weight broadcast to 4 receiver processes (services.common.weights.WeightsReceiver + the
    actor's NNQLPolicy.set_weights): p50/p99 from publish to applied.

    python -m bench.learner                  # human lines, then one JSON object on the last line
    python -m bench.learner --only update    # (u) alone
"""

from __future__ import annotations

import argparse
import copy
import cProfile
import json
import pstats
import signal
import threading
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from bench._common import (
    N_ACTIONS,
    OBS_DIM,
    Rate,
    free_port,
    machine_load,
    median_rate,
    overheads,
    process_cpu,
    random_transitions,
    spawn,
    stop,
    timed,
    wait_ready,
)
from bench._common import settings as zenoh_settings
from services.common.transport import open_session
from services.ops.status import query_status

RUN = "bench"
ROLES = "bench._learner_roles"


@dataclass
class Args:
    rounds: int = 3
    """Measurement windows of each kind, interleaved with the baseline's; medians are reported."""
    step_seconds: float = 4.0
    """Length of each update-step window (u)."""
    many: int = 16
    """Updates per ``update(n)`` call in the several-per-call window (u)."""
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


def settings(endpoint: str, mode: str = "client"):
    return zenoh_settings(endpoint, RUN, mode)


# ---------------------------------------------------------------- (u) update step


class BareDQN:
    """Double DQN in plain PyTorch, as one would write it without a library: the comparison."""

    def __init__(self, data: dict[str, np.ndarray], config: NNQLConfig):
        torch.manual_seed(config.seed)
        hidden = config.hidden_sizes
        self.net = nn.Sequential(
            nn.Linear(OBS_DIM, hidden[0]), nn.ReLU(),
            nn.Linear(hidden[0], hidden[1]), nn.ReLU(),
            nn.Linear(hidden[1], N_ACTIONS),
        )  # fmt: skip
        self.target = copy.deepcopy(self.net)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=config.lr)
        self.config = config
        self.obs = torch.as_tensor(data["obs"])
        self.action = torch.as_tensor(data["action"])
        self.reward = torch.as_tensor(data["reward"])
        self.next_obs = torch.as_tensor(data["next_obs"])
        self.terminated = torch.as_tensor(data["terminated"])
        self.generator = torch.Generator().manual_seed(config.seed)

    def step(self) -> None:
        cfg = self.config
        i = torch.randint(0, len(self.obs), (cfg.batch_size,), generator=self.generator)
        obs, action, reward, next_obs = self.obs[i], self.action[i], self.reward[i], self.next_obs[i]
        with torch.no_grad():
            next_action = self.net(next_obs).argmax(1, keepdim=True)
            next_value = self.target(next_obs).gather(1, next_action).squeeze(1)
            target = reward + cfg.gamma * (~self.terminated[i]).float() * next_value
        q = self.net(obs).gather(1, action.unsqueeze(1)).squeeze(1)
        loss = F.smooth_l1_loss(q, target)
        self.optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.net.parameters(), cfg.grad_clip)
        self.optimizer.step()
        with torch.no_grad():
            for p, tp in zip(self.net.parameters(), self.target.parameters(), strict=True):
                tp.lerp_(p, cfg.target_tau)


def filled_learner(data: dict[str, np.ndarray], config: NNQLConfig) -> NNQLLearner:
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    learner.add(data)
    learner.update(30)
    return learner


def bench_update_step(args: Args) -> dict:
    """Interleaved windows of the bare loop, the learner's update(1) and update(many), and the
    TorchRL path as it was (train_step on replay.sample(), Adam's per-tensor loop)."""
    config = NNQLConfig(torch_threads=1)
    data = random_transitions(20_000, np.random.default_rng(0))
    bare = BareDQN(data, config)
    after = filled_learner(data, config)
    before = filled_learner(data, config)
    before.optimizer = torch.optim.Adam(before.loss.parameters(), lr=config.lr)  # as it was
    loops = {
        "bare": (bare.step, 1),
        "update_1": (after.update, 1),
        f"update_{args.many}": (lambda: after.update(args.many), args.many),
        "before": (lambda: before.train_step(before.replay.sample()), 1),
    }
    for step, _ in loops.values():
        step()  # warm up
    rates: dict[str, list[Rate]] = {name: [] for name in loops}
    for _ in range(args.rounds):
        for name, (step, per_call) in loops.items():
            rates[name].append(timed(step, args.step_seconds, per_call))
    result = {name: median_rate(r) for name, r in rates.items()}
    result["ratio_to_bare"] = {
        name: [round(r.per_cpu_s / b.per_cpu_s, 3) for r, b in zip(rs, rates["bare"], strict=True)]
        for name, rs in rates.items()
        if name != "bare"
    }
    ratio = {name: float(np.median(v)) for name, v in result["ratio_to_bare"].items()}
    result["target_met"] = ratio["update_1"] >= 0.9
    result["profile_before"] = profile_before(before)
    print(
        f"(u) update step per CPU-second: bare PyTorch {result['bare']['per_cpu_s']:.0f}, "
        f"NNQLLearner.update() {result['update_1']['per_cpu_s']:.0f} ({ratio['update_1']:.2f} of bare), "
        f"update({args.many}) {result[f'update_{args.many}']['per_cpu_s']:.0f} "
        f"({ratio[f'update_{args.many}']:.2f}), TorchRL path before {result['before']['per_cpu_s']:.0f} "
        f"({ratio['before']:.2f}); target >= 0.9 of bare"
    )
    return result


PROFILE_PARTS = {
    "loss forward": ("objectives/dqn.py", "forward"),
    "  of which linear layers": ("~", "<built-in method torch._C._nn.linear>"),
    "backward": ("torch/_tensor.py", "backward"),
    "Adam step": ("torch/optim/optimizer.py", "wrapper"),
    "clip_grad_norm_": ("torch/nn/utils/clip_grad.py", "clip_grad_norm_"),
    "SoftUpdate.step": ("objectives/utils.py", "step"),
    "replay.sample": ("replay_buffers/tensordict.py", "sample"),
}


def profile_before(learner: NNQLLearner, updates: int = 300) -> dict[str, float]:
    """cProfile of the TorchRL path: each part's share of the update's time (cumulative)."""
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(updates):
        learner.train_step(learner.replay.sample())
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    total = sum(row[2] for row in stats.values())  # own time of every function
    shares = {}
    for part, (file, name) in PROFILE_PARTS.items():
        cumulative = sum(row[3] for (f, _, n), row in stats.items() if f.endswith(file) and n == name)
        shares[part] = round(cumulative / total, 3)
    print(
        "    TorchRL path, share of an update's CPU time (cProfile): "
        + ", ".join(f"{part.strip()} {100 * share:.0f}%" for part, share in shares.items())
    )
    return shares


# ---------------------------------------------------------------- (a) learner service


def baseline_window(learner: NNQLLearner, seconds: float) -> Rate:
    """The update step `train --local` times (NNQLLearner.update), for ``seconds``."""
    return timed(learner.update, seconds)


def bench_learner(args: Args) -> dict:
    """Baseline and service windows interleaved (the service paused with SIGSTOP meanwhile)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    local = filled_learner(random_transitions(20_000, np.random.default_rng(0)), NNQLConfig())
    baseline = [baseline_window(local, args.baseline_seconds)]
    learner = spawn(
        "-m", "services.cli", "learner", "--listen", endpoint, "--run", RUN, "--checkpoint-dir", ""
    )
    feeder = spawn("-m", ROLES, "feeder", "--endpoint", endpoint, "--batch", str(args.feeder_batch))
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
    from services.common.weights import WeightsBroadcaster

    receivers = [spawn("-m", ROLES, "receiver", "--endpoint", endpoint) for _ in range(args.receivers)]
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


def main(args: Args, only: str | None = None) -> dict:
    print(f"bench/learner.py {asdict(args)} load {machine_load()}")
    result = {"update_step": bench_update_step(args)}
    if only == "update":
        return result
    result["learner"] = bench_learner(args)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = spawn("-m", ROLES, "sink", "--endpoint", endpoint)
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
    parser.add_argument("--only", choices=("update",), help="run only the update-step comparison (u)")
    parser.add_argument(
        "--quick", action="store_true", help="short windows (a smoke run, not for RESULTS.md)"
    )
    parser.add_argument("--rounds", type=int, default=Args.rounds, help="interleaved rounds of each window")
    cli = parser.parse_args()
    quick = Args(rounds=1, step_seconds=1.5, measure_seconds=6, baseline_seconds=3, broadcasts=40)
    result = main(quick if cli.quick else Args(rounds=cli.rounds), cli.only)
    result["load_after"] = machine_load()
    print(json.dumps(result))
