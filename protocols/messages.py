"""Message schemas: one dataclass per kind, each field declared once with its wire type.

Every message carries the envelope header fields ``sender`` and ``seq`` (the codec adds the kind and
schema version). Each body field is declared with :mod:`protocols.schema` (``text()``, ``count()``,
``column("<f4", width="obs_dim")``, ...); the codec, the checks and the TransitionBatch fast path
(:mod:`protocols.fastpath`) are derived from those declarations, so adding a field is one line, and
adding a kind is one dataclass with ``KIND`` and ``VERSION``, decorated with :func:`register` (and a
``check_body`` classmethod if its fields must agree with each other).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from protocols import schema
from protocols.checks import (
    TENSOR_DTYPES,
    BodyReader,
    check_array,
    check_float,
    check_int,
    check_rows,
    check_size,
    check_string,
)
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.schema import Schema, column, count, custom, inside, json_map, number_map, text

DEMO_SOURCES = ("astar", "human", "file")
OWN_WORLD = "navlearn"
"""``TransitionBatch.env`` of navlearn's own robot world (``worlds.own_env.EnvConfig.signature``)"""
KINDS: dict[str, type[Message]] = {}


def register(cls: type[Message]) -> type[Message]:
    """Add a message class to the kind registry the codec decodes with, deriving its schema."""
    if cls.KIND in KINDS:
        raise ValueError(f"message kind {cls.KIND!r} registered twice")
    cls.SCHEMA = schema.schema_of(cls, cls.KIND)
    KINDS[cls.KIND] = cls
    return cls


@dataclass(kw_only=True, eq=False)
class Message:
    """Base of every message: the envelope header fields."""

    KIND: ClassVar[str]
    VERSION: ClassVar[int]
    SCHEMA: ClassVar[Schema]
    """Derived by :func:`register` from the field declarations."""
    sender: str = ""
    """Who sent it (an actor id, ``learner``, an evaluator id, ...)."""
    seq: int = 0
    """Sender's sequence number, increasing by one per message it sends on a key."""

    def __post_init__(self) -> None:
        for name, dtype in self.SCHEMA.dtypes.items():  # arrays in their wire dtype
            setattr(self, name, np.ascontiguousarray(getattr(self, name), dtype=dtype))

    def to_body(self) -> dict[str, Any]:
        """The body map (every field but the header, in declaration order)."""
        body = {name: getattr(self, name) for name, _ in self.SCHEMA.fields}
        for name, write in self.SCHEMA.writers.items():
            body[name] = write(body[name])
        for name, spec in self.SCHEMA.nested:
            value = getattr(self, name)
            if value is not None:
                body[spec.container] = {**body[spec.container], spec.key: spec.writer(value)}
        return body

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        """Check a decoded body and return the constructor's keyword arguments."""
        return schema.read(cls.SCHEMA, body, cls.check_body)

    @classmethod
    def check_body(cls, fields: dict[str, Any], limits: Limits) -> None:
        """Checks relating several fields, beyond those their declarations imply (none by default)."""

    @classmethod
    def accept_body(cls, body: object, limits: Limits) -> dict[str, Any] | None:
        """Fast path of the general decoder: :meth:`read_body`'s result if ``body`` passes all of its
        checks, else None (then :meth:`read_body` runs and reports what is wrong). Never accepts a
        body :meth:`read_body` rejects; only table messages (:func:`protocols.schema.accept`) have one."""
        return schema.accept(cls.SCHEMA, body, limits) if cls.SCHEMA.table else None


@register
@dataclass(kw_only=True, eq=False)
class TransitionBatch(Message):
    """N transitions from one actor's vectorised env, all from one policy version."""

    KIND: ClassVar[str] = "transitions"
    VERSION: ClassVar[int] = 1
    actor: str = text()
    model: str = text()
    """Name of the model whose policy acted (e.g. ``nnql``)."""
    env: str = text(default=OWN_WORLD)
    """The env the actor runs (``worlds.own_env.EnvConfig.signature``: a Gymnasium id and its kwargs,
    or ``navlearn``); the learner refuses batches of another env than its own, naming both."""
    policy_version: int = count()
    env_ids: np.ndarray = column("<i4")
    """int32 (N,): index of the robot in the actor's vector env."""
    obs: np.ndarray = column("<f4", width="obs_dim")
    """float32 (N, obs_dim)."""
    action: np.ndarray = column("<i8", actions=True)
    """int64 (N,), in [0, n_actions)."""
    reward: np.ndarray = column("<f4")
    """float32 (N,)."""
    next_obs: np.ndarray = column("<f4", width="obs_dim")
    """float32 (N, obs_dim): the true next observation (the terminal one at episode ends)."""
    terminated: np.ndarray = column("|b1")
    """bool (N,)."""
    truncated: np.ndarray = column("|b1")
    """bool (N,)."""

    def __len__(self) -> int:
        return int(self.action.shape[0])


