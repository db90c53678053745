"""Pictures of the world with matplotlib: map, robot, beams, moving discs, trajectory."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from worlds.maps import Cell, GridMap

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from worlds.batch import NavBatch


def draw(
    ax: Axes | None,
    grid: GridMap,
    trajectory: np.ndarray | Sequence[tuple[float, float]] | None = None,
    pose: tuple[float, float, float] | None = None,
    beams: np.ndarray | None = None,
    obstacles: np.ndarray | None = None,
    start: Cell | None = None,
    goal: Cell | None = None,
    robot_radius: float = 0.25,
    title: str | None = None,
    sectors: Sequence[np.ndarray] = (),
    subgoal: tuple[float, float] | None = None,
) -> Figure:
    """Draw ``grid`` (blocked cells dark), the ``trajectory`` ((n, 2) x, y in m), the robot at
    ``pose`` (x, y, theta) with its ``beams`` ((k, 2) end points), moving ``obstacles`` ((k, 3)
    x, y, radius), and the ``start``/``goal`` cells; with sector minima, each reading's arc across
    its sector (``sectors``: one (m, 2) polyline each), and the ``subgoal`` (x, y) the robot
    observes. Returns the figure (a new one when ``ax`` is None). Axes are metres with y growing
    downwards, as rows do."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    if ax is None:
        scale = 6.0 / max(grid.shape)
        fig, ax = plt.subplots(
            figsize=(max(3.0, grid.width * scale + 1), max(3.0, grid.height * scale + 0.6))
        )
    else:
        fig = ax.figure
    cs = grid.cell_size
    extent = (0, grid.width * cs, grid.height * cs, 0)
    ax.imshow(grid.blocked, cmap="Greys", vmin=0, vmax=1.3, extent=extent, interpolation="nearest")
    if start is not None:
        ax.add_patch(Circle(grid.cell_center(start), 0.35 * cs, color="tab:blue", alpha=0.5, label="start"))
    if goal is not None:
        ax.add_patch(Circle(grid.cell_center(goal), 0.35 * cs, color="tab:green", alpha=0.8, label="goal"))
    if trajectory is not None and len(trajectory) > 1:
        path = np.asarray(trajectory, dtype=float)
        ax.plot(path[:, 0], path[:, 1], "-", color="tab:blue", lw=1.5, label="trajectory")
    if obstacles is not None:
        for x, y, r in np.asarray(obstacles, dtype=float).reshape(-1, 3):
            ax.add_patch(Circle((x, y), r, color="tab:orange", alpha=0.9))
    if pose is not None:
        x, y, theta = pose
        if beams is not None:
            for bx, by in np.asarray(beams, dtype=float).reshape(-1, 2):
                ax.plot([x, bx], [y, by], "-", color="tab:red", lw=0.7, alpha=0.7)
                ax.plot(bx, by, ".", color="tab:red", ms=3)
        for arc in sectors:
            ax.plot(arc[:, 0], arc[:, 1], "-", color="tab:red", lw=1.2, alpha=0.8)
        ax.add_patch(Circle((x, y), robot_radius, color="tab:purple", zorder=5))
        ax.plot([x, x + 1.6 * robot_radius * np.cos(theta)], [y, y + 1.6 * robot_radius * np.sin(theta)],
                "-", color="white", lw=1.5, zorder=6)  # fmt: skip
    if subgoal is not None:
        ax.plot(*subgoal, "*", color="tab:green", ms=12, mec="black", zorder=7, label="subgoal")
    handles = [h for h in ax.patches if h.get_label() in ("start", "goal")]
    handles += [line for line in ax.lines if line.get_label() in ("trajectory", "subgoal")]
    if obstacles is not None and len(np.asarray(obstacles).reshape(-1, 3)):
        handles.append(Circle((0, 0), 1, color="tab:orange", label="moving disc"))
    if handles:
        # beside the map, never over it (a legend inside once covered a goal)
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0, fontsize=7)
    ax.set_xlim(0, grid.width * cs)
    ax.set_ylim(grid.height * cs, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if title:
        ax.set_title(title, fontsize=9)
    return fig


def beam_endpoints(batch: NavBatch, i: int) -> np.ndarray:
    """End points (k, 2) of robot ``i``'s beams as it last measured them."""
    cfg = batch.config.sensors
    ranges = batch.obs[i, : cfg.n_beams].astype(float) * cfg.max_range
    angles = batch.theta[i] + cfg.beam_angles
    return np.stack([batch.x[i] + ranges * np.cos(angles), batch.y[i] + ranges * np.sin(angles)], axis=1)


def sector_arcs(batch: NavBatch, i: int, points: int = 8) -> list[np.ndarray]:
    """With sector minima (``sensors.rays_per_beam`` > 1): per reading of robot ``i``, the arc
    at the range it read across its sector, ``points`` (x, y) points each; else none."""
    cfg = batch.config.sensors
    if cfg.rays_per_beam == 1:
        return []
    ranges = batch.obs[i, : cfg.n_beams].astype(float) * cfg.max_range
    half = cfg.fov / cfg.n_beams / 2
    arcs = []
    for reading, centre in zip(ranges, batch.theta[i] + cfg.beam_angles, strict=True):
        angles = np.linspace(centre - half, centre + half, points)
        arcs.append(
            np.stack([batch.x[i] + reading * np.cos(angles), batch.y[i] + reading * np.sin(angles)], 1)
        )
    return arcs


def observed_subgoal(batch: NavBatch, i: int) -> tuple[float, float] | None:
    """The subgoal (x, y in m) robot ``i`` observes now, when its observation has one."""
    if batch.perception is None or batch.config.observation.subgoal == "none":
        return None
    x, y = batch.perception.waypoint[i]
    return float(x), float(y)


def draw_robot(ax: Axes | None, batch: NavBatch, i: int, trajectory=None, title: str | None = None) -> Figure:
    """Draw robot ``i`` of a batch in its current episode (with its sectors and subgoal, if any)."""
    task = batch.task(i)
    return draw(
        ax, task.grid, trajectory=trajectory, pose=(batch.x[i], batch.y[i], batch.theta[i]),
        beams=beam_endpoints(batch, i), obstacles=batch.discs(i), start=task.start, goal=task.goal,
        robot_radius=batch.config.robot.radius, title=title, sectors=sector_arcs(batch, i),
        subgoal=observed_subgoal(batch, i),
    )  # fmt: skip


def render_rgb(batch: NavBatch, i: int, trajectory=None) -> np.ndarray:
    """Robot ``i``'s picture as an (h, w, 3) uint8 array (for ``render_mode="rgb_array"``)."""
    import matplotlib.pyplot as plt

    fig = draw_robot(None, batch, i, trajectory)
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return image


def draw_patch(fig: Figure, values: np.ndarray, size: int) -> None:
    """Add the egocentric patch of the robot's own map (the observation's ``2 * size**2`` patch
    values, :mod:`worlds.perception`) to the right of ``fig``: occupancy (black seen blocked, grey
    unknown, white seen free) and visits, heading up, the robot at the centre."""
    # (u back to front, v right to left, channel) -> rows front to back, columns left to right
    patch = np.asarray(values, dtype=float).reshape(size, size, 2)[::-1, ::-1]
    titles = ("own map: occupancy", "own map: visits")
    for k, (title, cmap) in enumerate(zip(titles, ("Greys", "Blues"), strict=True)):
        ax = fig.add_axes((1.02 + 0.42 * k, 0.3, 0.38, 0.38))
        image = ax.imshow(patch[:, :, k], cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax.plot([(size - 1) / 2], [(size - 1) / 2], marker="^", color="tab:purple", ms=7)
        ax.set(title=title, xticks=[], yticks=[])
        key = fig.colorbar(image, ax=ax, orientation="horizontal", fraction=0.08, pad=0.04)  # colour key
        if k == 0:  # occupancy values (worlds.perceive.PATCH_VALUE)
            key.set_ticks([0.0, 0.5, 1.0], labels=["seen free", "unknown", "seen blocked"], fontsize=6)
        else:  # 1 - 1 / (1 + visits)
            key.set_ticks([0.0, 0.5, 0.75, 1.0], labels=["0", "1", "3", "many"], fontsize=6)
            key.set_label("visits", fontsize=6)
