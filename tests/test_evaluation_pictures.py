"""The evaluation's pictures show what they say (issue 43): a dynamic set's path picture draws the
moving discs (their tracks and where they ended), its key sits outside every map panel, and the
own-map patch panels carry a colour key."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.plots import paths_figure, plot_paths
from worlds.config import LEARNING_NAV
from worlds.render import draw_patch


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_the_dynamic_sets_path_picture_draws_the_discs_and_keeps_its_key_off_the_maps(tmp_path):
    result = evaluate(lambda obs: np.zeros(len(obs), dtype=np.int64), make_eval_set("dynamic", 4, seed=0),
                      LEARNING_NAV)  # fmt: skip
    episodes = result.episodes["dynamic"]
    with_discs = [e for e in episodes if e.disc_tracks is not None]
    assert with_discs, "the dynamic set has moving discs"
    for ep in with_discs:
        assert ep.disc_tracks.shape[0] == len(ep.trajectory) and ep.disc_tracks.shape[2] == 3
        assert ep.disc_tracks.shape[1] >= 1 and np.all(ep.disc_tracks[:, :, 2] > 0)
    moved = max(float(np.abs(e.disc_tracks[-1, :, :2] - e.disc_tracks[0, :, :2]).max()) for e in with_discs)
    assert moved > 0.05, "the discs' tracks move"

    fig = paths_figure(result, "dynamic", n_episodes=4)
    fig.canvas.draw()
    maps = [ax for ax in fig.axes if ax.get_visible()]
    discs = [p for ax in maps for p in ax.patches if isinstance(p, Circle) and p.get_label() == "_disc"]
    assert len(discs) == sum(e.disc_tracks.shape[1] for e in with_discs)
    legend = fig.legends[0]
    assert "moving disc: track" in [t.get_text() for t in legend.get_texts()]
    box = legend.get_window_extent()
    assert not any(_overlaps(box, ax.get_window_extent()) for ax in maps), "the key covers a map"
    assert all(ax.get_legend() is None for ax in maps)
    plt.close(fig)
    assert plot_paths(result, "dynamic", tmp_path / "paths.png", n_episodes=4).stat().st_size > 10_000

    static = evaluate(lambda obs: np.zeros(len(obs), dtype=np.int64), make_eval_set("unseen", 2, seed=0),
                      LEARNING_NAV)  # fmt: skip
    assert all(e.disc_tracks is None for e in static.episodes["unseen"])


def test_the_patch_panels_have_a_colour_key():
    fig = plt.figure()
    size = 5
    draw_patch(fig, np.linspace(0, 1, 2 * size * size), size)
    keys = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(keys) == 2
    labels = [t.get_text() for t in keys[0].get_xticklabels()]
    assert labels == ["seen free", "unknown", "seen blocked"]
    plt.close(fig)
