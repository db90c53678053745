"""Where the learners' networks, losses and sampled batches live: ``--device cpu|cuda|auto``."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

DEVICES = ("cpu", "cuda", "auto")
"""Accepted device names; ``cuda:N`` picks one GPU of several."""


def resolve_device(name: str) -> torch.device:
    """The torch device ``name`` asks for; ``auto`` is the first GPU when torch sees one, else the CPU."""
    import torch  # here, not at the top: the CLI's parsers read DEVICES, and torch costs seconds

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name != "cpu" and name != "cuda" and not name.startswith("cuda:"):
        raise ValueError(f"device {name!r}: expected one of {DEVICES} (or cuda:N)")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(
            f"device {name!r}: torch sees no CUDA GPU on this machine "
            f"(torch {torch.__version__}, CUDA build {torch.version.cuda}); use --device cpu or auto."
        )
    return torch.device(name)
