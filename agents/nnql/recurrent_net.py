"""The recurrent Q-network (R2D2-style NNQL): MLP encoder -> LSTM -> MLP Q head.

The LSTM is TorchRL's ``LSTMModule`` (the recurrent DQN tutorial's building block), run in
recurrent mode over ``(B, T)`` TensorDicts: it starts every row from the state stored at its
first step (``is_init``), which is how replayed sequences restart from the state the actor
had (R2D2's stored state). ``hidden_sizes[0]`` is the encoder's width, ``hidden_sizes[1:]``
the head's hidden layers. The architecture dict is the feed-forward one plus ``lstm_size``;
agents/nnql/recurrent_policy.py runs the same weights in numpy.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict
from torch import nn
from torchrl.modules import MLP, LSTMModule, set_recurrent_mode

from agents.nnql.config import NNQLConfig
from agents.nnql.networks import activation_class

State = tuple[torch.Tensor, torch.Tensor]


class RecurrentQNetwork(nn.Module):
    """``unroll(obs (B, T, obs_dim), (h, c) (B, lstm_size) each) -> Q (B, T, n_actions), (h, c)``."""

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        hidden_sizes: list[int] | tuple[int, ...],
        activation: str,
        lstm_size: int,
    ):
        super().__init__()
        hidden = [int(h) for h in hidden_sizes]
        act = activation_class(activation)
        self.encoder = MLP(
            in_features=obs_dim, out_features=hidden[0], num_cells=[], activation_class=act,
            activate_last_layer=True,
        )  # fmt: skip
        self.lstm = LSTMModule(
            input_size=hidden[0], hidden_size=int(lstm_size), in_key="embedding", out_key="features"
        )
        self.head = MLP(
            in_features=int(lstm_size), out_features=n_actions, num_cells=hidden[1:], activation_class=act
        )
        self.architecture = {
            "obs_dim": int(obs_dim),
            "n_actions": int(n_actions),
            "hidden_sizes": hidden,
            "activation": activation,
            "lstm_size": int(lstm_size),
        }

    @classmethod
    def from_config(cls, config: NNQLConfig, obs_dim: int, n_actions: int) -> RecurrentQNetwork:
        return cls(obs_dim, n_actions, config.hidden_sizes, config.activation, config.lstm_size)

    @classmethod
    def from_architecture(cls, architecture: dict[str, Any]) -> RecurrentQNetwork:
        keys = ("obs_dim", "n_actions", "hidden_sizes", "activation", "lstm_size")
        return cls(*(architecture[k] for k in keys))

    def unroll(self, obs: torch.Tensor, state: State) -> tuple[torch.Tensor, State]:
        """Q-values along ``T`` steps of ``B`` sequences from ``state``, and the state after them."""
        b, t = obs.shape[:2]
        h0, c0 = state
        is_init = torch.zeros(b, t, 1, dtype=torch.bool, device=obs.device)
        is_init[:, 0] = True
        td = TensorDict(
            {
                "embedding": self.encoder(obs),
                # LSTMModule reads the stored state where is_init is set: only the first step here
                "recurrent_state_h": h0[:, None, None].expand(b, t, 1, h0.shape[-1]),
                "recurrent_state_c": c0[:, None, None].expand(b, t, 1, c0.shape[-1]),
                "is_init": is_init,
            },
            batch_size=[b, t],
        )
        with set_recurrent_mode(True):
            out = self.lstm(td)
        last = out.get("next")[:, -1]
        state = last["recurrent_state_h"][:, 0], last["recurrent_state_c"][:, 0]
        return self.head(out.get("features")), state
