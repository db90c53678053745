"""Any Gymnasium environment in place of navlearn's world: naming it, building it, vectorising it.

navlearn's compiled robot world is the default of every process; ``--env`` names another one, in one
of the forms Gymnasium users know:

* a registered id (``CartPole-v1``), after importing ``--env-module PKG`` if the package registers it
  on import (``--env-module minigrid --env MiniGrid-DoorKey-5x5-v0``);
* ``module:Id``, Gymnasium's own form: the module is imported, then ``Id`` made;
* ``module:callable``: a function (or class) of that module returning an env.

``--env-kwargs`` is a JSON object passed to ``gymnasium.make`` or to the callable. What NNQL needs of
the env is fixed here, once, for the actors, the learner and the evaluator alike (:func:`make_env`):
``Discrete`` actions (a continuous action space is refused, with what to do instead), observations
flattened to one float vector by gymnasium's own ``FlattenObservation`` (a ``Box`` of any shape, a
``Dict``, a ``Tuple``, a ``Discrete`` as one-hot). Copies are stepped by ``gymnasium.vector``'s
``SyncVectorEnv`` (default) or ``AsyncVectorEnv`` in ``SAME_STEP`` autoreset mode, the mode
``agents.nnql.rollout.VectorRollout`` and ``worlds.vector_env.NavigationVectorEnv`` share: an ended
episode's terminal observation is in ``info["final_obs"]``, its info in ``info["final_info"]``, and
``terminated`` and ``truncated`` come through as the env said them.

An observation that is an image (:func:`image_description`: a ``Box`` of shape (H, W, C) or (C, H, W),
uint8 0..255, C in 1, 3 or 4, Stable-Baselines3's convention) travels flat all the same; the learner
reads its shape and layout from its own copy of the env (:func:`describe_env`) and, with ``--network
auto``, learns it with a CNN (agents.nnql.image_network).

A run names its env by :meth:`EnvConfig.signature` (announced in every transition batch, checked by the
learner) and records it with :meth:`EnvConfig.record` (in the weights and in saved policies, so
``navlearn evaluate --policy`` rebuilds the same env).
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import importlib
import json
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from protocols.messages import OWN_WORLD

VECTORS = ("sync", "async")
ENV_TITLE = "environment (default navlearn's robot world; --env: any Gymnasium env with discrete actions)"
"""the --help group title of EnvConfig's flags, the same in every command"""


class EnvError(ValueError):
    """An env that cannot be named, built or learned by NNQL; the message names the value and the fix."""


@dataclass
class EnvConfig:
    """Which environment a process runs: navlearn's robot world (default) or any Gymnasium env."""

    env: str = field(default="", metadata={"env": "NAVLEARN_ENV", "metavar": "ID"})
    """a Gymnasium env instead of navlearn's world: a registered id (CartPole-v1), module:Id (imports
    module, which registers Id) or module:callable (a function returning an env); discrete actions
    only. Empty: navlearn's compiled robot world"""
    env_kwargs: str = field(default="", metadata={"env": "NAVLEARN_ENV_KWARGS", "metavar": "JSON"})
    """keyword arguments of --env as a JSON object, e.g. '{"max_episode_steps": 200}'"""
    env_module: str = field(default="", metadata={"env": "NAVLEARN_ENV_MODULE", "metavar": "MODULE"})
    """a module imported before --env is made, for packages that register their ids on import
    (minigrid, ale_py, your own package)"""
    env_vector: str = field(
        default="sync", metadata={"env": "NAVLEARN_ENV_VECTOR", "choices": VECTORS, "metavar": "MODE"}
    )
    """how an actor steps its copies of --env: sync (one after another in the actor process,
    gymnasium.vector.SyncVectorEnv) or async (one subprocess per copy, AsyncVectorEnv: for slow envs)"""

    def __post_init__(self) -> None:
        self.env = self.env.strip()
        if self.env_vector not in VECTORS:
            raise EnvError(f"--env-vector {self.env_vector!r}: expected one of {VECTORS}")
        if not self.env and (self.env_kwargs.strip() or self.env_module):
            flag = "--env-kwargs" if self.env_kwargs.strip() else "--env-module"
            raise EnvError(f"{flag} is for a Gymnasium env: give --env too (navlearn's world takes neither)")
        self.kwargs  # noqa: B018 - parsed now, so a bad --env-kwargs is refused at start

    @property
    def own_world(self) -> bool:
        """True for navlearn's compiled robot world (no --env)."""
        return not self.env

    @property
    def kwargs(self) -> dict[str, Any]:
        """``--env-kwargs`` as a dict."""
        text = self.env_kwargs.strip()
        if not text:
            return {}
        try:
            value = json.loads(text)
        except json.JSONDecodeError as exc:
            raise EnvError(f"--env-kwargs {text!r}: not valid JSON ({exc.msg}); give a JSON object") from None
        if not isinstance(value, dict):
            raise EnvError(f"--env-kwargs {text!r}: a JSON object is needed, e.g. '{{\"key\": 1}}'")
        return value

    def signature(self) -> str:
        """One printable line naming the env and its kwargs (at most 200 characters): what actors
        announce in each transition batch and the learner compares with its own."""
        if self.own_world:
            return OWN_WORLD
        kwargs = json.dumps(self.kwargs, sort_keys=True, separators=(",", ":"))
        line = self.env if kwargs == "{}" else f"{self.env} {kwargs}"
        if len(line) > 200 or not line.isprintable():
            digest = hashlib.sha1(kwargs.encode()).hexdigest()[:12]
            line = f"{self.env[:160]} kwargs-sha1:{digest}"
        return line

    def record(self) -> dict[str, Any] | None:
        """What a saved policy and the weights record of the env (None: navlearn's world)."""
        if self.own_world:
            return None
        return {"id": self.env, "kwargs": self.kwargs, "module": self.env_module}

    @classmethod
    def from_record(cls, record: dict[str, Any] | None, vector: str = "sync") -> EnvConfig:
        """Inverse of :meth:`record`."""
        if not record:
            return cls(env_vector=vector)
        kwargs = record.get("kwargs") or {}
        return cls(
            env=str(record["id"]),
            env_kwargs=json.dumps(kwargs) if kwargs else "",
            env_module=str(record.get("module") or ""),
            env_vector=vector,
        )

    def flags(self) -> list[str]:
        """The command-line flags that give another process this env (bench/own_env.py gives them to `up`)."""
        out = [] if self.own_world else ["--env", self.env]
        if self.env_kwargs.strip():
            out += ["--env-kwargs", self.env_kwargs]
        if self.env_module:
            out += ["--env-module", self.env_module]
        if self.env_vector != "sync":
            out += ["--env-vector", self.env_vector]
        return out


