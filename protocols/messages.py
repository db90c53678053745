"""Message schemas: one dataclass per kind, each reading and checking its own body.

Every message carries the envelope header fields ``sender`` and ``seq`` (the
codec adds the kind and schema version). Arrays are converted to their wire
dtypes on construction. Adding a kind is one small entry: a dataclass with
``KIND``, ``VERSION`` and a ``read_body`` classmethod, decorated with
:func:`register`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np

from protocols.checks import (
    INT64_MAX,
    TENSOR_DTYPES,
    BodyReader,
    actions_in_range,
    all_finite,
    check_actions,
    check_array,
    check_finite_pair,
    check_int,
    check_rows,
    check_size,
    check_string,
)
from protocols.errors import ProtocolError
from protocols.limits import Limits

F32 = frozenset({np.dtype("<f4")})
I64 = frozenset({np.dtype("<i8")})
I32 = frozenset({np.dtype("<i4")})
BOOL = frozenset({np.dtype("|b1")})
DEMO_SOURCES = ("astar", "human", "file")
KINDS: dict[str, type[Message]] = {}
_BODY_FIELDS: dict[type, tuple[str, ...]] = {}


def register(cls: type[Message]) -> type[Message]:
    """Add a message class to the kind registry the codec decodes with."""
    if cls.KIND in KINDS:
        raise ValueError(f"message kind {cls.KIND!r} registered twice")
    KINDS[cls.KIND] = cls
    return cls


@dataclass(kw_only=True, eq=False)
class Message:
    """Base of every message: the envelope header fields."""

    KIND: ClassVar[str]
    VERSION: ClassVar[int]
    sender: str = ""
    """Who sent it (an actor id, ``learner``, an evaluator id, ...)."""
    seq: int = 0
    """Sender's sequence number, increasing by one per message it sends on a key."""

    def to_body(self) -> dict[str, Any]:
        """The body map (every field but the header)."""
        names = _BODY_FIELDS.get(type(self))
        if names is None:
            names = _BODY_FIELDS[type(self)] = tuple(
                f.name for f in fields(self) if f.name not in ("sender", "seq")
            )
        return {name: getattr(self, name) for name in names}

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        """Check a decoded body and return the constructor's keyword arguments."""
        raise NotImplementedError

    @classmethod
    def accept_body(cls, body: object, limits: Limits) -> dict[str, Any] | None:
        """Optional fast path for hot kinds: :meth:`read_body`'s result if ``body`` passes all of
        its checks, else None (then :meth:`read_body` runs and reports what is wrong).

        It must never accept a body :meth:`read_body` rejects; None is always safe.
        """
        return None


def _arrays(obj: Message, dtypes: dict[str, np.dtype]) -> None:
    for name, dtype in dtypes.items():
        setattr(obj, name, np.ascontiguousarray(getattr(obj, name), dtype=dtype))


@register
@dataclass(kw_only=True, eq=False)
class TransitionBatch(Message):
    """N transitions from one actor's vectorised env, all from one policy version."""

    KIND: ClassVar[str] = "transitions"
    VERSION: ClassVar[int] = 1
    actor: str
    model: str
    """Name of the model whose policy acted (e.g. ``nnql``)."""
    policy_version: int
    env_ids: np.ndarray
    """int32 (N,): index of the robot in the actor's vector env."""
    obs: np.ndarray
    """float32 (N, obs_dim)."""
    action: np.ndarray
    """int64 (N,), in [0, n_actions)."""
    reward: np.ndarray
    """float32 (N,)."""
    next_obs: np.ndarray
    """float32 (N, obs_dim): the true next observation (the terminal one at episode ends)."""
    terminated: np.ndarray
    """bool (N,)."""
    truncated: np.ndarray
    """bool (N,)."""

    def __post_init__(self) -> None:
        _arrays(self, _TRANSITION_DTYPES)

    def __len__(self) -> int:
        return int(self.action.shape[0])

    @classmethod
    def accept_body(cls, body: object, limits: Limits) -> dict[str, Any] | None:
        """Every check of :meth:`read_body` as one conjunction, without its per-field machinery
        (about half the cost of decoding a batch of 1024 is that machinery)."""
        if type(body) is not dict or len(body) != len(_TRANSITION_FIELDS):  # no unknown fields
            return None
        get = body.get
        obs, next_obs, reward, action = get("obs"), get("next_obs"), get("reward"), get("action")
        env_ids, terminated, truncated = get("env_ids"), get("terminated"), get("truncated")
        actor, model, version = get("actor"), get("model"), get("policy_version")
        array, max_string = np.ndarray, limits.max_string
        if not (
            type(obs) is array
            and type(next_obs) is array
            and type(reward) is array
            and type(action) is array
            and type(env_ids) is array
            and type(terminated) is array
            and type(truncated) is array
            and obs.dtype == _F32
            and next_obs.dtype == _F32
            and reward.dtype == _F32
            and action.dtype == _I64
            and env_ids.dtype == _I32
            and terminated.dtype == _BOOL
            and truncated.dtype == _BOOL
            and obs.ndim == 2
            and next_obs.shape == obs.shape
            and 1 <= obs.shape[1] <= limits.max_obs_dim
            and obs.shape[0] <= limits.max_batch
            and reward.shape == action.shape == env_ids.shape == terminated.shape == truncated.shape
            and reward.shape == obs.shape[:1]
            and type(actor) is str
            and 0 < len(actor) <= max_string
            and actor.isprintable()
            and type(model) is str
            and 0 < len(model) <= max_string
            and model.isprintable()
            and type(version) is int
            and 0 <= version <= INT64_MAX
            and all_finite(obs, next_obs)
            and all_finite(reward)
            and actions_in_range(action, limits)
        ):
            return None
        return {
            "env_ids": env_ids,
            "obs": obs,
            "action": action,
            "reward": reward,
            "next_obs": next_obs,
            "terminated": terminated,
            "truncated": truncated,
            "actor": actor,
            "model": model,
            "policy_version": version,
        }

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        out: dict[str, Any] = body.arrays(_TRANSITION_SCHEMA, finite_later=("obs", "next_obs"))
        out["actor"] = body.string("actor")
        out["model"] = body.string("model")
        out["policy_version"] = body.integer("policy_version")
        n, obs_dim = out["obs"].shape
        if not 1 <= obs_dim <= body.limits.max_obs_dim:
            raise ProtocolError("shape", f"transitions.obs has dimension {obs_dim}")
        if out["next_obs"].shape != out["obs"].shape:
            raise ProtocolError(
                "shape", f"transitions: next_obs {out['next_obs'].shape} differs from obs {out['obs'].shape}"
            )
        check_finite_pair("transitions", ("obs", out["obs"]), ("next_obs", out["next_obs"]))
        for name in _TRANSITION_SCHEMA:
            if out[name].shape[0] != n:
                check_rows("transitions", n, (name, out[name]))
        check_actions(out["action"], "transitions.action", body.limits)
        return out