@dataclass(kw_only=True)
class EpisodeMeta:
    """Where one demonstrated episode comes from (stored as Minari episode metadata)."""

    map_id: str
    start: tuple[int, int]
    """Start cell (row, col)."""
    goal: tuple[int, int]
    """Goal cell (row, col)."""
    seed: int | None = None


def _read_episodes(body: BodyReader, name: str) -> list[EpisodeMeta]:
    return [_read_episode(m, i, body) for i, m in enumerate(body.list(name))]


def _read_episode(value: object, index: int, body: BodyReader) -> EpisodeMeta:
    inner = BodyReader(f"demos.episodes[{index}]", value, body.limits)
    cells = {}
    for name in ("start", "goal"):
        cell = inner.raw(name)
        if not isinstance(cell, list) or len(cell) != 2:
            raise ProtocolError("type", f"{inner.what(name)} must be a [row, col] pair")
        cells[name] = tuple(check_int(c, inner.what(name), 0, 2**31 - 1) for c in cell)
    seed = inner.raw("seed")
    meta = EpisodeMeta(
        map_id=inner.string("map_id", allow_empty=True),
        start=cells["start"],
        goal=cells["goal"],
        seed=None if seed is None else check_int(seed, inner.what("seed")),
    )
    inner.finish()
    return meta


def _write_episodes(episodes: list[EpisodeMeta]) -> list[dict[str, Any]]:
    return [
        {"map_id": m.map_id, "start": list(m.start), "goal": list(m.goal), "seed": m.seed} for m in episodes
    ]


@register
@dataclass(kw_only=True, eq=False)
class DemoBatch(Message):
    """Whole demonstrated episodes, concatenated.

    Episode i has ``episode_lengths[i] = L_i`` steps: ``L_i + 1`` observations
    (the last one final) and ``L_i`` actions, rewards, terminations, truncations,
    as in a Minari episode. ``obs`` stacks the episodes' observations in order.
    """

    KIND: ClassVar[str] = "demos"
    VERSION: ClassVar[int] = 1
    source: str = text(choices=DEMO_SOURCES)
    """``astar`` (the modified A* expert), ``human`` or ``file`` (a recorded dataset)."""
    quality: str | None = text(optional=True, default=None)
    """Optional tag such as ``optimal`` or ``suboptimal``."""
    episode_lengths: np.ndarray = schema.array("<i4", 1)
    """int32 (E,), each >= 1."""
    obs: np.ndarray = schema.array("<f4", 2)
    """float32 (sum(L_i + 1), obs_dim)."""
    actions: np.ndarray = schema.array("<i8", 1, actions=True)
    """int64 (sum(L_i),)."""
    rewards: np.ndarray = schema.array("<f4", 1)
    """float32 (sum(L_i),)."""
    terminations: np.ndarray = schema.array("|b1", 1)
    """bool (sum(L_i),)."""
    truncations: np.ndarray = schema.array("|b1", 1)
    """bool (sum(L_i),)."""
    episodes: list[EpisodeMeta] = custom(_read_episodes, _write_episodes, default_factory=list)
    """One entry per episode."""

    def split(self) -> Iterator[tuple[EpisodeMeta, dict[str, np.ndarray]]]:
        """Each episode's metadata and its arrays (``observations`` has one more row than the rest)."""
        step = obs_row = 0
        for meta, length in zip(self.episodes, self.episode_lengths.tolist(), strict=True):
            yield (
                meta,
                {
                    "observations": self.obs[obs_row : obs_row + length + 1],
                    "actions": self.actions[step : step + length],
                    "rewards": self.rewards[step : step + length],
                    "terminations": self.terminations[step : step + length],
                    "truncations": self.truncations[step : step + length],
                },
            )
            step += length
            obs_row += length + 1

    @classmethod
    def check_body(cls, fields: dict[str, Any], limits: Limits) -> None:
        lengths = fields["episode_lengths"]
        if lengths.size and int(lengths.min()) < 1:
            raise ProtocolError("shape", "demos.episode_lengths must all be >= 1")
        steps, n_episodes = int(lengths.sum(dtype=np.int64)), lengths.shape[0]
        if len(fields["episodes"]) != n_episodes:
            raise ProtocolError(
                "shape", f"demos: {len(fields['episodes'])} episode records for {n_episodes} lengths"
            )
        check_rows("demos", steps + n_episodes, ("obs", fields["obs"]))
        check_rows(
            "demos", steps, *((k, fields[k]) for k in ("actions", "rewards", "terminations", "truncations"))
        )
        if not 1 <= fields["obs"].shape[1] <= limits.max_obs_dim:
            raise ProtocolError(
                "shape",
                f"demos.obs has dimension {fields['obs'].shape[1]} (accepted: 1 to {limits.max_obs_dim})",
            )