def _import(module: str, flag: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise EnvError(
            f"{flag}: cannot import module {module!r} ({exc}); install the package or put its directory on "
            "PYTHONPATH"
        ) from None


def _factory(config: EnvConfig):
    """A zero-argument-plus-kwargs maker of the raw env: ``gymnasium.make`` of an id, or the callable."""
    import gymnasium as gym

    if config.env_module:
        _import(config.env_module, f"--env-module {config.env_module}")
    name = config.env
    if ":" in name:
        module_name, attr = name.split(":", 1)
        module = _import(module_name, f"--env {name}")
        target = getattr(module, attr, None)
        if target is None and attr not in gym.registry:
            raise EnvError(
                f"--env {name}: module {module_name!r} has no {attr!r} and registers no such Gymnasium id; "
                "give module:callable (a function returning an env) or module:Id"
            )
        if target is not None and callable(target):
            return target
        name = attr
    if name not in gym.registry:
        close = difflib.get_close_matches(name, list(gym.registry), n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise EnvError(
            f"--env {name}: not a registered Gymnasium id{hint}; give --env-module PKG when a package "
            "registers it on import, module:Id, or module:callable"
        )
    return functools.partial(gym.make, name)


def check_spaces(env: Any, name: str) -> None:
    """Raise :class:`EnvError` unless NNQL can act in ``env``: a ``Discrete`` action space."""
    from gymnasium import spaces

    action = env.action_space
    if isinstance(action, spaces.Discrete):
        if int(action.start) != 0:
            raise EnvError(
                f"--env {name}: actions Discrete({action.n}, start={action.start}); NNQL's actions are "
                "0..n-1: wrap the env so they start at 0"
            )
        return
    raise EnvError(
        f"--env {name}: its action space is {action}; NNQL learns one Q-value per discrete action, so it "
        "needs a Discrete action space: discretise the actions with a wrapper (a few fixed commands), or "
        "train a continuous-control method (SAC, TD3) instead"
    )


def make_env(config: EnvConfig) -> Any:
    """One copy of the env as NNQL takes it: the raw env checked (:func:`check_spaces`) and its
    observation flattened to one vector by ``gymnasium.wrappers.FlattenObservation`` unless it is one
    already."""
    from gymnasium import spaces
    from gymnasium.wrappers import FlattenObservation

    if config.own_world:
        raise EnvError("make_env is for a Gymnasium --env; navlearn's world is worlds.vector_env")
    try:
        env = _factory(config)(**config.kwargs)
    except EnvError:
        raise
    except Exception as exc:  # the user's env failed to build: say which and with what
        raise EnvError(
            f"--env {config.env} with --env-kwargs {config.kwargs}: building it failed "
            f"({type(exc).__name__}: {exc})"
        ) from None
    check_spaces(env, config.env)
    obs = env.observation_space
    if isinstance(obs, spaces.Box) and len(obs.shape) == 1:
        return env
    try:
        return FlattenObservation(env)
    except (NotImplementedError, TypeError, ValueError) as exc:
        env.close()
        raise EnvError(
            f"--env {config.env}: gymnasium cannot flatten its observation space {obs} to a vector "
            f"({type(exc).__name__}{': ' if str(exc) else ''}{exc}); wrap it so it observes only Box, "
            "Discrete, MultiBinary, Dict or Tuple parts (a Text part such as MiniGrid's mission cannot "
            "be: its ImgObsWrapper drops it)"
        ) from None


IMAGE_CHANNELS = (1, 3, 4)
"""an image's channel counts: grey, RGB, RGB-D or RGBA (Stable-Baselines3's ``is_image_space``)"""
IMAGE_SCALE = 1.0 / 255.0
"""what an image's uint8 values are multiplied by before the convolutions (0..255 to 0..1)"""


def image_description(space: Any) -> dict[str, Any] | None:
    """What the learner needs of an image observation space, or None when ``space`` is not one.

    An image is what Stable-Baselines3 calls one (``stable_baselines3.common.preprocessing.
    is_image_space`` with ``check_channels=True``; SB3 is not imported, only its rule followed, so every
    tool agrees on which envs get a CNN): a ``Box`` of 3 dimensions, dtype uint8, low 0 and high 255
    everywhere, whose channels (the smallest dimension first, as SB3's ``is_image_space_channels_first``
    decides: first if it is the smallest, last otherwise) number 1, 3 or 4. Its description:
    ``shape`` (the space's own shape, so the flat vector of ``FlattenObservation``, which flattens in C
    order, reshapes to it), ``channels_last`` (H, W, C) or not (C, H, W), and ``scale`` (1/255).
    A ``Dict`` observation with an image part is not described (it is learned by the MLP, flattened):
    the part's place in the flat vector would be one more layout to record."""
    from gymnasium import spaces

    if not isinstance(space, spaces.Box) or len(space.shape) != 3 or space.dtype != np.uint8:
        return None
    if np.any(space.low != 0) or np.any(space.high != 255):
        return None
    channels_last = int(np.argmin(space.shape)) != 0
    channels = space.shape[-1] if channels_last else space.shape[0]
    if channels not in IMAGE_CHANNELS:
        return None
    return {"shape": [int(n) for n in space.shape], "channels_last": channels_last, "scale": IMAGE_SCALE}


def image_hwc(image: dict[str, Any]) -> tuple[int, int, int]:
    """(height, width, channels) of an :func:`image_description`."""
    shape = [int(n) for n in image["shape"]]
    height, width, channels = shape if image["channels_last"] else (shape[1], shape[2], shape[0])
    return height, width, channels


class EnvSpaces(NamedTuple):
    """What NNQL's networks are sized by: the flat observation's width, the actions, and the image
    the flat observation is (:func:`image_description`; None when it is not one)."""

    obs_dim: int
    n_actions: int
    image: dict[str, Any] | None


def describe_env(config: EnvConfig) -> EnvSpaces:
    """:class:`EnvSpaces` of the env as NNQL takes it (one copy built and closed); the image is read
    from the observation space before ``FlattenObservation``."""
    from gymnasium.wrappers import FlattenObservation

    env = make_env(config)
    try:
        raw = env.env.observation_space if isinstance(env, FlattenObservation) else env.observation_space
        obs_dim = int(np.prod(env.observation_space.shape))
        return EnvSpaces(obs_dim, int(env.action_space.n), image_description(raw))
    finally:
        env.close()


def env_spaces(config: EnvConfig) -> tuple[int, int]:
    """(observation width, number of actions) of the env as NNQL takes it (:func:`describe_env`)."""
    spaces = describe_env(config)
    return spaces.obs_dim, spaces.n_actions


def make_vector_env(config: EnvConfig, num_envs: int) -> Any:
    """``num_envs`` copies of :func:`make_env` in a ``gymnasium.vector`` env in ``SAME_STEP``
    autoreset mode (``--env-vector``: sync or async; async starts its workers with ``spawn``, so a
    Zenoh session or torch threads of the parent never leak into them)."""
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

    make_env(config).close()  # refuse a bad env here, with its sentence, not in a worker
    fns = [functools.partial(make_env, config)] * num_envs
    if config.env_vector == "async":
        return AsyncVectorEnv(fns, autoreset_mode=AutoresetMode.SAME_STEP, context="spawn")
    return SyncVectorEnv(fns, autoreset_mode=AutoresetMode.SAME_STEP)


def reward_threshold(config: EnvConfig) -> float | None:
    """The env's registered ``reward_threshold`` (None when it has no spec or none is set)."""
    env = make_env(config)
    try:
        spec = env.spec
        return None if spec is None or spec.reward_threshold is None else float(spec.reward_threshold)
    finally:
        env.close()
