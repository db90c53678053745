"""How an episode ended. Shared by the envs, the evaluator and the wire."""

from __future__ import annotations

from enum import IntEnum


class Outcome(IntEnum):
    """Episode outcome; ``RUNNING`` while the episode goes on."""

    RUNNING = 0
    GOAL = 1
    COLLISION_STATIC = 2
    COLLISION_DYNAMIC = 3
    TIMEOUT = 4


OUTCOME_NAMES: dict[int, str] = {int(o): o.name.lower() for o in Outcome}