_TRANSITION_SCHEMA = {
    "env_ids": (I32, 1),
    "obs": (F32, 2),
    "action": (I64, 1),
    "reward": (F32, 1),
    "next_obs": (F32, 2),
    "terminated": (BOOL, 1),
    "truncated": (BOOL, 1),
}
_TRANSITION_DTYPES = {name: next(iter(dtypes)) for name, (dtypes, _) in _TRANSITION_SCHEMA.items()}
_TRANSITION_FIELDS = (*_TRANSITION_SCHEMA, "actor", "model", "policy_version")
_F32, _I64, _I32, _BOOL = (np.dtype(s) for s in ("<f4", "<i8", "<i4", "|b1"))


@dataclass(kw_only=True)
class EpisodeMeta:
    """Where one demonstrated episode comes from (stored as Minari episode metadata)."""

    map_id: str
    start: tuple[int, int]
    """Start cell (row, col)."""
    goal: tuple[int, int]
    """Goal cell (row, col)."""
    seed: int | None = None


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
    source: str
    """``astar`` (the modified A* expert), ``human`` or ``file`` (a recorded dataset)."""
    quality: str | None = None
    """Optional tag such as ``optimal`` or ``suboptimal``."""
    episode_lengths: np.ndarray
    """int32 (E,), each >= 1."""
    obs: np.ndarray
    """float32 (sum(L_i + 1), obs_dim)."""
    actions: np.ndarray
    """int64 (sum(L_i),)."""
    rewards: np.ndarray
    """float32 (sum(L_i),)."""
    terminations: np.ndarray
    """bool (sum(L_i),)."""
    truncations: np.ndarray
    """bool (sum(L_i),)."""
    episodes: list[EpisodeMeta] = field(default_factory=list)
    """One entry per episode."""

    def __post_init__(self) -> None:
        _arrays(self, _DEMO_DTYPES)

    def to_body(self) -> dict[str, Any]:
        body = super().to_body()
        body["episodes"] = [
            {"map_id": m.map_id, "start": list(m.start), "goal": list(m.goal), "seed": m.seed}
            for m in self.episodes
        ]
        return body

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
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        out: dict[str, Any] = body.arrays(_DEMO_SCHEMA)
        out["source"] = body.string("source", choices=DEMO_SOURCES)
        out["quality"] = body.string("quality", optional=True)
        out["episodes"] = [_read_episode(m, i, body) for i, m in enumerate(body.list("episodes"))]
        lengths = out["episode_lengths"]
        if lengths.size and int(lengths.min()) < 1:
            raise ProtocolError("shape", "demos.episode_lengths must all be >= 1")
        steps, n_episodes = int(lengths.sum(dtype=np.int64)), lengths.shape[0]
        if len(out["episodes"]) != n_episodes:
            raise ProtocolError(
                "shape", f"demos: {len(out['episodes'])} episode records for {n_episodes} lengths"
            )
        check_rows("demos", steps + n_episodes, ("obs", out["obs"]))
        check_rows(
            "demos", steps, *((k, out[k]) for k in ("actions", "rewards", "terminations", "truncations"))
        )
        if not 1 <= out["obs"].shape[1] <= body.limits.max_obs_dim:
            raise ProtocolError("shape", f"demos.obs has dimension {out['obs'].shape[1]}")
        check_actions(out["actions"], "demos.actions", body.limits)
        return out