def _read_tensors(body: BodyReader, name: str) -> dict[str, np.ndarray]:
    raw = body.raw(name)
    if not isinstance(raw, dict):
        raise ProtocolError("type", f"weights.tensors must be a map, got {type(raw).__name__}")
    check_size(raw, "weights.tensors", body.limits)
    tensors = {}
    for key, value in raw.items():
        check_string(key, "weights.tensors key", body.limits)
        what = f"weights.tensors[{key!r}]"
        ndim = value.ndim if isinstance(value, np.ndarray) else 0
        if ndim > body.limits.max_ndim:
            raise ProtocolError("shape", f"{what} has {ndim} dimensions (limit {body.limits.max_ndim})")
        tensors[key] = check_array(value, what, body.limits, TENSOR_DTYPES, ndim)
    return tensors


def _read_observation(value: object, what: str, limits: Limits) -> dict[str, Any]:
    """A flat map of observation setting -> number, bool or string (``architecture["observation"]``)."""
    if not isinstance(value, dict):
        raise ProtocolError("type", f"{what} must be a map, got {type(value).__name__}")
    for key, item in value.items():
        check_string(key, f"{what} key", limits)
        if not isinstance(item, bool | int | float | str):
            raise ProtocolError("type", f"{what}[{key!r}] must be a number, bool or string")
    return dict(value)


def _read_env(value: object, what: str, limits: Limits) -> str:
    """An env signature (``architecture["env"]``): a printable string."""
    return check_string(value, what, limits)


EXPLORATIONS = ("boltzmann", "epsilon")
"""the behaviour policies an actor runs (the one list: NNQLConfig.exploration takes these)"""


