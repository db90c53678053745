"""`navlearn demonstrator`: DemoBatch building, the terminal frame, and human teleoperation as a
real process driven through a pseudo-terminal, publishing to a Zenoh subscriber. The astar and
file sources run against a real learner in tests/test_nirl_services.py."""

from __future__ import annotations

import fcntl
import os
import queue
import select
import signal
import struct
import subprocess
import sys
import termios
import time

import numpy as np
import pytest
from conftest import free_port

from protocols import keys
from protocols.codec import decode, encode
from protocols.messages import DemoBatch
from services.demonstrator.demonstrator import demo_batch
from services.demonstrator.teleop import heading_glyph, render_frame
from services.ops.status import query_status

CORRIDOR = """\
##########
#S......G#
#........#
##########
"""
ARROWS = {0: b"q", 1: b"\x1bOD", 2: b"\x1bOA", 3: b"\x1bOC", 4: b"e"}
"""key bytes per action: xterm's arrow keys in the application mode curses switches on (smkx)"""


def expert_demos(maps: str, n: int, seed: int = 0, noise: float = 0.0):
    from agents.planning.demonstrate import generate_demos
    from worlds.config import NavConfig

    demos, _ = generate_demos(maps, n, seed=seed, noise=noise, config=NavConfig())
    return demos


def test_demo_batch_round_trips_through_the_codec():
    demos = expert_demos("rooms:10", 2)
    batch = demo_batch(demos, "astar", sender="test", seq=3)
    assert batch.quality == "optimal"
    decoded = decode(encode(batch))
    assert isinstance(decoded, DemoBatch) and decoded.source == "astar" and decoded.seq == 3
    for (meta, arrays), demo in zip(decoded.split(), demos, strict=True):
        assert np.array_equal(arrays["actions"], demo.actions)
        assert np.allclose(arrays["observations"], demo.observations)
        assert meta.start == tuple(demo.metadata["start"]) and meta.goal == tuple(demo.metadata["goal"])
    noisy = demo_batch(expert_demos("rooms:10", 1, noise=0.5), "astar", "test", 1)
    assert noisy.quality == "suboptimal"


def test_render_frame_draws_map_goal_beams_and_robot():
    blocked = np.zeros((3, 4), bool)
    blocked[0, :] = True
    rows = render_frame(blocked, 1.0, (1.5, 1.5, 0.0), (2, 3), np.array([[3.5, 1.5]]), [(0.5, 2.5)])
    assert rows[0] == "########"
    assert rows[1] == ". > . * "
    assert rows[2] == "o . . G "
    assert [heading_glyph(t) for t in (0.0, np.pi / 2, np.pi, -np.pi / 2)] == [">", "v", "<", "^"]


@pytest.fixture
def network(tmp_path):
    """A real learner (hosting the router) and this process as a second demos subscriber."""
    from services.common.transport import ZenohSettings, open_session

    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"dm{port}"
    argv = [sys.executable, "-m", "services.cli", "learner", "--listen", endpoint, "--run", run,
            "--checkpoint-dir", "", "--hidden-sizes", "16"]  # fmt: skip
    log = open(tmp_path / "learner.log", "wb")  # noqa: SIM115 - closed below
    learner = subprocess.Popen(argv, env=clean_env(), stdout=log, stderr=subprocess.STDOUT)
    session = None
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        received: queue.Queue = queue.Queue()
        subscriber = session.declare_subscriber(
            keys.everything(run, "demos"),
            lambda s: received.put((str(s.key_expr), decode(s.payload.to_bytes()))),
        )
        yield endpoint, run, received, session
        subscriber.undeclare()
    finally:
        if session is not None:
            session.close()
        finish(learner, timeout=0)
        log.close()


def command(endpoint: str, run: str, *extra: str) -> list[str]:
    return [sys.executable, "-m", "services.cli", "demonstrator", "--connect", endpoint, "--run", run, *extra]


def clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}


def collect(received: queue.Queue, episodes: int, timeout: float) -> list[tuple[str, DemoBatch]]:
    out, total, deadline = [], 0, time.monotonic() + timeout
    while total < episodes and time.monotonic() < deadline:
        try:
            key, batch = received.get(timeout=0.5)
        except queue.Empty:
            continue
        out.append((key, batch))
        total += len(batch.episode_lengths)
    return out


