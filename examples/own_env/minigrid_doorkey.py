"""MiniGrid's DoorKey as navlearn takes it (docs/own-env.md): the agent's 7x7 egocentric view through
MiniGrid's own ``ImgObsWrapper`` (147 integers; the text mission is constant here), and
``info["is_success"]`` at the episode's end (MiniGrid rewards a success with ``1 - 0.9 * steps / max``
and says nothing else), so navlearn's evaluator reports a success rate:

    navlearn up --env examples.own_env.minigrid_doorkey:doorkey

Needs the ``minigrid`` extra (``pip install -e ".[minigrid]"``).
"""

from __future__ import annotations

import gymnasium as gym
import minigrid  # noqa: F401 - registers the MiniGrid ids
from minigrid.wrappers import ImgObsWrapper


class SuccessInfo(gym.Wrapper):
    """Adds ``info["is_success"]`` (a positive reward at termination: MiniGrid's success) at episode ends."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info = {**info, "is_success": bool(terminated and reward > 0)}
        return obs, reward, terminated, truncated, info


def doorkey(size: int = 5, **kwargs) -> gym.Env:
    """``MiniGrid-DoorKey-<size>x<size>-v0`` (5, 6, 8 or 16) with the image observation and is_success."""
    return SuccessInfo(ImgObsWrapper(gym.make(f"MiniGrid-DoorKey-{size}x{size}-v0", **kwargs)))
