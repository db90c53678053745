"""Key expressions of the navlearn key space, all under ``navlearn/<run>/``.

=========================  ==========================  =================
key                        from -> to                  payload
=========================  ==========================  =================
``transitions/<actor>``    actor -> learner            TransitionBatch
``demos/<source>``         demonstrator -> learner     DemoBatch
``weights/<model>``        learner -> actors, eval     WeightsUpdate
``eval/<evaluator>``       evaluator -> learner        EvalReport
``status/learner``         queryable                   StatusReport
``status/actor:<actor>``   queryable (each actor)      StatusReport (the actor's figures)
``status/drive:<id>``      queryable (navlearn drive)  StatusReport (robot: goal, distance, ...)
``status/sim:<id>``        queryable (ros2-sim)        StatusReport (robot: pose, collision, ...)
``acks/<actor>``           learner -> actor            acknowledgements
``alive/<role>/<id>``      liveliness tokens           (none)
=========================  ==========================  =================

Every name placed in a key (run, actor, model, role, ...) must match
:data:`NAME_PATTERN`: no ``/``, wildcards (``*``), ``$``, ``?``, ``#``, spaces,
and not empty or too long, so that one name is always exactly one key chunk.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from protocols.errors import ProtocolError

ROOT = "navlearn"
MAX_NAME = 64
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.:@+=-]*")
CHANNELS: dict[str, int] = {
    "transitions": 1,
    "demos": 1,
    "weights": 1,
    "eval": 1,
    "status": 1,
    "acks": 1,
    "alive": 2,
}
"""Channel -> number of names after it in a key."""


def check_name(name: object, what: str = "name") -> str:
    """``name`` if it is safe as one key chunk, else ProtocolError("key")."""
    if not isinstance(name, str):
        raise ProtocolError("key", f"{what} must be a string, got {type(name).__name__}")
    if not name or len(name) > MAX_NAME:
        raise ProtocolError("key", f"{what} {name[:80]!r} must have 1 to {MAX_NAME} characters")
    if not NAME_PATTERN.fullmatch(name):
        raise ProtocolError(
            "key",
            f"{what} {name!r} may only use letters, digits and _ . : @ + = - (no '/', '*', '$', '?', '#', "
            "spaces), and must not start with a punctuation mark",
        )
    return name


def prefix(run: str) -> str:
    """``navlearn/<run>``."""
    return f"{ROOT}/{check_name(run, 'run')}"


def _key(run: str, channel: str, *names: str) -> str:
    checked = [check_name(n, f"{channel} name") for n in names]
    return "/".join((prefix(run), channel, *checked))


def transitions(run: str, actor: str) -> str:
    return _key(run, "transitions", actor)


def demos(run: str, source: str) -> str:
    return _key(run, "demos", source)


def weights(run: str, model: str) -> str:
    return _key(run, "weights", model)


def evaluation(run: str, evaluator: str) -> str:
    return _key(run, "eval", evaluator)


def status(run: str) -> str:
    return _key(run, "status", "learner")


ACTOR_STATUS_PREFIX = "actor:"
"""An actor answers its status on ``status/actor:<id>`` (the ``status`` channel has one name)."""


def actor_status(run: str, actor: str) -> str:
    return _key(run, "status", ACTOR_STATUS_PREFIX + check_name(actor, "actor id"))


DRIVE_STATUS_PREFIX = "drive:"
"""``navlearn drive`` answers its status on ``status/drive:<id>``"""
SIM_STATUS_PREFIX = "sim:"
"""``navlearn ros2-sim`` answers its status on ``status/sim:<id>``"""


def drive_status(run: str, ident: str) -> str:
    return _key(run, "status", DRIVE_STATUS_PREFIX + check_name(ident, "drive id"))


def sim_status(run: str, ident: str) -> str:
    return _key(run, "status", SIM_STATUS_PREFIX + check_name(ident, "sim id"))


def acks(run: str, actor: str) -> str:
    return _key(run, "acks", actor)


def alive(run: str, role: str, ident: str) -> str:
    return _key(run, "alive", role, ident)


def everything(run: str, channel: str) -> str:
    """The key expression matching every key of ``channel`` in ``run`` (e.g. ``navlearn/r/transitions/*``)."""
    if channel not in CHANNELS:
        raise ProtocolError("key", f"unknown channel {channel!r}; one of {sorted(CHANNELS)}")
    return "/".join((prefix(run), channel, *("*" * CHANNELS[channel])))


def alive_role(run: str, role: str) -> str:
    """Every liveliness token of one role: ``navlearn/<run>/alive/<role>/*``."""
    return f"{prefix(run)}/alive/{check_name(role, 'role')}/*"


def alive_in_every_run(role: str) -> str:
    """Every liveliness token of one role in any run: ``navlearn/*/alive/<role>/*`` (who is where)."""
    return f"{ROOT}/*/alive/{check_name(role, 'role')}/*"


@dataclass(frozen=True)
class ParsedKey:
    """A key split into its run, channel and names (``names`` has one entry, two for ``alive``)."""

    run: str
    channel: str
    names: tuple[str, ...]

    @property
    def name(self) -> str:
        """The last name: the actor, model, source, evaluator or process id."""
        return self.names[-1]


def parse(key: object) -> ParsedKey:
    """Split a concrete key of the navlearn key space; ProtocolError("key") for anything else."""
    if not isinstance(key, str):
        key = str(key)  # a zenoh.KeyExpr
    parts = key.split("/")
    if len(parts) < 4 or parts[0] != ROOT:
        raise ProtocolError("key", f"{key[:200]!r} is not a {ROOT}/<run>/<channel>/... key")
    run, channel, names = parts[1], parts[2], tuple(parts[3:])
    if CHANNELS.get(channel) != len(names):
        raise ProtocolError("key", f"{key[:200]!r}: unknown channel or wrong number of names")
    check_name(run, "run")
    for n in names:
        check_name(n, f"{channel} name")
    return ParsedKey(run, channel, names)
