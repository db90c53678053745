"""The reading shield (agents/shield.py): its geometry, its choice, and what it does in the world."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.shield import MARGINS, exit_distance, for_nav, reach_table
from services.cli import main
from worlds.config import LEARNING_NAV, SensorConfig
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome
from worlds.robot import wrap_angle

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


def _brute_reach(turn: float, centre: float, width: float, step: float, radius: float) -> float:
    """The farthest point of the swept capsule inside the sector, from a 2 mm grid of points (a
    lower bound: the grid misses the farthest corner by up to its spacing's worth of angle)."""
    h = 0.002
    xs = np.arange(-radius - step, radius + step + h, h)
    x, y = (a.ravel() for a in np.meshgrid(xs, xs))
    u = np.array([math.cos(turn), math.sin(turn)])
    t = np.clip(x * u[0] + y * u[1], 0.0, step)
    inside = np.hypot(x - t * u[0], y - t * u[1]) <= radius
    dev = np.abs((np.arctan2(y, x) - centre + math.pi) % (2 * math.pi) - math.pi)
    pick = inside & (dev <= width / 2)
    return float(np.hypot(x[pick], y[pick]).max())


def test_reach_is_the_capsules_farthest_point_in_each_sector():
    nav = LEARNING_NAV
    table = reach_table(nav)
    width = nav.sensors.fov / nav.sensors.n_beams
    assert table.shape == (nav.robot.n_actions, nav.sensors.n_beams)
    straight = int(np.argmin(np.abs(nav.robot.turns)))
    ahead = int(np.argmin(np.abs(nav.sensors.beam_angles)))
    assert table[straight, ahead] == pytest.approx(nav.robot.step + nav.robot.radius)
    behind = int(np.argmin(np.abs(np.abs(nav.sensors.beam_angles) - math.pi)))
    assert table[straight, behind] == pytest.approx(nav.robot.radius)
    for k, turn in enumerate(nav.robot.turns):
        for j in range(0, nav.sensors.n_beams, 5):
            brute = _brute_reach(turn, nav.sensors.beam_angles[j], width, nav.robot.step, nav.robot.radius)
            # the grid's points only reach into the sector's corners to within its spacing
            assert brute - 1e-9 <= table[k, j] <= brute + 0.006, (k, j)


def test_exit_distance_leaves_the_capsule_exactly_once():
    delta = np.linspace(-math.pi, math.pi, 721)
    rho = exit_distance(delta, 0.5, 0.25)
    for d, r in zip(delta, rho, strict=True):
        for f, inside in ((0.999, True), (1.001, False)):
            x, y = f * r * math.cos(d), f * r * math.sin(d)
            t = min(max(x, 0.0), 0.5)
            assert (math.hypot(x - t, y) <= 0.25) == inside, (d, r, f)


def test_choice_prefers_room_to_spare_then_the_capsule_then_turns_around():
    nav = LEARNING_NAV
    shield = for_nav(nav)
    assert MARGINS[0] > 0 and MARGINS[-1] == 0  # room to spare first, the robot's own capsule last
    n, k = nav.sensors.n_beams, nav.robot.n_actions
    step_reach = nav.robot.step + nav.robot.radius  # driving straight reaches this far ahead
    obs = np.zeros((4, 30), np.float32)
    obs[:, :n] = 1.0  # every reading at max range: everything is clear
    straight = int(np.argmin(np.abs(nav.robot.turns)))
    ahead = int(np.argmin(np.abs(nav.sensors.beam_angles)))
    obs[1, ahead] = 0.6 / nav.sensors.max_range  # a wall 0.6 m ahead: driving 0.5 m there hits it
    obs[2, ahead] = (step_reach + MARGINS[0] / 2) / nav.sensors.max_range  # clear, but not with room
    obs[2, n // 2 :] = (step_reach + MARGINS[0] / 2) / nav.sensors.max_range  # nor on the left
    obs[3, :n] = 0.3 / nav.sensors.max_range  # 0.05 m of room all round: nothing is clear
    outputs = np.zeros((4, k))
    outputs[:, straight] = 1.0  # the network wants to drive straight on
    outputs[:, 0] = 0.5  # then 90 degrees right
    room = shield.room(obs)
    assert room.shape == (len(MARGINS), 4, k)
    wide, tight = room[0] >= 0, room[-1] >= 0
    assert wide[0].all() and not tight[1, straight] and not tight[3].any()
    assert tight[2, straight] and not wide[2, straight] and wide[2, 0]
    chosen = shield.choose(outputs, obs)
    assert chosen[0] == straight  # nothing in the way: the network's choice
    assert chosen[1] == 0  # the wall: the next best clear action
    assert chosen[2] == 0  # straight on is clear but tight; the right has room to spare
    assert chosen[3] == nav.robot.turn_around == k  # boxed in: half a turn in place
    obs[2, : n // 2] = obs[2, n // 2]  # tight on the right too: clear at the last margin is enough
    assert shield.choose(outputs, obs)[2] == straight


def test_the_turn_around_turns_in_place_in_the_world():
    """The world executes the shield's turn-around as half a turn in place (no drive, so no wall
    can be hit), a Gymnasium step like any other (the drive's: tests/test_drive_motion.py)."""
    nav = replace(LEARNING_NAV, robot=replace(LEARNING_NAV.robot, trans_noise=0.0, rot_noise=0.0))
    env = NavigationEnv(nav, maps="rooms:16")
    x, y, theta = env.reset(seed=3)[1]["pose"]
    _, _, terminated, truncated, info = env.step(nav.robot.turn_around)
    assert not (terminated or truncated) and info["path_length"] == 0.0
    x1, y1, theta1 = info["pose"]
    assert (x1, y1) == (x, y) and math.isclose(abs(wrap_angle(theta1 - theta)), math.pi, abs_tol=1e-9)
    assert nav.robot.motion(nav.robot.turn_around) == (math.pi, 0.0)
    assert nav.robot.motion(0) == (float(nav.robot.turns[0]), nav.robot.step)
    with pytest.raises(ValueError, match=r"action 6 is not in \[0, 5\]"):
        nav.robot.motion(6)
    with pytest.raises(ValueError, match=r"actions must be integers in \[0, 5\]"):
        env.step(6)


def test_a_narrower_field_of_view_is_refused_naming_the_setting():
    nav = replace(LEARNING_NAV, sensors=SensorConfig(n_beams=24, n_rays=96, fov=math.pi))
    with pytest.raises(ValueError, match=r"sensors.fov=3.142.*--no-shield"):
        for_nav(nav)


def test_the_shield_cuts_the_shipped_networks_wall_collisions_in_the_world():
    """The shipped network on 150 episodes of 48-cell validation maps, with and without the shield
    (the same episodes): the network alone hits walls, through the shield it hits fewer and reaches
    the goal more often, and it changes nothing where the network was already clear."""
    es = make_eval_set("unseen", 150, seed=1, size=48)
    plain = load_policy(PRETRAINED)
    shielded = load_policy(PRETRAINED).use_shield(plain.nav_config(LEARNING_NAV))
    runs = {}
    for name, policy in (("plain", plain), ("shielded", shielded)):
        outcomes = np.array([e.outcome for e in evaluate(policy, es).episodes["unseen"]])
        runs[name] = outcomes
    hits = {k: int((v == int(Outcome.COLLISION_STATIC)).sum()) for k, v in runs.items()}
    goals = {k: int((v == int(Outcome.GOAL)).sum()) for k, v in runs.items()}
    assert hits["plain"] >= 2 and hits["shielded"] < hits["plain"], hits
    assert goals["shielded"] > goals["plain"], goals


def test_evaluate_shields_by_default_and_says_so(tmp_path, capsys):
    argv = ["evaluate", "--policy", str(PRETRAINED), "--maps", "unseen", "--episodes", "3"]
    assert main([*argv, "--out", str(tmp_path / "on")]) == 0
    assert "shielded" in capsys.readouterr().out
    assert json.loads((tmp_path / "on" / "eval.json").read_text())["shield"] is True
    assert main([*argv, "--no-shield", "--out", str(tmp_path / "off")]) == 0
    assert "shielded" not in capsys.readouterr().out
    assert json.loads((tmp_path / "off" / "eval.json").read_text())["shield"] is False
