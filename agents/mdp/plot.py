"""Pictures of grid MDP solutions: value heat map, greedy-policy arrows, a path.
matplotlib is imported inside the function, so importing this module is cheap."""

from __future__ import annotations

import math

import numpy as np

from worlds.gridworld import MOVES, GridDynamics
from worlds.maps import Cell


def plot_values(
    dynamics: GridDynamics,
    values: np.ndarray,
    policy: np.ndarray,
    path: list[Cell] | None = None,
    start: Cell | None = None,
    title: str = "",
    max_arrows: int = 50,
):
    """Heat map of ``values`` on the map (blocked cells black, free cells that
    cannot reach the goal grey), the greedy ``policy`` as arrows (on a coarser
    lattice when the map is wider than ``max_arrows`` cells), ``path`` as a red
    line from ``start`` (circle) to the goal (star). Returns the Figure."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    grid = dynamics.grid
    height, width = grid.shape
    rows, cols = dynamics.cells[:, 0], dynamics.cells[:, 1]
    image = np.full(grid.shape, np.nan)
    image[rows, cols] = values
    scale = max(6.0, min(12.0, max(height, width) / 8))
    fig, ax = plt.subplots(
        figsize=(scale * width / max(height, width) + 1.5, scale * height / max(height, width))
    )
    background = np.where(grid.blocked, 0.0, 0.75)
    ax.imshow(background, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    heat = ax.imshow(np.ma.masked_invalid(image), cmap="viridis", interpolation="nearest")
    fig.colorbar(heat, ax=ax, fraction=0.046, pad=0.04, label="V(s)")

    stride = max(1, math.ceil(max(height, width) / max_arrows))
    shown = (rows % stride == 0) & (cols % stride == 0)
    shown[dynamics.goal_state] = False
    moves = MOVES[np.asarray(policy)[shown]].astype(float)
    moves /= np.linalg.norm(moves, axis=1, keepdims=True)
    ax.quiver(
        cols[shown],
        rows[shown],
        moves[:, 1],
        moves[:, 0],
        angles="xy",
        scale_units="xy",
        scale=1.25 / stride,
        width=0.002 + 0.001 * min(stride, 3),
        color="white",
        alpha=0.85,
        pivot="middle",
    )
    if path:
        trace = np.asarray(path)
        ax.plot(
            trace[:, 1], trace[:, 0], color="red", linewidth=1.8, label=f"greedy path ({len(path) - 1} moves)"
        )
    if start is not None:
        ax.plot(start[1], start[0], "o", color="red", markersize=8, markeredgecolor="white", label="start")
    ax.plot(
        dynamics.goal[1],
        dynamics.goal[0],
        "*",
        color="gold",
        markersize=14,
        markeredgecolor="black",
        label="goal",
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=3, fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    return fig
