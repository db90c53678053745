"""The learned reward drawn over a map, beside the true geodesic cost (`navlearn nirl reward`).

For every free cell of a task's map the robot is put at the cell centre with ``headings`` evenly
spaced headings; its observation is built as the world builds it (exact ranges from
``worlds.sensors.cast_rays``, the squashed goal distance, the goal bearing) and the reward network
saved with a NIRL run (``reward.safetensors``) scores every action there. The cell's value is the
reward of the best action, averaged over headings. Beside it: the true cost-to-go, the geodesic
(8-connected grid) distance to the goal. If the learned reward is a reward for this task, it rises
as the geodesic cost falls; ``spearman`` measures that over the free cells. A run with a progress
potential (``potential.safetensors``, ``NIRLConfig.fixed_reward = "progress"``: the potential that
shapes the reward NIRL's policy learns on once the reward is fixed) gets a third panel, the
potential per cell (mean over headings), and its own rank correlation with minus the geodesic cost.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from agents.nirl import persistence
from agents.nirl.networks import RewardNetwork
from agents.nirl.persistence import REWARD_FILE
from agents.nirl.progress import ProgressPotential
from agents.planning import distance_field
from worlds.config import (
    LEGACY_OBSERVATION,
    NavConfig,
    observation_differences,
    saved_observation,
    with_observation,
)
from worlds.maps import Task
from worlds.sensors import cast_rays


@dataclass
class RewardMap:
    """Per-cell fields of one task (NaN where blocked or unreachable)."""

    task: Task
    learned: np.ndarray
    """(H, W) best action's learned reward, mean over headings"""
    geodesic: np.ndarray
    """(H, W) geodesic distance to the goal in metres"""
    spearman: float
    """rank correlation of learned reward and minus the geodesic cost over reachable free cells"""
    potential: np.ndarray | None = None
    """(H, W) the progress potential, mean over headings (runs that have one)"""
    potential_spearman: float = float("nan")
    """rank correlation of the potential and minus the geodesic cost over reachable free cells"""


def saved_config(run: Path) -> dict:
    """config.json of a NIRL run directory in the plain observation (the one this map can draw)."""
    config, weights = run / "config.json", run / REWARD_FILE
    if not weights.is_file() or not config.is_file():
        raise ValueError(f"{run}: no {REWARD_FILE} and config.json (is --run a NIRL run directory?)")
    saved = json.loads(config.read_text())
    if saved.get("reward_architecture") is None:
        raise ValueError(f"{config}: no reward_architecture (not written by NIRL)")
    plain = with_observation(NavConfig(), LEGACY_OBSERVATION)
    wrong = observation_differences(saved_observation(saved.get("observation")), plain, "plain")
    if wrong:
        raise ValueError(
            f"{config}: this run observes {', '.join(wrong)}; the map is drawn for runs in the plain "
            "observation (8 beams + goal, `nirl train --observation plain`) only, since an own-map "
            "subgoal depends on the path the robot drove to each cell"
        )
    return saved


def load_reward_network(run: str | Path) -> RewardNetwork:
    """The reward network of a NIRL run or policy directory (config.json + reward.safetensors)."""
    from safetensors.torch import load_file

    run = Path(run)
    network = RewardNetwork.from_architecture(saved_config(run)["reward_architecture"])
    network.mlp.load_state_dict(load_file(str(run / REWARD_FILE)))
    return network.eval()


def load_potential(run: str | Path) -> ProgressPotential | None:
    """The progress potential saved with a NIRL run in the plain observation (the one this map can
    draw: :func:`saved_config`'s checks), None if it has none."""
    saved_config(Path(run))
    return persistence.load_potential(run)


