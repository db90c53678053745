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


def test_learning_observation_is_drawn_sector_arcs_and_the_subgoal(tmp_path, capsys):
    from worlds.config import LEARNING_NAV
    from worlds.render import draw_robot, observed_subgoal, sector_arcs

    env = NavigationVectorEnv(1, config=LEARNING_NAV, maps="rooms:12", seed=2)
    env.reset(seed=2)
    env.step(np.array([2]))
    batch = env.batch
    arcs = sector_arcs(batch, 0)
    assert len(arcs) == LEARNING_NAV.sensors.n_beams == 24
    reading = batch.obs[0, 0] * LEARNING_NAV.sensors.max_range  # each arc lies at its sector's reading
    assert np.allclose(np.hypot(arcs[0][:, 0] - batch.x[0], arcs[0][:, 1] - batch.y[0]), reading, atol=1e-4)
    subgoal = observed_subgoal(batch, 0)
    assert subgoal is not None and np.allclose(subgoal, batch.perception.waypoint[0])
    labels = [line.get_label() for line in draw_robot(None, batch, 0).axes[0].lines]
    assert "subgoal" in labels
    env.close()
    plain = NavigationVectorEnv(1, config=NavConfig(), maps="rooms:12", seed=2)
    plain.reset(seed=2)
    assert sector_arcs(plain.batch, 0) == [] and observed_subgoal(plain.batch, 0) is None
    plain.close()
    out = tmp_path / "learning.png"
    assert main(["world", "show", "--learning", "--out", str(out), "--steps", "6", "--map", "rooms:12"]) == 0
    assert Image.open(out).size[0] > 300
