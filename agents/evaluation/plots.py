"""Pictures of evaluations: learned paths beside grid A*'s, and learning curves.

All write PNG files with matplotlib's Agg backend (no display needed); ``plot_evaluations`` draws the
evaluator service's curve (services.evaluator).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.runner import EpisodeRecord, EvalResult
from agents.planning.astar import astar
from worlds.outcomes import OUTCOME_NAMES, Outcome
from worlds.render import draw

OUTCOME_COLOURS = {
    Outcome.GOAL: "tab:blue",
    Outcome.COLLISION_STATIC: "tab:red",
    Outcome.COLLISION_DYNAMIC: "tab:orange",
    Outcome.TIMEOUT: "tab:gray",
}


def _pick(episodes: Sequence[EpisodeRecord], n: int) -> list[EpisodeRecord]:
    """Up to ``n`` episodes, successes and failures in proportion, in evaluation order."""
    wins = [e for e in episodes if e.outcome == Outcome.GOAL]
    losses = [e for e in episodes if e.outcome != Outcome.GOAL]
    n_loss = min(len(losses), max(int(bool(losses)), round(n * len(losses) / max(len(episodes), 1))))
    n_win = min(len(wins), n - n_loss)
    n_loss = min(len(losses), n - n_win)
    chosen = {id(e) for e in wins[:n_win] + losses[:n_loss]}
    return [e for e in episodes if id(e) in chosen]


def plot_paths(
    result: EvalResult, family: str, out: str | Path, n_episodes: int = 6, label: str = "learned"
) -> Path:
    """One PNG for ``family`` (:func:`paths_figure`)."""
    import matplotlib.pyplot as plt

    fig = paths_figure(result, family, n_episodes, label)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def paths_figure(result: EvalResult, family: str, n_episodes: int = 6, label: str = "learned"):
    """For each of ``n_episodes`` episodes of ``family``, the policy's path (coloured by outcome) in
    one panel, with the moving discs' tracks on a dynamic set, and grid A*'s shortest path beside
    it; the key below the panels (never over a map)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    episodes = _pick(result.episodes[family], n_episodes)
    if not episodes:
        raise ValueError(f"no episodes for family {family!r}")
    per_row = min(3, len(episodes))
    rows = int(np.ceil(len(episodes) / per_row))
    fig, axes = plt.subplots(rows, 2 * per_row, figsize=(4.2 * per_row, 2.3 * rows + 0.6), squeeze=False)
    for ax in axes.ravel():
        ax.set_visible(False)
    for k, ep in enumerate(episodes):
        left, right = axes[k // per_row, 2 * (k % per_row)], axes[k // per_row, 2 * (k % per_row) + 1]
        left.set_visible(True)
        right.set_visible(True)
        grid, task = ep.task.grid, ep.task
        draw(left, grid, start=task.start, goal=task.goal)
        colour = OUTCOME_COLOURS.get(Outcome(ep.outcome), "black")
        left.plot(ep.trajectory[:, 0], ep.trajectory[:, 1], "-", color=colour, lw=1.6)
        draw_disc_tracks(left, ep.disc_tracks)
        left.set_title(f"{label}: {OUTCOME_NAMES[ep.outcome]}, {ep.path_length:.1f} m", fontsize=8)
        draw(right, grid, start=task.start, goal=task.goal)
        path = astar(grid, task.start, task.goal).path or []
        xy = np.array([grid.cell_center(c) for c in path])
        if len(xy):
            right.plot(xy[:, 0], xy[:, 1], "--", color="tab:green", lw=1.6)
        right.set_title(f"A*: {ep.shortest:.1f} m", fontsize=8)
        for ax in (left, right):
            ax.set_xlabel("")
            ax.set_ylabel("")
            ax.tick_params(labelsize=6)
    metrics = result.metrics[family]
    fig.suptitle(
        f"{family}: success {100 * metrics.success.value:.0f}% of {metrics.episodes}, SPL {metrics.spl:.2f}",
        fontsize=10,
    )
    handles = [
        Line2D([], [], color=colour, lw=1.6, label=f"{label}: {OUTCOME_NAMES[outcome]}")
        for outcome, colour in OUTCOME_COLOURS.items()
    ]  # the key below the panels, never over a map
    handles.append(Line2D([], [], color="tab:green", ls="--", lw=1.6, label="A* shortest path"))
    marks = {}  # start and goal, drawn by worlds.render.draw with a legend of each panel's own
    for ax in axes.ravel():
        marks.update({h.get_label(): h for h in ax.patches if h.get_label() in ("start", "goal")})
        if ax.get_legend() is not None:
            ax.get_legend().remove()  # one key for the figure, below the panels
    handles = [*marks.values(), *handles]
    if any(ep.disc_tracks is not None for ep in episodes):
        handles.append(Line2D([], [], color="tab:purple", lw=0.8, alpha=0.6, label="moving disc: track"))
        handles.append(Circle((0, 0), 1, color="tab:purple", alpha=0.8, label="moving disc: at the end"))
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=7, frameon=False)
    return fig


