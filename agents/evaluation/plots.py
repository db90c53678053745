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
    """One PNG for ``family``: for each of ``n_episodes`` episodes, the policy's path (coloured by
    outcome) in one panel and grid A*'s shortest path beside it."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

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
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


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
    ax.legend(fontsize=8)
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
    policy version and wall time since the first launch. ``points`` are the evaluator's records
    (``evaluations.jsonl``: time, launch, model, policy_version, metrics per family); each launch of a
    resumed run is its own segment (no line across the gap), its start marked on the time axis; those
    of model :data:`REFERENCE` (a fixed saved policy) are drawn as horizontal lines."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    launches = sorted({p.get("launch", p["time"]) for p in points})
    start = min(launches[0], min(p["time"] for p in points))
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
            ("wall time since launch (min)", lambda p: (p["time"] - start) / 60),
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
                for ax in axes[:, col]:
                    ax.axvline((launch - start) / 60, ls=":", lw=1, color="black")
                axes[0, col].annotate(
                    "resumed" if k == 0 else "",
                    ((launch - start) / 60, 0.02),
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
    axes[0, 0].legend(fontsize=8, loc="upper left")
    where = ", ".join(families) if gym else "held-out maps"
    fig.suptitle(f"{', '.join(models).upper() or 'policies'} on {where} (greedy policy)")
    fig.tight_layout()
    return fig
