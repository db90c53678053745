"""The disc tracker behind the reading shield (agents/disc_tracker.py): finding discs in a scan,
predicting them, the choice it makes, how the runner drives it, and what it does in the world."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.disc_tracker import DiscTracker, detect
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.shield import ScanPolicy, for_nav
from worlds.config import LEARNING_NAV, ObstacleConfig
from worlds.outcomes import Outcome

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"
NAV = LEARNING_NAV
ANGLES = NAV.sensors.ray_angles
RADIUS = 0.3


def scan(discs: list[tuple[float, float]], wall: float = 5.0) -> np.ndarray:
    """The rays of a robot at the origin inside a round room of radius ``wall`` with discs of
    ``RADIUS`` at ``discs`` (its frame): each ray's first hit."""
    ranges = np.full(len(ANGLES), wall)
    for cx, cy in discs:
        ux, uy = np.cos(ANGLES), np.sin(ANGLES)
        along = ux * cx + uy * cy
        miss = (cx - along * ux) ** 2 + (cy - along * uy) ** 2
        hit = (along > 0) & (miss <= RADIUS**2)
        entry = along - np.sqrt(np.maximum(RADIUS**2 - miss, 0.0))
        ranges = np.where(hit, np.minimum(ranges, entry), ranges)
    return ranges


def found(ranges: np.ndarray) -> np.ndarray:
    centres, counts = np.zeros((1, 32, 2)), np.zeros(1, np.int64)
    detect(ranges[None], ANGLES, RADIUS, NAV.sensors.max_range, centres, counts)
    return centres[0, : counts[0]]


def test_a_disc_standing_in_front_of_the_wall_is_found_where_it_is():
    assert len(found(scan([]))) == 0  # a wall all round: no ray stands in front of its neighbours
    for where in ([(2.0, 0.0)], [(1.5, 1.0), (-2.0, -1.5)], [(-2.2, 0.3)], [(1.0, -1.0)]):
        centres = found(scan(where))
        assert len(centres) == len(where)
        for true in where:  # each within a few centimetres of its true centre
            assert np.hypot(*(centres - true).T).min() < 0.08, (where, centres)


def test_a_wide_object_or_one_beyond_the_range_is_not_a_disc():
    wide = scan([]).copy()
    wide[np.abs(ANGLES) < 0.5] = 2.0  # a 1.9 m wide panel 2 m ahead: a wall piece, not a disc
    assert len(found(wide)) == 0
    far = np.full(len(ANGLES), NAV.sensors.max_range)  # open space: every ray at its range
    assert len(found(far)) == 0


def tracker() -> DiscTracker:
    shield = for_nav(NAV)
    return DiscTracker(1, ANGLES, NAV.sensors.max_range, shield.moves, NAV.robot.radius, RADIUS)


def test_a_disc_coming_at_the_robot_is_predicted_one_more_step_on_and_straight_on_is_not_clear():
    track, straight = tracker(), int(np.argmin(np.abs(NAV.robot.turns)))
    track.observe(scan([(1.6, 0.0)])[None], np.array([True]))
    assert track.clear()[0].all()  # one frame: a standing disc 1.6 m ahead leaves room for 0.5 m
    track.moved(np.array([NAV.robot.turn_around]))  # half a turn: the disc is now behind
    track.observe(scan([(-1.4, 0.0)])[None], np.array([False]))  # it came 0.2 m closer
    assert np.allclose(track.nxt[0, 0], (-1.2, 0.0), atol=0.08)
    track.moved(np.array([NAV.robot.turn_around]))  # facing it again
    track.observe(scan([(1.2, 0.0)])[None], np.array([False]))
    assert np.allclose(track.nxt[0, 0], (1.0, 0.0), atol=0.08)
    clear = track.clear()[0]
    assert not clear[straight]  # 0.5 m towards a disc coming 0.2 m: closer than the two radii
    assert clear[0] and clear[-1]  # 90 degrees right, and turning round in place, stay clear
    track.observe(scan([(1.2, 0.0)])[None], np.array([True]))  # a new episode forgets the history
    assert np.allclose(track.nxt[0, 0], track.centres[0, 0]) and track.clear()[0, straight]