def draw_disc_tracks(ax, tracks: np.ndarray | None) -> None:
    """The moving discs of a dynamic episode on ``ax``: each disc's track (thin line) and the disc
    where it was when the episode ended (``tracks``: EpisodeRecord.disc_tracks; nothing if None)."""
    from matplotlib.patches import Circle

    if tracks is None or not tracks.shape[1]:
        return
    for k in range(tracks.shape[1]):
        ax.plot(tracks[:, k, 0], tracks[:, k, 1], "-", color="tab:purple", lw=0.8, alpha=0.6)
        x, y, r = tracks[-1, k]
        ax.add_patch(Circle((x, y), r, color="tab:purple", alpha=0.8, label="_disc"))


def plot_learning_curves(
    points: Sequence[tuple[float, dict]],
    out: str | Path,
    metric: str = "success",
    xlabel: str = "policy version",
) -> Path:
    """Plot ``metric`` per family against x. ``points`` are ``(x, metrics)`` pairs where
    ``metrics`` is ``EvalResult.to_dict()["metrics"]`` (or an EvalReport's); rates are drawn
    with their 95% interval as a band."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if not points:
        raise ValueError("no points to plot")
    fig, ax = plt.subplots(figsize=(6, 3.6))
    families = sorted({f for _, m in points for f in m})
    for family in families:
        xs, ys, lo, hi = [], [], [], []
        for x, metrics in sorted(points, key=lambda p: p[0]):
            value = metrics.get(family, {}).get(metric)
            if value is None:
                continue
            xs.append(x)
            if isinstance(value, dict):
                ys.append(value["value"])
                lo.append(value["low"])
                hi.append(value["high"])
            else:
                ys.append(value)
        (line,) = ax.plot(xs, ys, "o-", ms=3, label=family)
        if lo:
            ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(metric)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)  # off the curves
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


REFERENCE = "reference"
"""model field of points that evaluate a fixed saved policy (the imitation policy) once"""


def _headline(metrics: dict[str, Any]) -> tuple[float, float, float]:
    """(value, low, high) of the curve's top row: the success rate where there is one, else the mean
    return (a Gymnasium env without ``is_success``)."""
    if "success" in metrics:
        s = metrics["success"]
        return s["value"], s["low"], s["high"]
    r = metrics["return"]
    return r["mean"], r["low"], r["high"]


def plot_evaluations(points: list[dict[str, Any]], path: Path) -> Path:
    """The evaluator's learning curve (:func:`evaluations_figure`) written to ``path``."""
    import matplotlib.pyplot as plt

    fig = evaluations_figure(points)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(path)
    return path


