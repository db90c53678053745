"""NNQL losses: TorchRL's DQNLoss for Q-learning, a small SARSA loss beside it.

Q-learning (the thesis' state-action value iteration over stored experience) is
TorchRL's ``DQNLoss`` with its TD(0) value estimator, target network
(``delay_value``) and optional double Q. TorchRL has no SARSA loss, so ``SarsaLoss``
reuses DQNLoss's plumbing (functional parameters, target copy, keys, priority
output, importance weights) and only swaps the bootstrap: the target network's value
of the next action actually taken, read from ``("next", "action")``.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.modules import QValueActor
from torchrl.objectives import DQNLoss, ValueEstimators
from torchrl.objectives.utils import distance_loss

from agents.nnql.config import NNQLConfig

PRIORITY_KEY = "td_error"
"""TensorDict key where both losses write the per-sample priority (squared TD error)."""


def td_target(
    reward: torch.Tensor, terminated: torch.Tensor, next_value: torch.Tensor, gamma: float | torch.Tensor
) -> torch.Tensor:
    """One-step TD target r + gamma * (1 - terminated) * V(s'); with n-step transitions (agents/nnql/nstep.py)
    r is the discounted n-step return and ``gamma`` the per-transition factor gamma^m.

    Truncated (time-limit) transitions are not terminated: they bootstrap, as they
    should - the episode was cut, the state still has a future. For Q-learning V(s')
    is max_a Q_target(s', a) (double Q: Q_target(s', argmax_a Q(s', a))); for SARSA it
    is Q_target(s', a') with a' the action taken next.
    """
    return reward + gamma * (~terminated.bool()).to(reward.dtype) * next_value


class SarsaLoss(DQNLoss):
    """On-policy SARSA TD loss: target r + gamma * Q_target(s', a'_taken).

    Needs ``("next", "action")`` in the batch. Writes the squared TD error to
    ``"td_error"`` like DQNLoss, so prioritized replay works the same.
    """

    def __init__(self, value_network: QValueActor, *, gamma: float, loss_function: str = "smooth_l1"):
        super().__init__(
            value_network,
            loss_function=loss_function,
            delay_value=True,
            double_dqn=False,
            action_space="categorical",
        )
        self.gamma = float(gamma)

    def _set_in_keys(self) -> None:
        super()._set_in_keys()
        self._in_keys = [*self._in_keys, ("next", self.tensor_keys.action)]

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        keys = self.tensor_keys
        current = tensordict.select(*self.value_network.in_keys).clone(False)
        with self.value_network_params.to_module(self.value_network, preserve_module_state=False):
            self.value_network(current)
        action = tensordict.get(keys.action).long().reshape(-1, 1)
        predicted = current.get(keys.action_value).gather(-1, action).squeeze(-1)

        following = tensordict.get("next").select(*self.value_network.in_keys).clone(False)
        with (
            torch.no_grad(),
            self.target_value_network_params.to_module(self.value_network, preserve_module_state=False),
        ):
            self.value_network(following)
        next_action = tensordict.get(("next", keys.action)).long().reshape(-1, 1)
        next_value = following.get(keys.action_value).gather(-1, next_action).squeeze(-1)
        reward = tensordict.get(("next", keys.reward)).reshape(predicted.shape)
        terminated = tensordict.get(("next", keys.terminated)).reshape(predicted.shape)
        target = td_target(reward, terminated, next_value, self.gamma).detach()

        with torch.no_grad():
            priority = (predicted - target).pow(2).unsqueeze(-1)
        tensordict.set(keys.priority, priority, inplace=True)
        loss = distance_loss(predicted, target, self.loss_function)
        weights = tensordict.get(keys.priority_weight, None)
        loss = self._reduce_loss(loss, tensordict=tensordict, weights=weights)
        return TensorDict(loss=loss)


def make_loss(config: NNQLConfig, actor: QValueActor) -> DQNLoss:
    """The loss the config asks for: DQNLoss (TD(0), target network, double Q) or SarsaLoss."""
    if config.sarsa:
        return SarsaLoss(actor, gamma=config.gamma, loss_function=config.loss_function)
    loss = DQNLoss(
        actor,
        loss_function=config.loss_function,
        delay_value=True,
        double_dqn=config.double_q,
        action_space="categorical",
    )
    loss.make_value_estimator(ValueEstimators.TD0, gamma=config.gamma)
    return loss
