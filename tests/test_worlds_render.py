"""Pictures: worlds.render and `navlearn world show`."""

from __future__ import annotations

import numpy as np
from PIL import Image

from services.cli import main
from worlds.config import NavConfig
from worlds.heuristics import goal_seeking_policy
from worlds.maps import parse_ascii
from worlds.render import draw
from worlds.vector_env import NavigationVectorEnv


def test_draw_returns_a_figure_with_everything():
    grid = parse_ascii("######\n#S..G#\n######\n")[0]
    fig = draw(
        None, grid, trajectory=[(1.5, 1.5), (2.0, 1.5)], pose=(2.0, 1.5, 0.0), beams=np.array([[5.0, 1.5]]),
        obstacles=np.array([[3.5, 1.5, 0.3]]), start=(1, 1), goal=(1, 4), title="t",
    )  # fmt: skip
    ax = fig.axes[0]
    assert ax.get_title() == "t" and len(ax.patches) >= 4 and ax.get_legend() is not None


def test_world_show_writes_a_png(tmp_path, capsys):
    out = tmp_path / "world.png"
    assert main(["world", "show", "--out", str(out), "--steps", "20", "--map", "rooms:12"]) == 0
    image = Image.open(out)
    assert image.size[0] > 300 and image.size[1] > 300
    assert "wrote" in capsys.readouterr().out


def test_world_show_bad_input_exits_2(tmp_path, capsys):
    assert main(["world", "show", "--map", "caves:16", "--out", str(tmp_path / "x.png")]) == 2
    assert "unknown map family" in capsys.readouterr().err
    assert main(["world", "show", "--steps", "0", "--out", str(tmp_path / "x.png")]) == 2


def test_goal_seeking_policy_reaches_goals():
    env = NavigationVectorEnv(64, NavConfig(pool_size=32), maps="rects:16", seed=0)
    obs, _ = env.reset()
    policy = goal_seeking_policy()
    outcomes = []
    for _ in range(150):
        obs, _, _, _, info = env.step(policy(obs))
        if "final_info" in info:
            outcomes += info["final_info"]["outcome"][info["_final_info"]].tolist()
    assert np.mean(np.asarray(outcomes) == 1) > 0.5  # random actions reach well under 10%
