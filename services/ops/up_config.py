"""`navlearn up`'s settings and the checks run on them before any process starts (apart so the
CLI parser builds fast)."""

from __future__ import annotations

import socket
from dataclasses import dataclass
from pathlib import Path

from protocols import keys


@dataclass
class UpConfig:
    """A one-machine run: how many processes, how long, where the outputs go."""

    run: str = "local"
    """run name (Zenoh keys navlearn/<run>/...); a second `up` with the same run resumes its checkpoint"""
    out: str = ""
    """output directory; empty: runs/<run>"""
    actors: int = 2
    """actor processes"""
    envs: int = 8
    """robots per actor"""
    maps: str = "mixed:16"
    """training map spec for the actors (worlds.tasks)"""
    seed: int = 0
    """seed of the learner (network, replay sampling); actor i uses seed + i"""
    duration: float = 90.0
    """seconds of training, counted from the first transition the learner receives (0: no time limit)"""
    updates: int = 0
    """stop once the learner has run this many updates in total (0: no limit)"""
    eval_episodes: int = 20
    """evaluator episodes per family (unseen and dynamic held-out maps)"""
    eval_every: int = 0
    """updates between evaluated versions (0: every new version the evaluator can keep up with)"""
    checkpoint_every: float = 60.0
    """seconds between learner checkpoints (one is always written at the end)"""
    port: int = 0
    """port of the learner's router; 0: a free one"""
    listen_all: bool = False
    """the learner's router listens on 0.0.0.0 (all interfaces), so actors on other hosts can join
    with --connect tcp/<this host>:<port> (give --port); default: 127.0.0.1 only"""


def check_config(config: UpConfig) -> None:
    """Raise ValueError, naming the value and the fix, for anything wrong that is cheap to see
    before a process starts (counts, durations, port, the map spec, the output directory)."""
    from worlds.tasks import parse_map_spec

    positive = {"actors": config.actors, "envs": config.envs, "eval_episodes": config.eval_episodes}
    for name, value in positive.items():
        if value < 1:
            raise ValueError(f"--{name.replace('_', '-')} {value}: needs at least 1")
    for name in ("duration", "updates", "eval_every"):
        if getattr(config, name) < 0:
            raise ValueError(f"--{name.replace('_', '-')} {getattr(config, name)}: must be 0 or more")
    if config.checkpoint_every <= 0:
        raise ValueError(f"--checkpoint-every {config.checkpoint_every}: must be more than 0 seconds")
    if not 0 <= config.port <= 65535:
        raise ValueError(f"--port {config.port}: must be 0 (a free port) or 1 to 65535")
    if config.port:
        with socket.socket() as sock:
            try:
                sock.bind(("0.0.0.0" if config.listen_all else "127.0.0.1", config.port))
            except OSError:
                raise ValueError(
                    f"--port {config.port}: already in use (another learner or router?); stop it, "
                    "or give another port or 0 for a free one"
                ) from None
    keys.check_name(config.run, "run")
    try:
        parse_map_spec(config.maps)
    except (ValueError, OSError) as exc:
        raise ValueError(f"--maps: {exc}") from None
    out = Path(config.out or f"runs/{config.run}")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: is a file; give a directory")
