"""The own map's plan prefers the cells the robot has seen (``ObservationConfig.subgoal_prefers_seen``,
:mod:`worlds.own_map`): unseen cells are SOFT on the plan grid, entered at twice a move's cost, until a
ray sees them free; the change reaches a kept plan only where its search looked."""

from __future__ import annotations

import numpy as np
import pytest

from agents.evaluation.runner import fixed_sampler
from tests.test_own_map_inflation import fine_tasks
from worlds.config import LEARNING_NAV, LEGACY_OBSERVATION, NavConfig, saved_observation
from worlds.fields import BLOCKED
from worlds.gridsearch import SOFT, new_work
from worlds.own_map import CHANGED, FREE, ON_PLAN, PENALTY, UNKNOWN, _set, map_rays, plan_clear, waypoint
from worlds.vector_env import NavigationVectorEnv

H, W = 5, 9


def cell_of(node: int) -> tuple[int, int] | None:
    return None if node < 0 else (node // (W + 2) - 1, node % (W + 2) - 1)


def plan_seeing(rows) -> np.ndarray:
    """A 1 m plan grid, H x W, every cell unseen (SOFT) but those of ``rows``, seen free."""
    plan = np.zeros((H + 2) * (W + 2), np.uint8)
    plan_clear(plan, H, W, SOFT)
    inner = plan.reshape(H + 2, W + 2)[1:-1, 1:-1]
    inner[list(rows)] = 0
    return plan


def plan_from(plan: np.ndarray, unseen: float) -> tuple[tuple[int, int] | None, float]:
    """The waypoint (2.5 m along) and plan length from cell (0, 0) to the goal (0, 8)."""
    exam = np.zeros(plan.shape, np.int32)
    empty = np.zeros(0, np.uint8), np.zeros((0, plan.size), np.int32), np.zeros(0)
    start, goal, along, clearance = (0.5, 0.5), (0, 8), 2.5, 0.0
    node, searched, length = waypoint(
        plan, *empty, H, W, 1.0, *start, *goal, along, new_work(plan.size), exam, 1, clearance, unseen
    )
    assert searched
    return cell_of(node), length


def test_the_plan_keeps_to_a_seen_way_unless_an_unseen_one_is_clearly_shorter():
    # row 0 (start and goal) unseen, row 1 seen: straight along row 0 is 8 m, through row 1 8.83 m
    plan = plan_seeing([1])
    assert plan_from(plan, 0.0) == ((0, 3), pytest.approx(8.0))  # unseen cells as free: straight on
    way, length = plan_from(plan, PENALTY)
    assert way[0] == 1 and length == pytest.approx(6 + 2 * np.sqrt(2))  # through the seen row, in metres
    # only row 4 seen: the way round through it costs 19.8, straight on through unseen cells 15: taken
    assert plan_from(plan_seeing([4]), PENALTY) == ((0, 3), pytest.approx(8.0))


def test_a_cell_seen_free_leaves_the_soft_cells_and_reaches_the_plan_where_its_search_looked():
    occ = np.zeros((H, W), np.int8)
    plan = plan_seeing([])
    none = np.zeros(0, np.uint8), np.zeros((0, plan.size), np.int32), H, np.zeros(0)
    exam = np.zeros(plan.shape, np.int32)
    exam[(2 + 1) * (W + 2) + 4 + 1] = 7  # the last search (7) expanded cell (2, 4)
    assert _set(occ, plan, exam, 7, W + 2, 2, 5, FREE, none[0], none[1], H, none[3]) == CHANGED | ON_PLAN
    assert _set(occ, plan, exam, 7, W + 2, 2, 7, FREE, none[0], none[1], H, none[3]) == CHANGED
    assert _set(occ, plan, exam, 7, W + 2, 2, 7, FREE, none[0], none[1], H, none[3]) == 0  # seen before
    inner = plan.reshape(H + 2, W + 2)[1:-1, 1:-1]
    assert inner[2, 5] == 0 and inner[2, 7] == 0 and inner[2, 6] == SOFT
    assert occ[2, 6] == UNKNOWN


def test_rays_turn_the_cells_they_cross_free_and_the_cell_they_hit_blocked():
    occ, visits = np.zeros((H, W), np.int8), np.zeros((H, W), np.int32)
    plan = plan_seeing([])
    none = np.zeros(0, np.uint8), np.zeros((0, plan.size), np.int32), np.zeros(0)
    exam = np.zeros(plan.shape, np.int32)
    angles = np.array([0.0])  # one ray along +x from (0.5, 2.5), hitting a wall 5.5 m ahead
    flags = map_rays(occ, visits, plan, exam, -1, H, W, 1.0, 0.5, 2.5, 0.0, np.cos(angles), np.sin(angles),
                     np.array([5.5]), 6.0, 1, *none)  # fmt: skip
    assert flags == CHANGED | ON_PLAN
    inner = plan.reshape(H + 2, W + 2)[1:-1, 1:-1]
    assert list(inner[2, :7]) == [0] * 6 + [BLOCKED]  # crossed free, the hit cell blocked
    assert (inner[2, 7:] == SOFT).all() and (inner[[0, 1, 3, 4]] == SOFT).all()  # the rest unseen


def test_learned_policies_prefer_seen_cells_and_older_ones_do_not():
    assert LEARNING_NAV.observation.subgoal_prefers_seen
    assert not NavConfig().observation.subgoal_prefers_seen
    assert LEGACY_OBSERVATION["observation.subgoal_prefers_seen"] is False
    assert saved_observation({"observation.subgoal": "own_map"})["observation.subgoal_prefers_seen"] is False


@pytest.mark.parametrize(("k", "prefers"), [(1, True), (4, False), (10, False)])
def test_the_world_prefers_seen_cells_on_maps_of_cells_that_need_no_inflation(k, prefers):
    """In the world (LEARNING_NAV), a robot's plan grid holds its unseen cells SOFT on 1 m cells, and
    free on 0.25 and 0.1 m cells, where one traced ray per sector leaves most cells unseen."""
    tasks = fine_tasks(k)
    env = NavigationVectorEnv(len(tasks), LEARNING_NAV, maps=fixed_sampler(tasks, f"fine:{k}"), threads=1)
    env.reset(seed=3, options={"tasks": tasks})
    for _ in range(3):
        env.step(np.zeros(len(tasks), np.int64))
    perception = env.batch.perception
    for i, task in enumerate(tasks):
        h, w = task.grid.shape
        plan = perception.plan[i][: (h + 2) * (w + 2)].reshape(h + 2, w + 2)[1:-1, 1:-1]
        occ = perception.occ[i][:h, :w]
        assert (occ == UNKNOWN).any() and (occ == FREE).any()
        assert np.array_equal(plan == SOFT, (occ == UNKNOWN) if prefers else np.zeros((h, w), bool))
        assert not (plan[occ == FREE]).any()
    env.close()
