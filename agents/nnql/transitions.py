"""Transition batches into the replay's TensorDict layout, for every learner that stores transitions.

Transitions come as a TensorDict in TorchRL's layout (``observation``, ``action``,
``("next", "observation"|"reward"|"done"|"terminated"|"truncated")``), as a flat dict of arrays
(see ``TRANSITION_FIELDS``) or as any object with those attributes (a protocols TransitionBatch),
N transitions per call.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase

TRANSITION_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "truncated")
"""Flat transition batch (the field names of protocols' TransitionBatch): float32 (N, obs_dim), int (N,),
float (N,), float32 (N, obs_dim) - the true next observation, terminal one at episode ends -, bool (N,),
bool (N,); plus ``next_action`` int (N,) for the SARSA variant, ``env_ids`` int (N,) for n-step returns
(agents/nnql/nstep.py) and, once those are built, ``discount`` float32 (N,): the bootstrap's factor."""
OPTIONAL_FIELDS = ("next_action", "env_ids", "discount")


def flat_fields(batch: Any) -> dict[str, Any]:
    """The flat fields of a TorchRL-layout TensorDict, a mapping, or an object with those attributes."""
    if isinstance(batch, TensorDictBase):
        flat = {
            "obs": batch.get("observation"),
            "action": batch.get("action"),
            "reward": batch.get(("next", "reward")),
            "next_obs": batch.get(("next", "observation")),
            "terminated": batch.get(("next", "terminated")),
            "truncated": batch.get(("next", "truncated"), torch.zeros(batch.batch_size[0], dtype=torch.bool)),
        }
        for key, name in ((("next", "action"), "next_action"), (("next", "discount"), "discount")):
            if key in batch.keys(include_nested=True):
                flat[name] = batch.get(key)
        return flat
    if not isinstance(batch, Mapping):  # e.g. a protocols.messages.TransitionBatch
        batch = {
            name: getattr(batch, name)
            for name in (*TRANSITION_FIELDS, *OPTIONAL_FIELDS)
            if hasattr(batch, name)
        }
    missing = [name for name in TRANSITION_FIELDS if name not in batch]
    if missing:
        raise KeyError(f"transition batch lacks {missing}")
    return dict(batch)


def transitions_to_tensordict(batch: Any, obs_dim: int) -> TensorDict:
    """A transition batch (see ``flat_fields``) as a replay-ready TensorDict in TorchRL's layout."""
    flat = flat_fields(batch)
    n = len(flat["action"])
    obs = torch.as_tensor(np.asarray(flat["obs"], dtype=np.float32))
    next_obs = torch.as_tensor(np.asarray(flat["next_obs"], dtype=np.float32))
    if obs.shape != (n, obs_dim) or next_obs.shape != (n, obs_dim):
        raise ValueError(
            f"observations must be ({n}, {obs_dim}); got {tuple(obs.shape)}, {tuple(next_obs.shape)}"
        )
    terminated = torch.as_tensor(np.asarray(flat["terminated"], dtype=bool)).reshape(n, 1)
    truncated = torch.as_tensor(np.asarray(flat["truncated"], dtype=bool)).reshape(n, 1)
    following = {
        "observation": next_obs,
        "reward": torch.as_tensor(np.asarray(flat["reward"], dtype=np.float32)).reshape(n, 1),
        "terminated": terminated,
        "truncated": truncated,
        "done": terminated | truncated,
    }
    if "discount" in flat:
        following["discount"] = torch.as_tensor(np.asarray(flat["discount"], dtype=np.float32)).reshape(n, 1)
    if "next_action" in flat:
        following["action"] = torch.as_tensor(np.asarray(flat["next_action"], dtype=np.int64)).reshape(n)
    return TensorDict(
        {
            "observation": obs,
            "action": torch.as_tensor(np.asarray(flat["action"], dtype=np.int64)).reshape(n),
            "next": TensorDict(following, batch_size=[n]),
        },
        batch_size=[n],
    )
