"""The actor service's settings (`navlearn actor` flags), apart so the CLI parser builds fast."""

from __future__ import annotations

from dataclasses import dataclass

from worlds.config import TRAINING_DISCS, TRAINING_MAPS, observation_field


@dataclass
class ActorConfig:
    """One actor process: its robots, its maps and how it sends."""

    id: str = ""
    """actor id (key transitions/<id>, token alive/actor/<id>); empty: <hostname>-<pid>"""
    envs: int = 8
    """robots stepped together in the vector env"""
    maps: str = TRAINING_MAPS
    """training map spec (worlds.tasks): mixed:16-64 (default: a side per map, 16 to 64 cells), rooms:16,
    mixed:16,mixed:32, or map files (a map_server .yaml, a MovingAI .map/.scen, an ASCII map, a
    directory) with key=value options; docs/maps.md"""
    moving_discs: int = TRAINING_DISCS
    """each episode has 0..moving_discs moving discs, uniform (0: none; the dynamic test set has 4)"""
    observation: str = observation_field()
    """what the robots observe (worlds.config.OBSERVATIONS): learning (24 sector minima, goal, own-map
    subgoal) or learning_plan (the same and the own map's plan length to the goal); the learner's"""
    seed: int | None = None
    """env and exploration seed; empty: derived from the actor id (give each actor its own)"""
    model: str = "nnql"
    """model whose weights the actor follows (weights/<model>)"""
    batch_steps: int = 16
    """vector-env steps per published TransitionBatch (K); a batch holds K x envs transitions"""
    ack_window: int = 2
    """batches in flight without the learner's acknowledgement before the actor waits"""
    ack_timeout: float = 10.0
    """seconds without any acknowledgement before the unacknowledged batches are sent again"""
    outbox_size: int = 64
    """batches held (unsent or unacknowledged); when full the actor waits for the learner (back-pressure)"""
    silence_warning: float = 15.0
    """seconds without any acknowledgement, while batches wait, before the actor says so and names the
    likely cause (no learner on this run, a wrong --run, an ACL); repeated with back-off (0: never)"""
    max_steps: int = 0
    """stop after this many robot-steps (0: run until stopped)"""
    log_every: float = 10.0
    """seconds between progress lines on stdout"""