def test_the_shield_keeps_the_networks_choice_unless_a_disc_sweeps_it():
    shield = for_nav(NAV)
    k, straight = NAV.robot.n_actions, int(np.argmin(np.abs(NAV.robot.turns)))
    outputs = np.zeros((3, k))
    outputs[:, straight], outputs[:, 0], outputs[:, k - 1] = 1.0, 0.5, 0.7  # straight, then left, right
    room = np.full((2, 3, k), 1.0)  # the readings leave everything clear
    room[:, 2, k - 1] = -1.0  # robot 2: the readings rule out the left
    disc_clear = np.ones((3, k + 1), bool)
    disc_clear[1, straight] = False  # robot 1: a disc sweeps straight on
    disc_clear[2, : k - 1] = False  # robot 2: every action but the left (which the readings rule out)
    action = shield.pick(outputs, room)
    assert (action == straight).all()
    kept = shield.keep_clear(action, outputs, room, disc_clear)
    assert kept[0] == straight  # nothing sweeps it: the network's choice
    assert kept[1] == k - 1  # the next preference the readings leave clear
    assert kept[2] == shield.turn_around  # the readings' clear ones all swept: turn round in place
    disc_clear[2, shield.turn_around] = False
    assert shield.keep_clear(action, outputs, room, disc_clear)[2] == k - 1  # then what the readings rule out
    disc_clear[2] = False
    assert shield.keep_clear(action, outputs, room, disc_clear)[2] == straight  # none: the shield's


class Recorder:
    """A policy that reads the scans: records what the runner hands it, drives straight on."""

    def __init__(self) -> None:
        self.calls: list[tuple[tuple[int, ...], np.ndarray]] = []

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        raise AssertionError("a scan policy is driven through its scan actor")

    def scan_actor(self, n: int):
        def act(obs, rays, fresh):
            assert rays.shape == (n, len(ANGLES)) and (rays > 0).all()
            self.calls.append((rays.shape, np.array(fresh, bool)))
            return np.full(n, int(np.argmin(np.abs(NAV.robot.turns))))

        return act


def test_the_runner_hands_a_scan_policy_its_rays_and_each_episodes_start():
    es = make_eval_set("unseen", 4, seed=1)
    policy = Recorder()
    assert isinstance(policy, ScanPolicy)
    evaluate(policy, es, NAV)
    fresh = np.stack([f for _, f in policy.calls])
    assert fresh[0].all() and not fresh[1].all()  # all start together; afterwards only a robot's new one
    ended = fresh[1:].any(axis=0)  # driving straight on hits a wall before the longest ends
    assert ended.any()


def test_the_tracker_cuts_the_shipped_networks_disc_collisions_in_the_world():
    """The shipped network through its shield on 300 validation episodes with 4 moving discs at 16
    cells, the one-frame shield against the shield with its tracker (the same episodes): fewer disc
    collisions, no episode lost."""
    es = make_eval_set("dynamic", 300, seed=1, obstacles=ObstacleConfig(count=4))
    nav = load_policy(PRETRAINED).nav_config(NAV)
    runs = {}
    for track in (False, True):
        policy = load_policy(PRETRAINED).use_shield(nav, track_discs=track)
        runs[track] = np.array([e.outcome for e in evaluate(policy, es, nav).episodes["dynamic"]])
    hits = {k: int((v == int(Outcome.COLLISION_DYNAMIC)).sum()) for k, v in runs.items()}
    assert hits[False] >= 4 and hits[True] < hits[False], hits
    goal = int(Outcome.GOAL)
    assert not ((runs[False] == goal) & (runs[True] != goal)).any()  # none lost
