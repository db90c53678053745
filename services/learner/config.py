"""The learner service's settings (``navlearn learner`` flags; NNQL's own are NNQLConfig's)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from agents.device import DEVICES
from agents.nnql.config import STORAGES, NNQLConfig
from worlds.config import OBSERVATIONS, observation_field, observation_settings
from worlds.own_env import EnvConfig, EnvSpaces, describe_env

SARSA_LOCAL_ONLY = (
    "the SARSA variant needs the next action taken, which transition batches do not carry; "
    "use `navlearn train --local --sarsa`"
)
PATCH_ONLY = (
    "it shapes the CNN over the own-map patch, and the observations of the distributed services "
    "(--observation learning or learning_plan) have none; `navlearn train --local --patch-size N` has one"
)
NNQL_REFUSED = {"sarsa": SARSA_LOCAL_ONLY, "patch": PATCH_ONLY}
"""NNQLConfig fields the learner service (and so `navlearn up`) cannot honour, and why: refused when
the arguments are parsed (services.common.options.add_options' ``refuse``; ``patch``: every --patch-*
option of the patch network)"""


def learner_network(
    nnql: NNQLConfig, observation: str, env: EnvConfig, spaces: EnvSpaces | None = None
) -> NNQLConfig:
    """``nnql`` with the Q-network variant the learner builds for the actors' ``observation`` (an
    OBSERVATIONS name) or ``env`` (a Gymnasium env: its ``spaces``, or one copy built to read them): a
    variant it cannot feed (``--network patch``, ``--network local`` with --env, ``--network cnn``
    without an image) is a ValueError while the arguments are checked, before any process starts."""
    if env.own_world:
        return nnql.resolved(observation_settings(OBSERVATIONS[observation]))
    return nnql.resolved(None, (spaces or describe_env(env)).image)


@dataclass
class LearnerConfig:
    """The learner service (NNQL hyper-parameters, incl. the update-to-data ratio, are NNQLConfig's)."""

    id: str = "learner"
    """learner id: its liveliness token is alive/learner/<id>"""
    model: str = "nnql"
    """model name: weights go out on weights/<model>"""
    checkpoint_dir: str = "runs/default/checkpoints"
    """where checkpoints go (ckpt-NNNNNNNN directories); empty: no checkpoints"""
    checkpoint_every: float = 300.0
    """seconds between checkpoints; one is also written on SIGTERM/SIGINT (0: only then)"""
    keep_checkpoints: int = 3
    """checkpoints kept; older ones are deleted"""
    resume: bool = True
    """resume from the newest checkpoint in checkpoint_dir if there is one"""
    broadcast_every: int = 50
    """updates between weight broadcasts (M)"""
    rate_tolerance: float = 64.0
    """updates the learner may run ahead of or fall behind the update-to-data ratio before waiting"""
    inbox_size: int = 256
    """transition batches waiting to be inserted; more are dropped and counted (dropped/inbox_full)"""
    inbox_mb: int = 256
    """megabytes of transition batches waiting (and as many of demos and evaluation reports); one
    actor may fill a quarter (dropped/sender_full beyond)"""
    max_batch_fraction: float = 0.01
    """largest transition batch accepted, as a fraction of the replay capacity (also at most
    rate_tolerance / utd_ratio rows); larger ones are refused and counted (rejected/batch_too_large)"""
    max_names: int = 256
    """distinct sender names (actors, demo sources, evaluators) accepted besides an ACL's; messages of
    new names beyond are refused and counted (rejected/too_many_names)"""
    acl_names: str = ""
    """an ACL file (navlearn credentials' acl.json5) whose process ids are always accepted; the
    learner's own --acl (when it hosts the router) counts too"""
    demo_capacity: int = 200_000
    """demonstration steps kept (a separate buffer: actor transitions never evict demonstrations)"""
    tensorboard: str = ""
    """directory for TensorBoard scalars (charts/, losses/); empty: none"""
    log_every: float = 10.0
    """seconds between progress lines on stdout"""
    max_updates: int = 0
    """stop (with a checkpoint) after this many updates; 0: run until stopped"""
    wal_fsync: str = "always"
    """write-ahead log (checkpoint_dir/wal) fsync: always, never, or milliseconds between fsyncs"""
    observation: str = observation_field()
    """what the actors' robots observe (worlds.config.OBSERVATIONS): learning or learning_plan; the
    networks take it as input, and transitions of another width are refused"""
    nirl: bool = False
    """also train NIRL (thesis ch. 5) on the demonstrations and the actors' experience; weights/nirl"""
    nirl_updates: int = 1
    """NIRL updates per NNQL update once NIRL's warm start on the demonstrations is done"""
    replay_storage: str = "memory"
    """memory (RAM) or memmap (files under checkpoint_dir/replay, flushed in place by each checkpoint)"""
    device: str = "cpu"
    """where networks, losses and sampled batches live: cpu, cuda (cuda:N) or auto (a GPU if torch has one)"""

    def __post_init__(self) -> None:
        if self.device not in DEVICES and not self.device.startswith("cuda:"):
            raise ValueError(f"LearnerConfig.device={self.device!r}: expected one of {DEVICES} or cuda:N")
        if self.replay_storage not in STORAGES:
            raise ValueError(
                f"LearnerConfig.replay_storage={self.replay_storage!r}: expected one of {STORAGES}"
            )
        if self.replay_storage == "memmap" and not self.checkpoint_dir:
            raise ValueError("--replay-storage memmap keeps the replay under --checkpoint-dir; set one")

    @property
    def replay_dir(self) -> Path | None:
        """Where a memory-mapped replay lives (None: in RAM)."""
        return Path(self.checkpoint_dir) / "replay" if self.replay_storage == "memmap" else None