def finish(process: subprocess.Popen, timeout: float = 60) -> int:
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGTERM)
        try:
            return process.wait(30)
        except subprocess.TimeoutExpired:
            process.kill()
            return process.wait()


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_human_teleop_through_a_pseudo_terminal(network, tmp_path):
    """Keys go in through a pty, exactly as a person's would; the episode arrives at the subscriber."""
    from agents.planning.expert import Expert
    from services.demonstrator.config import DemonstratorConfig
    from services.demonstrator.episodes import nav_config
    from worlds.env import NavigationEnv

    endpoint, run, received, session = network
    corridor = tmp_path / "corridor.txt"
    corridor.write_text(CORRIDOR)
    config = DemonstratorConfig(source="human", maps=str(corridor), seed=7)
    # The keys a person would press: the expert's actions in the very episode the UI will show.
    env = NavigationEnv(nav_config(config), maps=str(corridor))
    obs, info = env.reset(seed=config.seed)
    expert = Expert(env.config)
    expert.reset(info["task"], info["pose"])
    actions, done = [], False
    while not done:
        actions.append(expert.act(info["pose"], obs))
        obs, _, terminated, truncated, info = env.step(actions[-1])
        done = terminated or truncated
    assert info["outcome"] == 1 and len(actions) < 40

    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 100, 0, 0))
    argv = command(
        endpoint, run, "--source", "human", "--maps", str(corridor), "--seed", "7", "--episodes", "1",
        "--record", str(tmp_path / "human-v0"),
    )  # fmt: skip
    process = subprocess.Popen(
        argv,
        stdin=slave, stdout=slave, stderr=slave, env={**clean_env(), "TERM": "xterm"}, start_new_session=True,
    )  # fmt: skip
    os.close(slave)
    screen = b""
    try:
        deadline = time.monotonic() + 120
        while b"keys:" not in screen and time.monotonic() < deadline and process.poll() is None:
            if select.select([master], [], [], 0.5)[0]:
                screen += os.read(master, 65536)
        assert b"keys:" in screen, screen[-2000:]
        for action in actions:
            os.write(master, ARROWS[action])
            time.sleep(0.05)
        got = collect(received, 1, timeout=60)
        while select.select([master], [], [], 0.2)[0]:  # drain the pty so the UI never blocks on output
            try:
                screen += os.read(master, 65536)
            except OSError:
                break
        assert finish(process) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        os.close(master)
    assert len(got) == 1, screen[-3000:].decode(errors="replace")
    key, batch = got[0]
    assert batch.source == "human" and keys.parse(key).name == "human"
    assert batch.actions.tolist() == actions
    assert bool(batch.terminations[-1])
    # --record: the episode is a Minari dataset that NIRL takes like the expert's
    from agents.nirl.buffers import load_demonstrations
    from worlds.config import LEARNING_NAV

    recorded = load_demonstrations(str(tmp_path / "human-v0"), LEARNING_NAV)  # what the learner takes
    assert len(recorded) == 1 and recorded[0].actions.tolist() == actions
    deadline = time.monotonic() + 30  # and the learner took it into its demonstration buffer
    status = None
    while time.monotonic() < deadline:
        status = query_status(session, run)
        if status is not None and status.counters.get("demo_episodes/human") == 1:
            break
        time.sleep(0.5)
    assert status is not None and status.counters.get("demo_episodes/human") == 1, status
    assert status.replay_sizes["demos"] == len(actions)


def test_file_source_refuses_demonstrations_in_another_observation_than_the_learners(tmp_path):
    from gymnasium import spaces

    from agents.demos import DemoFormatError, write_demos
    from agents.planning.demonstrate import generate_demos
    from services.cli import main
    from services.demonstrator.config import DemonstratorConfig
    from services.demonstrator.episodes import check_file
    from worlds.config import NavConfig
    from worlds.env import observation_space

    demos, _ = generate_demos("rooms:10", 1, seed=3, config=NavConfig())
    write_demos(tmp_path / "plain" / "expert-v0", demos, observation_space(NavConfig()), spaces.Discrete(5))
    learning = tmp_path / "learning" / "expert-v0"  # as the README says to make one
    argv = ["demos", "generate", "--maps", "rooms:10", "--episodes", "1", "--observation", "learning"]
    assert main([*argv, "--out", str(learning)]) == 0
    check_file(DemonstratorConfig(source="file", file=str(learning)))
    with pytest.raises(DemoFormatError, match=r"observing sensors\.n_beams=8 \(the learner has 24\)"):
        check_file(DemonstratorConfig(source="file", file=str(tmp_path / "plain" / "expert-v0")))
