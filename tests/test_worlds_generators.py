"""Seeded map generators and map specs (worlds.generators, worlds.tasks)."""

from __future__ import annotations

import numpy as np
import pytest

from worlds.config import TRAINING_MAPS
from worlds.generators import FAMILIES, generate, generate_task, min_task_distance
from worlds.maps import GridMap, MapFormatError, components, connected
from worlds.tasks import DEFAULT_MAPS, MIXED_FAMILIES, parse_map_spec


@pytest.mark.parametrize("family", FAMILIES)
def test_generate_is_seeded_bordered_and_connected(family):
    a = generate(family, 16, 20, seed=3)
    assert a == generate(family, 16, 20, seed=3)
    assert any(generate(family, 16, 20, seed=s) != a for s in (4, 5, 6))
    assert a.shape == (16, 20)
    assert a.blocked[0].all() and a.blocked[-1].all() and a.blocked[:, 0].all() and a.blocked[:, -1].all()
    labels = components(a)
    assert set(np.unique(labels[labels > 0])) == {1}, "free space must be one 4-connected region"
    assert 0.3 < (~a.blocked).mean() < 0.95


@pytest.mark.parametrize("family", FAMILIES)
def test_generate_task_start_goal_free_connected_apart(family):
    for seed in range(5):
        task = generate_task(family, 16, 16, seed)
        assert task.grid.is_free(task.start) and task.grid.is_free(task.goal)
        assert connected(task.grid, task.start, task.goal)
        gap = np.hypot(task.start[0] - task.goal[0], task.start[1] - task.goal[1])
        assert gap >= min_task_distance(task.grid) - 1e-9
    assert generate_task(family, 16, 16, 1) == generate_task(family, 16, 16, 1)


def test_generate_rejects_bad_arguments():
    with pytest.raises(ValueError, match="unknown map family"):
        generate("caves", 16, 16, 0)
    with pytest.raises(ValueError, match="at least 5x5"):
        generate("rooms", 4, 16, 0)


@pytest.mark.parametrize("spec", ["rooms:16", "rects:12x20", "maze:15", "discs:20", "mixed:16", DEFAULT_MAPS])
def test_generated_specs(spec):
    sampler = parse_map_spec(spec)
    tasks = [sampler(np.random.default_rng(k)) for k in range(6)]
    size = spec.split(":")[1]
    shape = tuple(int(v) for v in size.split("x")) if "x" in size else (int(size), int(size))
    for task in tasks:
        assert task.grid.shape == shape
        assert connected(task.grid, task.start, task.goal)
    again = sampler(np.random.default_rng(0))
    assert again.grid == tasks[0].grid and again.start == tasks[0].start
    assert sampler.resample and sampler.cache_key is not None


def test_mixed_spec_draws_several_families():
    sampler = parse_map_spec("mixed:16")
    families = {sampler(np.random.default_rng(k)).grid.name.split("-")[0] for k in range(30)}
    assert families == set(MIXED_FAMILIES)


def test_file_specs(tmp_path, arena_paths):
    arena_map, arena_scen = arena_paths
    sampler = parse_map_spec(str(arena_map))
    task = sampler(np.random.default_rng(0))
    assert task.grid.shape == (49, 49) and connected(task.grid, task.start, task.goal)
    scen = parse_map_spec(str(arena_scen))
    assert len(scen.tasks) == 130
    first, second = scen(np.random.default_rng(0)), scen(np.random.default_rng(0))
    assert (first.start, first.goal) == (scen.tasks[0].start, scen.tasks[0].goal)
    assert (second.start, second.goal) == (scen.tasks[1].start, scen.tasks[1].goal)  # in turn

    marked = tmp_path / "marked.txt"
    marked.write_text("#####\n#S..#\n#..G#\n#####\n")
    task = parse_map_spec(str(marked))(np.random.default_rng(0))
    assert (task.start, task.goal) == ((1, 1), (2, 3))
    plain = tmp_path / "plain.txt"
    plain.write_text("######\n#....#\n#....#\n######\n")
    sampler = parse_map_spec(str(plain))
    # a map file without S/G: seeded start/goal pairs from worlds.pairs (a pool), not env resampling
    assert not sampler.resample and sampler.draw_pool is not None
    pool = sampler.draw_pool(4, 1)
    assert pool == sampler.draw_pool(4, 1)  # reproducible
    assert all(t.grid.shape == (4, 6) and connected(t.grid, t.start, t.goal) for t in pool)


def test_size_range_spec_draws_every_size_and_keeps_each_maps_distance():
    from worlds.bank import E_MIN_D2, pool_bank

    sampler = parse_map_spec(TRAINING_MAPS)
    assert TRAINING_MAPS == "mixed:16-64"
    sizes = [sampler(np.random.default_rng(k)).grid.shape for k in range(400)]
    sides = np.array([h for h, w in sizes])
    assert all(h == w for h, w in sizes) and sides.min() == 16 and sides.max() == 64
    # log-uniform: about as many maps in 16..31 as in 32..64
    small, big = (sides < 32).sum(), (sides >= 32).sum()
    assert 0.7 < small / big < 1.4, (small, big)
    again = sampler(np.random.default_rng(3))
    assert again.grid == sampler(np.random.default_rng(3)).grid
    # resampled endpoints keep each map's own least distance (40% of its side), not the smallest map's
    bank = pool_bank(sampler, 64, 0)
    for task, row in zip(bank.pool_tasks, bank.etab, strict=True):
        least = min_task_distance(task.grid)
        assert row[E_MIN_D2] == int(np.ceil(least**2 - 1e-9))
    assert len({int(r[E_MIN_D2]) for r in bank.etab}) > 10


def test_size_range_episodes_start_far_enough_apart():
    from worlds.config import LEARNING_NAV
    from worlds.vector_env import NavigationVectorEnv

    env = NavigationVectorEnv(8, LEARNING_NAV, maps="mixed:16-64", seed=0)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    seen = 0
    for _ in range(300):
        env.step(rng.integers(5, size=8))
        for i in range(8):
            task = env.batch.task(i)
            gap = np.hypot(task.start[0] - task.goal[0], task.start[1] - task.goal[1])
            assert gap * task.grid.cell_size >= min_task_distance(task.grid) - 1e-9
            seen += 1
    env.close()
    assert seen > 0


def test_bad_specs_raise_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown map family 'caves'"):
        parse_map_spec("caves:16")
    with pytest.raises(ValueError, match="between 5 and 1024"):
        parse_map_spec("rooms:3")
    with pytest.raises(ValueError, match="must go up"):
        parse_map_spec("mixed:64-16")
    with pytest.raises(ValueError, match="neither FAMILY:N"):
        parse_map_spec("no/such/file.map")
    bad = tmp_path / "bad.txt"
    bad.write_text("####\n#.x#\n####\n")
    with pytest.raises(MapFormatError, match=r"bad\.txt:2"):
        parse_map_spec(str(bad))


def test_min_task_distance_scales_with_the_map():
    assert min_task_distance(GridMap(np.zeros((16, 16), bool))) == pytest.approx(0.4 * 14)
