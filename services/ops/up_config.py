"""`navlearn up`'s settings and the checks run on them before any process starts (apart so the
CLI parser builds fast)."""

from __future__ import annotations

import socket
from dataclasses import dataclass
from pathlib import Path

from protocols import keys
from worlds.config import OBSERVATIONS, TRAINING_DISCS, TRAINING_MAPS, observation_field
from worlds.own_env import EnvConfig


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
    maps: str = TRAINING_MAPS
    """training map spec for the actors (worlds.tasks): generated (default mixed:16-64, a side per map from
    16 to 64 cells) or map files (a map_server .yaml, a MovingAI .map, an ASCII map, a directory;
    docs/maps.md), which the evaluator measures too"""
    moving_discs: int = TRAINING_DISCS
    """each actor episode has 0..moving_discs moving discs, uniform (0: none; the dynamic test set has 4)"""
    observation: str = observation_field()
    """what every process of the run observes (worlds.config.OBSERVATIONS): learning (NNQL's default)
    or learning_plan (and the own map's plan length to the goal: what NIRL's progress potential needs)"""
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
    keep_best: bool = True
    """save as the run's policy the version that scored best in the evaluator's evaluations (on the
    validation episodes, seed 1) rather than the learner's last; --no-keep-best: the last, with the
    evaluator on the test episodes (seed 0)"""
    checkpoint_every: float = 60.0
    """seconds between learner checkpoints (one is always written at the end)"""
    port: int = 0
    """port of the learner's router; 0: a free one"""
    nirl: bool = False
    """also train NIRL (thesis ch. 5) beside NNQL: the learner runs with --nirl, a demonstrator process
    publishes demonstrations (--demos or --demonstrator) and the evaluator compares nirl with nnql"""
    demos: str = ""
    """with --nirl: a demonstration dataset (Minari, `navlearn demos generate`) the demonstrator
    publishes once; empty: live demonstrations from --demonstrator"""
    demonstrator: str = "astar"
    """with --nirl and no --demos: the live demonstrator (astar: the modified-A* expert on --maps;
    a human one needs a terminal of its own: `navlearn demonstrator --source human --connect ...`)"""
    demo_episodes: int = 20
    """with --demonstrator astar: expert episodes it publishes, then it exits (0: until the run stops)"""
    nirl_config: str = ""
    """with --nirl: a JSON file of NIRLConfig fields for the learner (`navlearn learner --nirl-config`)"""
    imitation: str = ""
    """a saved behaviour-cloning policy (`navlearn imitate train`) the evaluator reports beside them"""
    listen_all: bool = False
    """the learner's router listens on 0.0.0.0 (all interfaces), so actors on other hosts can join
    with --connect tcp/<this host>:<port> (give --port); default: 127.0.0.1 only"""


def check_config(config: UpConfig, env: EnvConfig | None = None) -> list[str]:
    """Raise ValueError, naming the value and the fix, for anything wrong that is cheap to see
    before a process starts (counts, durations, port, the map spec, the output directory, and the
    flags a Gymnasium ``env`` cannot take). The env itself (an id that cannot be built, no discrete
    actions) is checked by ``services.learner.config.learner_network``, which `up` calls next and
    which builds the one copy the check needs.
    Returns what each map file of ``--maps`` was read as (its cell size and why), for `up` to print."""
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
        notes = [mf.note for mf in parse_map_spec(config.maps).maps]
    except (ValueError, OSError) as exc:
        raise ValueError(f"--maps: {exc}") from None
    check_nirl(config)
    if env is not None and not env.own_world and (config.nirl or config.imitation):
        flag = "--nirl" if config.nirl else "--imitation"
        raise ValueError(
            f"{flag} works on navlearn's world (its expert and maps); with --env {env.env} drop it"
        )
    out = Path(config.out or f"runs/{config.run}")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: is a file; give a directory")
    return notes


def check_nirl(config: UpConfig) -> None:
    """--demos, --demonstrator and --demo-episodes belong to --nirl; a --demos dataset must be one a
    NIRL learner can use (agents.nirl.buffers.load_demonstrations names the file if not)."""
    for name in ("demos", "nirl_config"):
        if getattr(config, name) and not config.nirl:
            raise ValueError(f"--{name.replace('_', '-')} {getattr(config, name)}: is for NIRL; add --nirl")
    if config.demonstrator != "astar":
        raise ValueError(
            f"--demonstrator {config.demonstrator}: `up` starts astar (the expert); a human demonstrator "
            "needs its own terminal: navlearn demonstrator --source human --connect <the learner's endpoint>"
        )
    if config.demo_episodes < 0:
        raise ValueError(f"--demo-episodes {config.demo_episodes}: must be 0 or more")
    if config.demos:
        from agents.nirl.buffers import load_demonstrations  # torch: only when there is a dataset

        # a file demonstrator sends it to the learner, which takes the run's observation only
        load_demonstrations(config.demos, OBSERVATIONS[config.observation])
    if config.nirl_config and not Path(config.nirl_config).is_file():
        raise ValueError(f"--nirl-config {config.nirl_config}: no such file")
    if config.imitation and not Path(config.imitation, "config.json").exists():
        raise ValueError(f"--imitation {config.imitation}: no saved policy there (no config.json)")