def observe_at(task: Task, nav: NavConfig, x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The noise-free observations (N, obs_dim) of robots at poses (x, y, theta) on ``task``, built
    as the world's kernel builds them (tests/test_nirl_cli.py holds them to the env's own)."""
    sensors = nav.sensors
    ranges = cast_rays(task.grid, x, y, theta, np.asarray(sensors.beam_angles), sensors.max_range)
    gx, gy = task.grid.cell_center(task.goal)
    ux, uy = gx - x, gy - y
    dist = np.hypot(ux, uy)
    c, s = np.cos(theta), np.sin(theta)
    safe = np.maximum(dist, 1e-9)
    sin_b = np.where(dist > 0, (-ux * s + uy * c) / safe, 0.0)
    cos_b = np.where(dist > 0, (ux * c + uy * s) / safe, 1.0)
    obs = np.column_stack([ranges / sensors.max_range, dist / (dist + sensors.max_range), sin_b, cos_b])
    return obs.astype(np.float32)


def observations(task: Task, nav: NavConfig, headings: int) -> tuple[np.ndarray, np.ndarray]:
    """Observations (n_cells * headings, obs_dim) at every free cell centre and heading, and the cells."""
    grid = task.grid
    cells = grid.free_cells()
    centres = np.array([grid.cell_center(tuple(c)) for c in cells])
    theta = np.repeat(
        np.linspace(-math.pi, math.pi, headings, endpoint=False)[None, :], len(cells), 0
    ).ravel()
    x, y = np.repeat(centres[:, 0], headings), np.repeat(centres[:, 1], headings)
    return observe_at(task, nav, x, y, theta), cells


def reward_map(
    network: RewardNetwork,
    task: Task,
    nav: NavConfig | None = None,
    headings: int = 8,
    potential: ProgressPotential | None = None,
) -> RewardMap:
    """The learned reward (and potential) and the geodesic cost of ``task`` (module docstring)."""
    nav = nav or NavConfig()
    obs, cells = observations(task, nav, headings)
    geodesic = distance_field(task.grid, task.goal, 8)
    reachable = np.isfinite(geodesic)
    with torch.no_grad():
        obs_t = torch.as_tensor(obs)
        learned, rho = _per_cell(network(obs_t).max(dim=1).values.numpy(), cells, headings, geodesic)
        if potential is not None:
            phi, phi_rho = _per_cell(potential(obs_t).numpy(), cells, headings, geodesic)
    geodesic = np.where(reachable, geodesic, np.nan)
    if potential is None:
        return RewardMap(task, learned, geodesic, rho)
    return RewardMap(task, learned, geodesic, rho, potential=phi, potential_spearman=phi_rho)


def _per_cell(values: np.ndarray, cells: np.ndarray, headings: int, geodesic: np.ndarray):
    """(H, W) mean over headings at the reachable free cells (NaN elsewhere), and its rank
    correlation with minus the geodesic cost."""
    from scipy.stats import spearmanr

    field = np.full(geodesic.shape, np.nan)
    field[cells[:, 0], cells[:, 1]] = values.reshape(len(cells), headings).mean(axis=1)
    reachable = np.isfinite(geodesic) & np.isfinite(field)
    field[~reachable] = np.nan
    if reachable.sum() <= 2:
        return field, float("nan")
    return field, float(spearmanr(field[reachable], -geodesic[reachable]).statistic)


def plot_reward_map(result: RewardMap, out: str | Path, title: str = "") -> Path:
    """PNG: the learned reward (left), the progress potential if the run has one, and the geodesic
    cost to the goal (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(result.learned, "learned reward (best action, mean over headings)", "viridis")]
    if result.potential is not None:
        panels.append((result.potential, "progress potential (shapes the fixed reward)", "viridis"))
    panels.append((result.geodesic, "true geodesic cost to the goal (m)", "viridis_r"))
    fig, axes = plt.subplots(1, len(panels), figsize=(5.5 * len(panels), 4.6))
    for ax, (field, name, cmap) in zip(axes, panels, strict=True):
        image = ax.imshow(field, cmap=cmap, origin="upper")
        ax.imshow(
            np.where(result.task.grid.blocked, 1.0, np.nan), cmap="Greys", vmin=0, vmax=1, origin="upper"
        )
        ax.plot(result.task.goal[1], result.task.goal[0], "r*", ms=14, label="goal")
        ax.set(title=name, xticks=[], yticks=[])
        fig.colorbar(image, ax=ax, shrink=0.8)
    axes[0].legend(loc="lower right", fontsize=8)
    extra = "" if result.potential is None else f", potential {result.potential_spearman:.2f}"
    fig.suptitle(f"{title}  Spearman(learned, -geodesic) = {result.spearman:.2f}{extra}")
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
