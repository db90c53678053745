"""Bounds every decoded message must respect (nothing from the network is trusted)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    """Decoding limits; services build one from their own config (e.g. ``n_actions``)."""

    max_message_bytes: int = 64 * 2**20
    """Largest encoded message accepted, in bytes (a 2x256 MLP's weights are about 0.3 MB)."""
    max_string: int = 256
    """Longest string (ids, names, tags, dictionary keys and values), in characters."""
    max_items: int = 65_536
    """Most entries in any list or map (tensors in a weights update, episodes in a demo batch, ...)."""
    max_batch: int = 1 << 20
    """Most rows in one batch (transitions, or demonstration steps)."""
    max_obs_dim: int = 4096
    """Largest observation dimension."""
    max_ndim: int = 8
    """Most dimensions of any array."""
    max_depth: int = 8
    """Deepest nesting of JSON-like values (architecture configs, metrics)."""
    n_actions: int | None = None
    """Number of discrete actions: actions must lie in [0, n_actions). None only checks actions >= 0;
    services pass their robot's ``n_actions``."""


DEFAULT_LIMITS = Limits()