def evaluations_figure(points: list[dict[str, Any]]):
    """The evaluator's learning curve: success rate (95% band) and path ratio to A* per family, against
    policy version and training time with the launches of a resumed run laid end to end (idle
    time between them left out, so the curve stays readable across resumes). ``points`` are the
    evaluator's records (``evaluations.jsonl``: time, launch, model, policy_version, metrics per
    family); each launch of a resumed run is its own segment (no line across the gap), its start
    marked on the time axis; those of model :data:`REFERENCE` (a fixed saved policy) are drawn as
    horizontal lines."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    launches = sorted({p.get("launch", p["time"]) for p in points})
    offset, elapsed = {}, 0.0  # each launch starts where the one before it ended: no idle gaps
    for launch in launches:
        times = [p["time"] for p in points if p.get("launch", p["time"]) == launch]
        first = min(launch, *times)
        offset[launch] = elapsed - first
        elapsed += max(times) - first

    def end_to_end(point: dict[str, Any]) -> float:
        """Seconds of training before ``point``, the launches laid end to end."""
        return point["time"] + offset[point.get("launch", point["time"])]

    families = sorted({f for p in points for f in p["metrics"]})
    models = sorted({p.get("model", "") for p in points if p.get("model") != REFERENCE})
    series = [(m, f) for m in models for f in families]
    references = [p for p in points if p.get("model") == REFERENCE]
    gym = any("return" in m for p in points for m in p["metrics"].values())
    """a Gymnasium --env (agents.evaluation.env_returns): episode length below, not path ratio"""
    returns = gym and any("success" not in m for p in points for m in p["metrics"].values())
    """such an env that says no success: the curve shows the mean return"""
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.4), sharey="row")
    for col, (xlabel, xof) in enumerate(
        (
            ("policy version (updates)", lambda p: p["policy_version"]),
            ("training time, launches end to end (min)", lambda p: end_to_end(p) / 60),
        )
    ):
        for model, family in series:
            color = None
            for launch in launches:  # one segment per launch: no line across a resumed run's gap
                rows = sorted(
                    (xof(p), p["metrics"][family])
                    for p in points
                    if family in p["metrics"]
                    and p.get("model", "") == model
                    and p.get("launch", p["time"]) == launch
                )
                if not rows:
                    continue
                name = f"{model} {family}".strip() if len(models) > 1 else family
                label = name if color is None else None
                xs = [x for x, _ in rows]
                top = [_headline(m) for _, m in rows]
                (line,) = axes[0, col].plot(xs, [t[0] for t in top], "o-", ms=3, label=label, color=color)
                color = line.get_color()
                axes[0, col].fill_between(
                    xs, [t[1] for t in top], [t[2] for t in top], color=color, alpha=0.2
                )
                second = "length" if gym else "path_ratio"
                ratio = [(x, m[second]) for x, m in rows if m.get(second) is not None]
                if ratio:
                    axes[1, col].plot(*zip(*ratio, strict=True), "o-", ms=3, color=color, label=label)
        for reference in references:  # a fixed policy (imitation): one horizontal line per family
            for family, metrics in reference["metrics"].items():
                label = f"{reference.get('name', REFERENCE)} {family}"
                axes[0, col].axhline(metrics["success"]["value"], ls="--", lw=1, color="gray", label=label)
                if metrics.get("path_ratio") is not None:
                    axes[1, col].axhline(metrics["path_ratio"], ls="--", lw=1, color="gray")
        if col == 1:
            for k, launch in enumerate(launches[1:]):  # where a resumed run started again
                at = (launch + offset[launch]) / 60 if launch + offset[launch] >= 0 else 0.0
                for ax in axes[:, col]:
                    ax.axvline(at, ls=":", lw=1, color="black")
                axes[0, col].annotate(
                    "resumed" if k == 0 else "",
                    (at, 0.02),
                    fontsize=7,
                    xytext=(2, 0),
                    textcoords="offset points",
                )
        if returns:  # a Gymnasium --env without is_success: mean return (95% CI)
            axes[0, col].set(ylabel="mean return" if col == 0 else None)
        else:
            axes[0, col].set(ylim=(0, 1.02), ylabel="success rate" if col == 0 else None)
        below = "episode length" if gym else "path length / A*"
        axes[1, col].set(xlabel=xlabel, ylabel=below if col == 0 else None)
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    axes[0, 1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1), borderaxespad=0)  # off the maps
    where = ", ".join(families) if gym else "held-out maps"
    fig.suptitle(f"{', '.join(models).upper() or 'policies'} on {where} (greedy policy)")
    fig.tight_layout()
    return fig
