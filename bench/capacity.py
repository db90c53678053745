"""Capacity model: how many actor hosts one learner host feeds, and what saturates first.

Measured here, each per CPU-second of the process doing the work (so the figure carries to a
machine whose cores are not shared, unlike wall-clock rates on this 2-core machine):

(a) actor: robot-steps per CPU-second of a real `navlearn actor` process (vector env, NNQL
    Boltzmann policy with the default 128x128 network's weights, batching, encoding, publishing,
    acknowledgement window) for several --envs, towards a sink that serves those weights and
    acknowledges every batch at once; the actor's own counter (status/actor:<id>) over its CPU
    time from /proc;
(b) wire: bytes per transition of the TransitionBatch an actor sends (16 steps x --envs rows);
(c) learner: NNQLLearner updates per CPU-second (default NNQLConfig: 128x128, batch 256, one
    torch thread, full replay) and ingest per CPU-second (decode + checks + replay insert of
    the actor's batches), both in this process, as the learner's main thread does them; and the
    write-ahead log's transitions/s (wall clock: the disk) with one fsync per batch, the
    service's default --wal-fsync always when each pass holds one batch;
(d) router: TransitionBatch messages through `navlearn router` processes on loopback, one
    router (TCP), and two routers linked router-to-router over mutual TLS (the multi-host
    path of tests/test_multihost_routers.py): a publisher as fast as BLOCK allows, a
    subscriber counting; router CPU per message. Zenoh's shared memory (on by default) is
    turned off there, as between hosts; one router with it on is shown for comparison.

Model (one learner main thread does updates, ingest and the log in turn): at update-to-data
ratio r a transition costs the learner r/u + 1/i + 1/w seconds (u updates and i transitions
decoded and inserted per CPU-second, w transitions/s through the write-ahead log), so one
learner host consumes D(r) = 1 / (r/u + 1/i + 1/w) transitions/s, fed by
D(r) / (a * cores) actor hosts. The network carries D(r) * b bytes/s; a router core forwards
rows/m transitions/s (m router CPU-seconds per message); one actor host of C cores makes
a * C. Each limit is reported as the transitions/s it allows; the smallest saturates first, and
r / (1/(a*C) - 1/i - 1/w) is the update rate a learner needs to take one actor host's output.
--learner-updates-per-s projects a faster learner (a GPU, or a later learner) without
re-measuring the rest.

    python -m bench.capacity                      # human lines, then one JSON object
    python -m bench.capacity --envs 64 --actor-host-cores 32 --utd 0.0625 0.25 1
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.transitions import transitions_to_tensordict
from bench._capacity_roles import RUN, actor_batch
from bench._common import N_ACTIONS, OBS_DIM, free_port, process_cpu, settings, spawn, stop, wait_ready
from protocols.codec import decode, encode
from protocols.limits import Limits
from services.actor.status import query_actor_statuses
from services.common.transport import open_session
from services.learner.durable import DurableIngest

ROLES = "bench._capacity_roles"
BATCH_STEPS = 16  # the actor's default --batch-steps
CLI = ["-m", "services.cli"]
READY_TIMEOUT = 180  # s: a helper's first start may compile


# ---------------------------------------------------------------- (a) actor, (b) bytes


def bench_actor(envs: int, seconds: float, logs: Path) -> dict:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = spawn("-m", ROLES, "sink", "--endpoint", endpoint)
    actor = None
    try:
        wait_ready(sink, READY_TIMEOUT)
        with open(logs / f"actor-{envs}.log", "w") as log:
            argv = ["--connect", endpoint, "--run", RUN, "--id", "a1", "--envs", str(envs), "--seed", "1"]
            actor = spawn(*CLI, "actor", *argv, log=log)
        with open_session(settings(endpoint, RUN)) as session:

            def steps() -> tuple[int, int, float]:
                status = query_actor_statuses(session, RUN, timeout=5.0).get("a1")
                counters = status.counters if status else {}
                return (
                    counters.get("robot_steps", 0),
                    counters.get("weights_applied", 0),
                    process_cpu(actor.pid),
                )

            deadline = time.monotonic() + 240
            while steps()[1] < 1 and time.monotonic() < deadline:  # compiled, weights in, stepping
                time.sleep(1.0)
            time.sleep(2.0)
            s0, applied, c0 = steps()
            time.sleep(seconds)
            s1, _, c1 = steps()
    finally:
        if actor is not None:
            stop(actor)
        stop(sink)
    if applied < 1:
        raise RuntimeError(f"the actor never applied the sink's weights (see {logs}/actor-{envs}.log)")
    rows = BATCH_STEPS * envs
    size = len(encode(actor_batch(rows, np.random.default_rng(0))))
    return {
        "envs": envs,
        "robot_steps_per_cpu_s": round((s1 - s0) / (c1 - c0)),
        "cpu_share": round((c1 - c0) / seconds, 2),
        "batch_rows": rows,
        "batch_bytes": size,
        "bytes_per_transition": round(size / rows, 1),
    }


# ---------------------------------------------------------------- (c) learner


def bench_learner(envs: int, seconds: float, wal_dir: Path) -> dict:
    # torchrl was imported at its default INFO level (it reads RL_LOGGING_LEVEL then): quiet it here
    logging.getLogger("torchrl").setLevel(os.environ.get("RL_LOGGING_LEVEL", "WARNING"))
    warnings.filterwarnings("ignore", message="The given NumPy array is not writable")  # decoded views
    config = NNQLConfig()
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(1)
    rows = BATCH_STEPS * envs
    payloads = [encode(actor_batch(rows, rng)) for _ in range(16)]
    limits = Limits(n_actions=N_ACTIONS)

    def ingest_window() -> float:
        n, start = 0, time.process_time()
        while time.process_time() - start < seconds:
            for payload in payloads:
                n += learner.add(decode(payload, limits))
        return n / (time.process_time() - start)

    def update_window() -> float:
        n, start = 0, time.process_time()
        while time.process_time() - start < seconds:
            learner.update()
            n += 1
        return n / (time.process_time() - start)

    def wal_window() -> float:
        """Transitions/s through the write-ahead log with one fsync per batch (--wal-fsync always
        when each loop pass holds one batch; group commit shares an fsync between several)."""
        with tempfile.TemporaryDirectory(dir=wal_dir) as tmp:
            durable = DurableIngest(tmp, fsync="always", limits=limits)
            assert not list(durable.replay())  # opens the (empty) log for appending
            n, start, seq = 0, time.perf_counter(), 0
            while time.perf_counter() - start < seconds:
                for payload in payloads:
                    message = decode(payload, limits)
                    seq += 1
                    message.seq = seq
                    durable.admit(message, payload)
                    durable.sync()
                    n += len(message)
            rate = n / (time.perf_counter() - start)
            durable.close()
        return rate

    while len(learner.replay) < min(config.replay_capacity, 100_000):  # a replay as a run has it
        learner.add(decode(payloads[len(learner.replay) // rows % 16], limits))
    ingest, updates, wal = [], [], []
    for _ in range(3):  # interleaved windows; medians
        ingest.append(ingest_window())
        updates.append(update_window())
        wal.append(wal_window())
    return {
        "updates_per_cpu_s": round(float(np.median(updates)), 1),
        "updates_rounds": [round(u, 1) for u in updates],
        "ingest_transitions_per_cpu_s": round(float(np.median(ingest))),
        "ingest_rounds": [round(i) for i in ingest],
        "wal_fsync_always_transitions_per_s": round(float(np.median(wal))),
        "wal_rounds": [round(w) for w in wal],
        "replay_bytes_per_transition": round(
            transitions_to_tensordict(decode(payloads[0], limits), OBS_DIM).bytes() / rows, 1
        ),
        "batch_size": config.batch_size,
        "hidden_sizes": list(config.hidden_sizes),
        "torch_threads": torch.get_num_threads(),
    }


# ---------------------------------------------------------------- (d) router


NO_SHM = "{ transport: { shared_memory: { enabled: false } } }\n"
"""Zenoh config without shared memory: Zenoh otherwise moves messages over 3 kB between processes
of one host through shared memory (on by default), so loopback would not measure a network."""


def bench_router(rows: int, seconds: float, two: bool, shm: bool, workdir: Path) -> dict:
    """Messages of ``rows`` transitions through one router, or two linked by mutual TLS."""
    port_in, port_out = free_port(), free_port()
    routers: list[subprocess.Popen] = []
    config = workdir / "no-shm.json5"
    config.write_text(NO_SHM)
    base = [] if shm else ["--zenoh-config", str(config)]
    log = open(workdir / "routers.log", "a")  # noqa: SIM115 - closed below
    if two:
        tls = workdir / "tls"
        if not tls.exists():
            made = ["--out", str(tls), "--hosts", "127.0.0.1", "--clients", "router-a"]
            certs = [sys.executable, *CLI, "certs", *made]
            subprocess.run(certs, check=True, capture_output=True, timeout=120)
        link = f"tls/127.0.0.1:{free_port()}"
        ca = [*base, "--tls-root-ca", str(tls / "ca.pem"), "--tls-mtls"]
        b_side = ["--listen", link, "--listen", f"tcp/127.0.0.1:{port_out}", *ca]
        a_side = ["--connect", link, "--listen", f"tcp/127.0.0.1:{port_in}", *ca]
        b_pair = ["--tls-cert", str(tls / "server.pem"), "--tls-key", str(tls / "server.key")]
        a_pair = ["--tls-cert", str(tls / "router-a.pem"), "--tls-key", str(tls / "router-a.key")]
        routers.append(spawn(*CLI, "router", *b_side, *b_pair, log=log))
        routers.append(spawn(*CLI, "router", *a_side, *a_pair, log=log))
    else:
        port_out = port_in
        routers.append(spawn(*CLI, "router", *base, "--listen", f"tcp/127.0.0.1:{port_in}", log=log))
    helper = ["--rows", str(rows), *base, "--endpoint"]
    subscriber = spawn("-m", ROLES, "subscriber", *helper, f"tcp/127.0.0.1:{port_out}")
    publisher = spawn("-m", ROLES, "publisher", *helper, f"tcp/127.0.0.1:{port_in}")
    try:
        wait_ready(subscriber, READY_TIMEOUT)
        wait_ready(publisher, READY_TIMEOUT)
        time.sleep(1.0)

        def snapshot() -> tuple[float, int, int, list[float]]:
            subscriber.send_signal(signal.SIGUSR1)
            messages, size = json.loads(subscriber.stdout.readline())
            return time.perf_counter(), messages, size, [process_cpu(r.pid) for r in routers]

        t0, m0, b0, c0 = snapshot()
        time.sleep(seconds)
        t1, m1, b1, c1 = snapshot()
    finally:
        for process in (publisher, subscriber, *routers):
            stop(process)
        log.close()
    messages = m1 - m0
    cpu = [b - a for a, b in zip(c0, c1, strict=True)]
    return {
        "routers": len(routers),
        "link": ("two routers, mutual TLS between them" if two else "one router, TCP")
        + ("" if shm else ", no shared memory"),
        "shared_memory": shm,
        "rows": rows,
        "messages_per_s": round(messages / (t1 - t0)),
        "transitions_per_s": round(messages * rows / (t1 - t0)),
        "mb_per_s": round((b1 - b0) / (t1 - t0) / 1e6, 1),
        "router_cpu_us_per_message": [round(1e6 * c / max(messages, 1), 1) for c in cpu],
        "router_transitions_per_cpu_s": round(rows * messages / max(max(cpu), 1e-9)),
    }


# ---------------------------------------------------------------- model


def model(inputs: dict, utds: list[float], actor_host_cores: int, nic_gbps: float) -> list[dict]:
    """One row per update-to-data ratio: the transitions/s each part allows, and who binds."""
    a, b = inputs["actor_robot_steps_per_cpu_s"], inputs["bytes_per_transition"]
    u, i = inputs["learner_updates_per_s"], inputs["learner_ingest_per_cpu_s"]
    w = inputs["wal_fsync_always_transitions_per_s"]
    nic = nic_gbps * 1e9 / 8 / b
    rows = []

    def updates_for(rate: float) -> int | None:
        """Updates/s the learner needs to take ``rate`` transitions/s at ratio r (None: ingest
        and the log alone stop it below that rate, however fast its updates)."""
        left = 1.0 / rate - 1.0 / i - 1.0 / w
        return round(r / left) if left > 0 else None

    for r in utds:
        seconds = {"updates": r / u, "decode and insert": 1.0 / i, "write-ahead log": 1.0 / w}
        learner = 1.0 / sum(seconds.values())  # the learner's main thread does all three in turn
        limits = {
            "learner": learner,
            f"one actor host ({actor_host_cores} cores)": a * actor_host_cores,
            "one router core": inputs["router_transitions_per_cpu_s"],
            f"{nic_gbps:g} Gb/s link": nic,
        }
        rows.append({
            "utd_ratio": r,
            "new_transitions_per_update": round(1 / r, 2),
            "replay_samples_per_transition": round(r * inputs["batch_size"], 2),
            "learner_transitions_per_s": round(learner),
            "learner_bound_by": max(seconds, key=seconds.get),
            "learner_time_shares": {k: round(v / sum(seconds.values()), 4) for k, v in seconds.items()},
            "actor_cores_fed": round(learner / a, 4),
            "actor_hosts_fed": round(learner / (a * actor_host_cores), 5),
            "wire_mb_per_s": round(learner * b / 1e6, 3),
            "updates_per_s_to_take_one_actor_core": updates_for(a),
            "updates_per_s_to_take_one_actor_host": updates_for(a * actor_host_cores),
            "learner_ceiling_transitions_per_s": round(1.0 / (1.0 / i + 1.0 / w)),
            "limits_transitions_per_s": {k: round(v) for k, v in limits.items()},
            "saturates_first": min(limits, key=limits.get),
        })  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", type=int, nargs="+", default=[8, 64], help="actor --envs to measure")
    parser.add_argument("--seconds", type=float, default=8.0, help="length of each measurement window")
    parser.add_argument(
        "--utd", type=float, nargs="+", default=[0.0005, 0.0625, 0.25, 1.0], help="UTD ratios"
    )
    parser.add_argument("--actor-host-cores", type=int, default=16, help="cores of one actor host")
    parser.add_argument("--nic-gbps", type=float, default=1.0, help="network link between hosts, Gb/s")
    parser.add_argument("--wal-dir", default="runs", help="where the write-ahead log is timed (a disk)")
    parser.add_argument(
        "--learner-updates-per-s",
        type=float,
        default=0.0,
        help="project a learner doing this many updates/s (0: the measured CPU figure)",
    )
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        actors = []
        for envs in args.envs:
            actors.append(bench_actor(envs, args.seconds, workdir))
            a = actors[-1]
            print(
                f"(a) actor --envs {envs}: {a['robot_steps_per_cpu_s']:,} robot-steps per CPU-second; "
                f"(b) {a['bytes_per_transition']} B per transition in batches of {a['batch_rows']}",
                flush=True,
            )
        best = max(actors, key=lambda x: x["robot_steps_per_cpu_s"])
        wal_dir = Path(args.wal_dir)
        wal_dir.mkdir(parents=True, exist_ok=True)
        learner = bench_learner(best["envs"], args.seconds / 2, wal_dir)
        print(
            f"(c) learner: {learner['updates_per_cpu_s']} updates per CPU-second, ingest "
            f"{learner['ingest_transitions_per_cpu_s']:,} transitions per CPU-second, write-ahead log "
            f"with an fsync per batch {learner['wal_fsync_always_transitions_per_s']:,} transitions/s",
            flush=True,
        )
        routers = [
            bench_router(best["batch_rows"], args.seconds, two, shm, workdir)
            for two, shm in ((False, True), (False, False), (True, False))
        ]
        for r in routers:
            print(
                f"(d) {r['link']}: {r['messages_per_s']:,} msgs/s = {r['transitions_per_s']:,} "
                f"transitions/s, {r['mb_per_s']} MB/s; router CPU per message "
                f"{r['router_cpu_us_per_message']} us",
                flush=True,
            )
    inputs = {
        "actor_envs": best["envs"],
        "actor_robot_steps_per_cpu_s": best["robot_steps_per_cpu_s"],
        "bytes_per_transition": best["bytes_per_transition"],
        "learner_updates_per_s": args.learner_updates_per_s or learner["updates_per_cpu_s"],
        "learner_updates_measured": not args.learner_updates_per_s,
        "learner_ingest_per_cpu_s": learner["ingest_transitions_per_cpu_s"],
        "batch_size": learner["batch_size"],
        "router_transitions_per_cpu_s": min(
            r["router_transitions_per_cpu_s"] for r in routers if not r["shared_memory"]
        ),
        "replay_bytes_per_transition": learner["replay_bytes_per_transition"],
        "wal_fsync_always_transitions_per_s": learner["wal_fsync_always_transitions_per_s"],
    }
    rows = model(inputs, args.utd, args.actor_host_cores, args.nic_gbps)
    for row in rows:
        print(
            f"UTD {row['utd_ratio']:g}: the learner takes {row['learner_transitions_per_s']:,} "
            f"transitions/s ({row['learner_bound_by']}-bound) = {row['actor_cores_fed']} actor cores = "
            f"{row['actor_hosts_fed']} hosts of {args.actor_host_cores} cores, {row['wire_mb_per_s']} MB/s;"
            f" saturates first: {row['saturates_first']}; to take one actor core it needs "
            + (
                f"{row['updates_per_s_to_take_one_actor_core']:,} updates/s"
                if row["updates_per_s_to_take_one_actor_core"]
                else f"more than faster updates (ingest and the log stop it at "
                f"{row['learner_ceiling_transitions_per_s']:,} transitions/s)"
            )
        )
    print(json.dumps({
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_before": round(load_before, 2),
        "load_after": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(), "actors": actors,
        "learner": learner, "routers": routers, "inputs": inputs, "actor_host_cores": args.actor_host_cores,
        "nic_gbps": args.nic_gbps, "model": rows,
    }))  # fmt: skip


if __name__ == "__main__":
    main()
