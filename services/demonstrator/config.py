"""The demonstrator service's settings (`navlearn demonstrator` flags), apart so the CLI starts fast."""

from __future__ import annotations

from dataclasses import dataclass

from worlds.config import observation_field

SOURCES = ("astar", "human", "file")


@dataclass
class DemonstratorConfig:
    """One demonstrator process: where its demonstrations come from and how fast they go out."""

    source: str = "astar"
    """astar (the modified-A* expert), human (terminal teleoperation) or file (a Minari dataset)"""
    id: str = ""
    """demonstrator id (token alive/demonstrator/<id>); empty: <source>-<pid>"""
    maps: str = "mixed:16"
    """map spec of the astar and human episodes (worlds.tasks): mixed:16, rooms:20, or map files (a
    map_server .yaml, a MovingAI .map, an ASCII map, a directory); docs/maps.md"""
    rate: float = 1.0
    """astar: expert episodes per second (0: as fast as the expert runs)"""
    episodes: int = 0
    """stop after publishing this many episodes (0: astar and human run until stopped, file sends all)"""
    noise: float = 0.0
    """astar: probability that a step takes a random wall-free action instead of the expert's"""
    obstacles: int = 0
    """moving discs per astar/human episode"""
    observation: str = observation_field()
    """what the demonstrated episodes record (worlds.config.OBSERVATIONS): the learner's; a --file
    dataset must have been recorded in it"""
    seed: int = 0
    """episode i resets the environment with seed SEED + i"""
    file: str = ""
    """file: the demonstration dataset directory to publish"""
    record: str = ""
    """also write every episode it published to this Minari dataset directory when it stops (e.g.
    demos/human-v0: a person's demonstrations for `navlearn nirl train --demos`); empty: none"""
    batch_episodes: int = 1
    """episodes per DemoBatch"""
    keep_failures: bool = False
    """also publish episodes that did not reach the goal"""
    wait_learner: bool = True
    """hold each batch until a learner's liveliness token is present"""
    log_every: float = 10.0
    """seconds between progress lines (astar, file)"""
    outbox_size: int = 16
    """demo batches held unacknowledged; when full the demonstrator waits for the learner"""
    ack_timeout: float = 10.0
    """seconds without an acknowledgement before the unacknowledged batches are sent again"""

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise ValueError(f"source must be one of {', '.join(SOURCES)}, got {self.source!r}")
        if self.source == "file" and not self.file:
            raise ValueError("--source file needs --file DATASET")
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1], got {self.noise}")
        if self.rate < 0 or self.episodes < 0 or self.batch_episodes < 1 or self.obstacles < 0:
            raise ValueError("need rate >= 0, episodes >= 0, obstacles >= 0 and batch_episodes >= 1")
        if self.outbox_size < 1 or self.ack_timeout <= 0:
            raise ValueError("need outbox_size >= 1 and ack_timeout > 0")
