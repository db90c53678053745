"""Configuration of behaviour cloning (no torch import, so the CLI can read the defaults fast)."""

from __future__ import annotations

from dataclasses import dataclass, field

from agents.mlp import ACTIVATION_NAMES


@dataclass(frozen=True)
class ImitationConfig:
    """Behaviour cloning of the expert's actions."""

    hidden_sizes: tuple[int, ...] = (128, 128)
    """widths of the hidden layers"""
    activation: str = field(default="relu", metadata={"choices": ACTIVATION_NAMES})
    """hidden-layer activation: relu, tanh or elu"""
    lr: float = 1e-3
    """Adam learning rate"""
    weight_decay: float = 1e-5
    """L2 penalty (Adam's weight_decay)"""
    batch_size: int = 512
    """minibatch size (steps)"""
    max_epochs: int = 200
    """upper bound on passes over the training set"""
    patience: int = 15
    """stop after this many epochs without a better validation loss"""
    val_fraction: float = 0.2
    """share of episodes held out for validation"""
    seed: int = 0
    """seed of the split, the initial weights and the minibatch order"""
    torch_threads: int = 1
    """torch intra-op threads while training (small MLPs run fastest on one; set for the process)"""

    def __post_init__(self) -> None:
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"hidden_sizes must be positive layer widths, got {self.hidden_sizes}")
        if self.activation not in ACTIVATION_NAMES:
            raise ValueError(f"activation must be one of {ACTIVATION_NAMES}, got {self.activation!r}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
