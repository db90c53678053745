"""The learner's hot loop on plain tensors: TorchRL's update without a TensorDict per step.

Why it exists: profiled with cProfile on the 2-core machine, one ``NNQLLearner.train_step``
(``DQNLoss`` forward + backward + Adam + ``SoftUpdate``) spent about half its CPU time in
TensorDict plumbing, not arithmetic: swapping functional parameters into the module
(``to_module``, three times per update), cloning the batch and ``step_mdp``, and the soft
updater's per-key lerp over TensorDicts; the replay's ``sample`` added a TensorDict index and
its metadata per update. ``LeanUpdate`` runs the same update on plain tensors:

- the online network is the loss's own (``loss.value_network_params`` *are* its parameters);
- the target network is a copy of it whose parameters share storage with the loss's
  ``target_value_network_params``, so ``loss.state_dict()``, checkpoints and the TorchRL path
  see every step (either path can continue from the other);
- the TD target is ``losses.td_target`` (TorchRL's TD(0) formula), the distance is TorchRL's
  ``distance_loss``, reduced as ``DQNLoss`` reduces it (importance-weighted mean under
  prioritized replay), the priority written back is the squared TD error, as ``DQNLoss`` and
  ``SarsaLoss`` write it;
- the target update is ``SoftUpdate``'s lerp (one foreach call) or ``HardUpdate``'s copy on
  its own counter.

The replay stays TorchRL's: its sampler draws the indices, its storage gathers them (once for
several updates when sampling is uniform), its ``update_priority`` takes the priorities.
tests/test_nnql_lean.py runs both paths on the same batches and compares every parameter, the
target network and the optimiser state.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.objectives import HardUpdate, SoftUpdate
from torchrl.objectives.utils import distance_loss

from agents.nnql.config import NNQLConfig
from agents.nnql.losses import td_target


class Batch(NamedTuple):
    """One update's transitions as plain tensors (leading dimension B)."""

    obs: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    next_obs: torch.Tensor
    terminated: torch.Tensor
    next_action: torch.Tensor | None = None
    """the action taken next (SARSA only)"""
    weight: torch.Tensor | None = None
    """importance-sampling weights (prioritized replay only)"""
    discount: torch.Tensor | None = None
    """factor of the bootstrap per transition, gamma^m (n-step returns only; else config.gamma)"""

    @classmethod
    def from_tensordict(cls, td: TensorDictBase, weight: torch.Tensor | None = None) -> Batch:
        """The fields of a transition TensorDict in TorchRL's layout (as the replay stores it)."""
        following = td.get("next")
        n = td.batch_size[0]
        next_action = following.get("action", None)
        discount = following.get("discount", None)
        return cls(
            obs=td.get("observation"),
            action=td.get("action").reshape(n),
            reward=following.get("reward").reshape(n),
            next_obs=following.get("observation"),
            terminated=following.get("terminated").reshape(n),
            next_action=None if next_action is None else next_action.reshape(n),
            weight=None if weight is None else weight.reshape(n),
            discount=None if discount is None else discount.reshape(n),
        )

    def to(self, device: torch.device) -> Batch:
        return Batch(*(None if t is None else t.to(device, non_blocking=True) for t in self))

    def slice(self, start: int, stop: int) -> Batch:
        return Batch(*(None if t is None else t[start:stop] for t in self))


class Step(NamedTuple):
    """What one update leaves behind (tensors: nothing is synchronised with the device)."""

    loss: torch.Tensor
    priority: torch.Tensor
    """squared TD error per transition (B,)"""
    grad_norm: torch.Tensor


class LeanUpdate:
    """One gradient update of the loss module's networks on a ``Batch``.

    Built over the learner's own parts: ``network`` (the online Q-network the loss wraps),
    ``loss`` (``DQNLoss`` or ``SarsaLoss`` made by ``losses.make_loss``), its ``optimizer``
    and its target ``updater``.
    """

    def __init__(
        self,
        config: NNQLConfig,
        network: nn.Module,
        loss: nn.Module,
        optimizer: torch.optim.Optimizer,
        updater: SoftUpdate | HardUpdate,
    ):
        self.config = config
        self.network = network
        self.optimizer = optimizer
        self.updater = updater
        self.params = list(network.parameters())
        online = list(loss.value_network_params.values(True, True))
        if len(online) != len(self.params) or any(
            a is not b for a, b in zip(online, self.params, strict=True)
        ):
            raise ValueError("the loss module does not train the network's own parameters")
        self.target_params = list(loss.target_value_network_params.values(True, True))
        self.target = copy.deepcopy(network).requires_grad_(False)
        for param, shared in zip(self.target.parameters(), self.target_params, strict=True):
            param.data = shared  # same storage: the updater and the loss see what this one writes
        self.max_norm = config.grad_clip if config.grad_clip > 0 else float("inf")

    def next_value(self, batch: Batch) -> torch.Tensor:
        """V(s') of the TD target: SARSA's taken action, double Q's online argmax, or the max."""
        next_q = self.target(batch.next_obs)
        if self.config.sarsa:
            return next_q.gather(-1, batch.next_action.long().unsqueeze(-1)).squeeze(-1)
        if self.config.double_q:
            chosen = self.network(batch.next_obs).argmax(-1, keepdim=True)
            return next_q.gather(-1, chosen).squeeze(-1)
        return next_q.max(-1).values

    def loss(self, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """The TD loss (reduced as DQNLoss reduces it) and the squared TD error per transition."""
        predicted = self.network(batch.obs).gather(-1, batch.action.long().unsqueeze(-1)).squeeze(-1)
        with torch.no_grad():
            gamma = self.config.gamma if batch.discount is None else batch.discount
            target = td_target(batch.reward, batch.terminated, self.next_value(batch), gamma)
            priority = (predicted - target).pow(2)
        distance = distance_loss(predicted, target, self.config.loss_function)
        if batch.weight is None:
            return distance.mean(), priority
        return (distance * batch.weight).sum() / batch.weight.sum(), priority

    def __call__(self, batch: Batch) -> Step:
        loss, priority = self.loss(batch)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = nn.utils.clip_grad_norm_(self.params, self.max_norm, foreach=True)
        self.optimizer.step()
        self.update_target()
        return Step(loss.detach(), priority, grad_norm)

    @torch.no_grad()
    def update_target(self) -> None:
        """SoftUpdate's lerp (weight 1 - eps, as it computes it) or HardUpdate's counted copy."""
        updater = self.updater
        if isinstance(updater, SoftUpdate):
            torch._foreach_lerp_(self.target_params, self.params, 1 - updater.eps)
            return
        if updater.counter == updater.value_network_update_interval:
            torch._foreach_copy_(self.target_params, self.params)
            updater.counter = 0
        else:
            updater.counter += 1
