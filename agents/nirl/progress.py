"""A progress potential learned from the demonstrations, for the fixed-reward phase's shaping.

What it is. A demonstrated episode that reaches the goal tells, at each of its states, how many
steps the expert still needed: ``k``. If the expert pays one unit per step (it drives to the goal
as fast as it can, the premise of every shortest-path demonstrator), its discounted value there is
``-(1 - gamma^k) / (1 - gamma)``. ``ProgressPotential`` regresses that value on the observation, so
it generalises to states and maps no demonstration visited - it is a function of what the robot
perceives (goal distance and bearing, the subgoal from its own map, free space), never of the
true map. Why (``bench/nirl.py --diagnose``): IQ-Learn's implicit reward does not
transfer - held-out expert steps earn less (-0.67) than the learner's own (-0.31).

How it is used (``NIRLConfig.fixed_reward = "progress"``, the default): once the reward is fixed
(``fix_reward_after``), NNQL-style soft Q-learning learns on the potential-based
shaping ``F(s, s') = gamma Phi(s') - Phi(s)`` (Ng, Harada & Russell, ICML 1999: it leaves the
optimal policy unchanged) on top of a unit step cost, with ``Phi = 0`` at the goal and the
never-arriving value ``-1 / (1 - gamma)`` in the collision's absorbing state. Shaping rewards built
from demonstrations: Brys, Harutyunyan, Suay, Chernova, Taylor & Nowe, "Reinforcement Learning
from Demonstration through Shaping", IJCAI 2015; a state-only reward term in the spirit of AIRL's
``g(s) + gamma h(s') - h(s)`` (Fu, Luo & Levine, ICLR 2018), whose ``h`` recovers the expert's value.
The environment's own reward is never read.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torchrl.modules import MLP

from agents.nnql.networks import activation_class


def steps_to_go(n_steps: int, reached_goal: bool) -> np.ndarray:
    """(n_steps,) int64: steps the expert still took from each state (``n, n - 1, ..., 1``) when the
    episode ended at the goal; zeros (unknown) otherwise."""
    if not reached_goal:
        return np.zeros(n_steps, dtype=np.int64)
    return np.arange(n_steps, 0, -1, dtype=np.int64)


def unit_cost_value(to_go: torch.Tensor, gamma: float) -> torch.Tensor:
    """The expert's discounted value ``-(1 - gamma^k) / (1 - gamma)`` at unit cost per step."""
    return -(1.0 - gamma ** to_go.to(torch.float32)) / (1.0 - gamma)


class ProgressPotential(nn.Module):
    """``Phi(s)``: the expert's unit-cost value regressed on the observation's features from index
    ``first_input`` on, (N,): all of them (0), or with ``first_input`` = the number of range readings
    the goal's and the subgoal's distance and bearing only (``NIRLConfig.potential_inputs = "goal"``)."""

    def __init__(self, obs_dim: int, hidden_sizes, activation: str, gamma: float, first_input: int = 0):
        super().__init__()
        if not 0 <= first_input < obs_dim:
            raise ValueError(
                f"ProgressPotential: first_input={first_input} outside the {obs_dim} observation features"
            )
        self.architecture = {
            "obs_dim": int(obs_dim),
            "hidden_sizes": [int(h) for h in hidden_sizes],
            "activation": activation,
            "gamma": float(gamma),
            "first_input": int(first_input),
        }
        self.first_input = int(first_input)
        self.mlp = MLP(
            in_features=obs_dim - self.first_input, out_features=1, num_cells=list(hidden_sizes),
            activation_class=activation_class(activation),
        )  # fmt: skip
        self.scale = 1.0 / (1.0 - gamma)  # the net outputs values in units of 1 / (1 - gamma)

    @classmethod
    def from_architecture(cls, architecture: dict) -> ProgressPotential:
        """The potential :attr:`architecture` describes (weights not loaded; runs saved before
        ``first_input`` existed read every feature)."""
        return cls(architecture["obs_dim"], architecture["hidden_sizes"], architecture["activation"],
                   architecture["gamma"], architecture.get("first_input", 0))  # fmt: skip

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.scale * self.mlp(obs[..., self.first_input :]).squeeze(-1)


def potential_loss(potential: ProgressPotential, obs: torch.Tensor, to_go: torch.Tensor, gamma: float):
    """Mean squared error (in units of ``1 / (1 - gamma)``) on the steps whose steps-to-go are known."""
    known = to_go > 0
    if not bool(known.any()):
        return None
    target = unit_cost_value(to_go[known], gamma)
    return ((potential(obs[known]) - target) / potential.scale).pow(2).mean()


def shaped_progress_reward(
    potential: ProgressPotential,
    obs: torch.Tensor,
    next_obs: torch.Tensor,
    terminated: torch.Tensor,
    at_goal: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """``-1 + gamma Phi(s') - Phi(s)`` per step, (N,), with ``Phi(s') = 0`` at the goal and
    ``-1 / (1 - gamma)`` (never arriving) after a collision; 0 along a path the potential
    fits exactly, negative for steps that lose progress."""
    with torch.no_grad():
        phi, phi_next = potential(obs), potential(next_obs)
        terminated = terminated.reshape(-1).bool()
        end = torch.where(at_goal, torch.zeros_like(phi_next), torch.full_like(phi_next, -potential.scale))
        phi_next = torch.where(terminated, end, phi_next)
        return -1.0 + gamma * phi_next - phi