_DEMO_SCHEMA = {
    "episode_lengths": (I32, 1),
    "obs": (F32, 2),
    "actions": (I64, 1),
    "rewards": (F32, 1),
    "terminations": (BOOL, 1),
    "truncations": (BOOL, 1),
}
_DEMO_DTYPES = {name: next(iter(dtypes)) for name, (dtypes, _) in _DEMO_SCHEMA.items()}


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


@register
@dataclass(kw_only=True, eq=False)
class WeightsUpdate(Message):
    """A versioned set of named tensors for one model, with its architecture config."""

    KIND: ClassVar[str] = "weights"
    VERSION: ClassVar[int] = 1
    model: str
    version: int
    tensors: dict[str, np.ndarray]
    """Parameter name -> array (float, integer or bool dtypes; floats must be finite)."""
    architecture: dict[str, Any] = field(default_factory=dict)
    """JSON-like description needed to rebuild the network (layer sizes, activation, ...)."""

    def __post_init__(self) -> None:
        self.tensors = {name: np.asarray(value) for name, value in self.tensors.items()}

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        raw = body.raw("tensors")
        if not isinstance(raw, dict):
            raise ProtocolError("type", f"weights.tensors must be a map, got {type(raw).__name__}")
        check_size(raw, "weights.tensors", body.limits)
        tensors = {}
        for name, value in raw.items():
            check_string(name, "weights.tensors key", body.limits)
            what = f"weights.tensors[{name!r}]"
            ndim = value.ndim if isinstance(value, np.ndarray) else 0
            if ndim > body.limits.max_ndim:
                raise ProtocolError("shape", f"{what} has {ndim} dimensions (limit {body.limits.max_ndim})")
            tensors[name] = check_array(value, what, body.limits, TENSOR_DTYPES, ndim)
        return {
            "model": body.string("model"),
            "version": body.integer("version"),
            "tensors": tensors,
            "architecture": body.json_map("architecture"),
        }


@register
@dataclass(kw_only=True, eq=False)
class EvalReport(Message):
    """Evaluation of one policy version: metrics per map family (``EvalResult.to_dict()``)."""

    KIND: ClassVar[str] = "eval"
    VERSION: ClassVar[int] = 1
    model: str
    policy_version: int
    metrics: dict[str, Any]
    """Map family -> JSON-like metrics (rates, confidence intervals, SPL, ...); floats finite."""

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        metrics = body.json_map("metrics")
        for family, value in metrics.items():
            check_string(family, "eval.metrics family", body.limits)
            if not isinstance(value, dict):
                raise ProtocolError("type", f"eval.metrics[{family!r}] must be a map")
        return {
            "model": body.string("model"),
            "policy_version": body.integer("policy_version"),
            "metrics": metrics,
        }


@register
@dataclass(kw_only=True, eq=False)
class LearnerStatus(Message):
    """The learner's answer to a status query."""

    KIND: ClassVar[str] = "status"
    VERSION: ClassVar[int] = 1
    counters: dict[str, int] = field(default_factory=dict)
    """Totals: transitions received, updates, rejected messages by reason, ..."""
    rates: dict[str, float] = field(default_factory=dict)
    """Per-second rates over a recent window (finite)."""
    versions: dict[str, int] = field(default_factory=dict)
    """Model name -> newest weights version."""
    replay_sizes: dict[str, int] = field(default_factory=dict)
    """Replay buffer name -> number of stored transitions."""
    actors_last_seen: dict[str, float] = field(default_factory=dict)
    """Actor id -> Unix time (s) of its last accepted batch."""
    losses: dict[str, float] = field(default_factory=dict)
    """Latest losses; NaN and infinity are allowed here so a diverged learner can still say so."""
    last_eval: dict[str, Any] | None = None
    """The newest evaluation summary (JSON-like), if any."""

    @classmethod
    def read_body(cls, body: BodyReader) -> dict[str, Any]:
        return {
            "counters": body.number_map("counters", int),
            "rates": body.number_map("rates", float),
            "versions": body.number_map("versions", int),
            "replay_sizes": body.number_map("replay_sizes", int),
            "actors_last_seen": body.number_map("actors_last_seen", float),
            "losses": body.number_map("losses", float, finite=False),
            "last_eval": body.json_map("last_eval", optional=True),
        }


__all__ = [
    "DEMO_SOURCES",
    "KINDS",
    "DemoBatch",
    "EpisodeMeta",
    "EvalReport",
    "LearnerStatus",
    "Message",
    "TransitionBatch",
    "WeightsUpdate",
    "register",
]