@dataclass(kw_only=True, frozen=True)
class ExplorationSchedule:
    """How actors explore with the weights they receive, as a function of the weights' version.

    Field names are NNQLConfig's (``agents.nnql.policy.NNQLPolicy.explore_as`` takes either). On the
    wire it is the map ``architecture["exploration"]`` of a WeightsUpdate (None fields left out).
    """

    exploration: str
    """``boltzmann`` (softmax of Q / temperature) or ``epsilon`` (epsilon-greedy)."""
    temperature_start: float | None = None
    temperature_end: float | None = None
    temperature_decay_updates: int | None = None
    """Boltzmann temperature: geometric decay from start to end over this many updates."""
    epsilon_start: float | None = None
    epsilon_end: float | None = None
    epsilon_decay_updates: int | None = None
    """epsilon: linear decay from start to end over this many updates."""

    @classmethod
    def of(cls, config: object) -> ExplorationSchedule:
        """The schedule of a learner config with these fields (``NNQLConfig``): the one place it is built."""
        return cls(**{f.name: getattr(config, f.name) for f in fields(cls)})

    def to_wire(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    @classmethod
    def from_wire(cls, value: object, what: str, limits: Limits) -> ExplorationSchedule:
        """The schedule in a decoded map; unknown keys are ignored (a newer learner may send more)."""
        if not isinstance(value, dict):
            raise ProtocolError("type", f"{what} must be a map, got {type(value).__name__}")
        mode = value.get("exploration")
        if mode not in EXPLORATIONS:
            raise ProtocolError(
                "field", f"{what}.exploration = {str(mode)[:40]!r} is not one of {EXPLORATIONS}"
            )
        read: dict[str, Any] = {"exploration": mode}
        for name in ("temperature", "epsilon"):
            start, end, steps = f"{name}_start", f"{name}_end", f"{name}_decay_updates"
            if (mode == "boltzmann") == (name == "temperature") or start in value:
                for key in (start, end):
                    read[key] = check_float(value.get(key), f"{what}.{key}")
                read[steps] = check_int(value.get(steps), f"{what}.{steps}", 0)
        if mode == "boltzmann" and min(read["temperature_start"], read["temperature_end"]) <= 0:
            raise ProtocolError("range", f"{what}: Boltzmann temperatures must be > 0")
        return cls(**read)


@register
@dataclass(kw_only=True, eq=False)
class WeightsUpdate(Message):
    """A versioned set of named tensors for one model, with its architecture config."""

    KIND: ClassVar[str] = "weights"
    VERSION: ClassVar[int] = 1
    model: str = text()
    version: int = count()
    tensors: dict[str, np.ndarray] = custom(_read_tensors)
    """Parameter name -> array (float, integer or bool dtypes; floats must be finite)."""
    architecture: dict[str, Any] = json_map(default_factory=dict)
    """JSON-like description needed to rebuild the network (layer sizes, activation, ...)."""
    exploration: ExplorationSchedule | None = inside(
        "architecture",
        "exploration",
        ExplorationSchedule.from_wire,
        ExplorationSchedule.to_wire,
        default=None,
    )
    """How actors explore with these weights (on the wire: ``architecture["exploration"]``)."""
    observation: dict[str, Any] | None = inside(
        "architecture", "observation", _read_observation, dict, default=None
    )
    """What the network takes as input (``worlds.config.observation_settings``: setting -> value);
    actors and evaluators of another observation refuse the weights naming the setting (on the wire:
    ``architecture["observation"]``; None: not said)."""
    env: str | None = inside("architecture", "env", _read_env, str, default=None)
    """The env the network was trained on (``TransitionBatch.env``'s signature); actors and evaluators
    running another env refuse the weights naming both (on the wire: ``architecture["env"]``; None:
    not said, navlearn's world)."""

    def __post_init__(self) -> None:
        self.tensors = {name: np.asarray(value) for name, value in self.tensors.items()}


@register
@dataclass(kw_only=True, eq=False)
class EvalReport(Message):
    """Evaluation of one policy version: metrics per map family (``EvalResult.to_dict()``)."""

    KIND: ClassVar[str] = "eval"
    VERSION: ClassVar[int] = 1
    model: str = text()
    policy_version: int = count()
    metrics: dict[str, Any] = json_map()
    """Map family -> JSON-like metrics (rates, confidence intervals, SPL, ...); floats finite."""

    @classmethod
    def check_body(cls, fields: dict[str, Any], limits: Limits) -> None:
        for family, value in fields["metrics"].items():
            check_string(family, "eval.metrics family", limits)
            if not isinstance(value, dict):
                raise ProtocolError("type", f"eval.metrics[{family!r}] must be a map")


@register
@dataclass(kw_only=True, eq=False)
class StatusReport(Message):
    """A service's answer to a status query: the learner's on ``status/learner``, an actor's on
    ``status/actor:<id>`` (each fills the maps that apply to it)."""

    KIND: ClassVar[str] = "status"
    VERSION: ClassVar[int] = 1
    counters: dict[str, int] = number_map(int, default_factory=dict)
    """Totals: transitions received, updates, rejected messages by reason, ..."""
    rates: dict[str, float] = number_map(float, default_factory=dict)
    """Per-second rates over a recent window (finite)."""
    versions: dict[str, int] = number_map(int, default_factory=dict)
    """Model name -> newest weights version."""
    replay_sizes: dict[str, int] = number_map(int, default_factory=dict)
    """Replay buffer name -> number of stored transitions."""
    actors_last_seen: dict[str, float] = number_map(float, default_factory=dict)
    """Actor id -> Unix time (s) of its last accepted batch."""
    losses: dict[str, float] = number_map(float, finite=False, default_factory=dict)
    """Latest losses; NaN and infinity are allowed here so a diverged learner can still say so."""
    last_eval: dict[str, Any] | None = json_map(optional=True, default=None)
    """The newest evaluation summary (JSON-like), if any."""
    observation: str | None = text(optional=True, default=None)
    """The learner's observation (``--observation``, a name of ``worlds.config.OBSERVATIONS``): what
    its networks take, and so what its actors and evaluator must run; ``env <signature>`` for a learner
    on a Gymnasium ``--env``. None: not said (an actor)."""
    robot: dict[str, Any] | None = json_map(optional=True, default=None)
    """A process facing a robot: ``navlearn drive``'s state (goal, distance, last action, stale
    inputs, ...) or ``navlearn ros2-sim``'s (pose, collision, path length); None for the others."""


__all__ = [
    "DEMO_SOURCES",
    "KINDS",
    "OWN_WORLD",
    "DemoBatch",
    "EpisodeMeta",
    "EvalReport",
    "ExplorationSchedule",
    "Message",
    "StatusReport",
    "TransitionBatch",
    "WeightsUpdate",
    "register",
]
