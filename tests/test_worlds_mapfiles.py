"""Map files (worlds.mapfiles): map_server YAML + PGM/PNG written by hand with known cells, each bad
file's one error, conservative resampling, MovingAI swamp, and start/goal pairs (worlds.pairs)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from agents.planning.astar import astar
from worlds.mapfiles import choose_factor, coarsen, load_map_file, read_map_server
from worlds.maps import GridMap, MapFormatError, load_movingai
from worlds.pairs import draw_pairs, robot_cells
from worlds.tasks import parse_map_spec

SHARED = Path("/work/shared/data")

# one row of pixels, each shade picked against the default thresholds (occupied 0.65, free 0.196):
# occ = 1 - p/255 -> 255: 0.0 free; 0: 1.0 occupied; 128: 0.498 unknown (trinary) / 50% (scale);
# 210: 0.176 free; 80: 0.686 occupied
ROW = [255, 0, 128, 210, 80]


def write_pgm(path: Path, pixels: list[list[int]]) -> None:
    """A binary PGM (P5) by hand: the header, then one byte per pixel, top row first."""
    rows = np.asarray(pixels, dtype=np.uint8)
    header = f"P5\n{rows.shape[1]} {rows.shape[0]}\n255\n".encode()
    path.write_bytes(header + rows.tobytes())


def write_yaml(tmp_path: Path, image: str = "m.pgm", name: str = "m.yaml", **fields) -> Path:
    data = {"image": image, "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0}
    data.update({"occupied_thresh": 0.65, "free_thresh": 0.196}, **fields)
    text = "".join(f"{k}: {v}\n" for k, v in data.items() if v is not None)
    path = tmp_path / name
    path.write_text(text)
    return path


def test_trinary_cells_by_hand(tmp_path):
    write_pgm(tmp_path / "m.pgm", [ROW, ROW[::-1]])
    cells, resolution, origin = read_map_server(write_yaml(tmp_path))
    assert resolution == 0.05 and origin == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(cells, [[0, 100, -1, 0, 100], [100, 0, -1, 100, 0]])


def test_negate_flips_occupancy(tmp_path):
    write_pgm(tmp_path / "m.pgm", [ROW])
    cells, *_ = read_map_server(write_yaml(tmp_path, negate=1))
    # occ = p/255: 255 -> 1.0 occupied, 0 free, 128 unknown, 210 (0.82) occupied, 80 (0.31) unknown
    np.testing.assert_array_equal(cells, [[100, 0, -1, 100, -1]])


def test_both_thresholds_move_the_boundaries(tmp_path):
    write_pgm(tmp_path / "m.pgm", [ROW])
    cells, *_ = read_map_server(write_yaml(tmp_path, occupied_thresh=0.4, free_thresh=0.1))
    # 128 (0.498) is now occupied, 210 (0.176) now unknown
    np.testing.assert_array_equal(cells, [[0, 100, 100, -1, 100]])


def test_scale_mode_and_alpha(tmp_path):
    pixels = np.array([[[255, 255], [0, 255], [128, 255], [128, 100]]], dtype=np.uint8)  # grey + alpha
    Image.fromarray(pixels, mode="LA").save(tmp_path / "m.png")
    cells, *_ = read_map_server(write_yaml(tmp_path, image="m.png", mode="scale"))
    # 128: occ 0.498 -> round((0.498 - 0.196) / (0.65 - 0.196) * 100) = 67; not opaque -> unknown
    assert cells.tolist() == [[0, 100, 67, -1]]


def test_raw_mode_reads_percent(tmp_path):
    write_pgm(tmp_path / "m.pgm", [[0, 1, 100, 101, 255]])
    cells, *_ = read_map_server(write_yaml(tmp_path, mode="raw"))
    assert cells.tolist() == [[0, 1, 100, -1, -1]]


def test_png_rgb_is_the_mean_of_its_channels(tmp_path):
    Image.fromarray(np.array([[[255, 255, 255], [0, 0, 0], [255, 0, 0]]], dtype=np.uint8)).save(
        tmp_path / "c.png"
    )
    cells, *_ = read_map_server(write_yaml(tmp_path, image="c.png"))
    assert cells.tolist() == [[0, 100, 100]]  # red: mean 85 -> occ 0.667 > 0.65


def open_room(tmp_path: Path, side: int = 40, **fields) -> Path:
    """A side x side pixel room at 0.05 m: a wall ring one pixel thick, a 1-pixel wall in the middle
    with a 12-pixel (0.6 m) door, unknown pixels (grey) outside a corner."""
    pixels = np.full((side, side), 254, dtype=np.uint8)
    pixels[0, :] = pixels[-1, :] = pixels[:, 0] = pixels[:, -1] = 0
    pixels[:, side // 2] = 0
    pixels[14:26, side // 2] = 254
    pixels[1:4, 1:4] = 205  # map_saver's unknown grey
    write_pgm(tmp_path / "room.pgm", pixels.tolist())
    return write_yaml(tmp_path, image="room.pgm", name="room.yaml", **fields)


def test_room_loads_at_its_metric_size_and_says_why(tmp_path):
    mf = load_map_file(open_room(tmp_path, origin=[2.0, 3.0, 0.5]))
    assert mf.factor == 2 and mf.grid.cell_size == pytest.approx(0.1) and mf.grid.shape == (20, 20)
    assert mf.grid.height * mf.grid.cell_size == pytest.approx(40 * 0.05)  # 2 m, never rescaled
    assert "0.1 m = 2 x 0.05 m" in mf.note and "half the robot radius" in mf.note
    assert mf.origin == (2.0, 3.0, 0.5)
    assert mf.to_ros(0.0, mf.grid.height * mf.grid.cell_size) == pytest.approx((2.0, 3.0))  # lower left
    assert mf.grid.blocked[0:2, 0:2].all()  # unknown -> blocked by default
    free = load_map_file(open_room(tmp_path), unknown="free")
    assert not free.grid.blocked[1, 1]


def test_resampling_keeps_every_wall():
    rng = np.random.default_rng(0)
    for k in (2, 3, 5):
        fine = rng.random((37, 41)) < 0.05  # thin scattered walls, sides not multiples of k
        coarse = coarsen(fine, k)
        assert coarse.shape == (math.ceil(37 / k), math.ceil(41 / k))
        rows, cols = np.nonzero(fine)
        assert coarse[rows // k, cols // k].all()  # no blocked pixel lost
        empty = ~coarse
        r, c = np.nonzero(empty)
        for rr, cc in zip(r, c, strict=True):  # and a free coarse cell has only free pixels
            assert not fine[rr * k : rr * k + k, cc * k : cc * k + k].any()


def test_cell_size_rule():
    assert choose_factor(0.05, 0.25)[0] == 2
    assert choose_factor(0.03, 0.25)[0] == 4
    assert choose_factor(0.2, 0.25)[0] == 1  # never finer than the file
    assert choose_factor(0.05, 0.25, cell_size=0.25)[0] == 5


@pytest.mark.parametrize(
    ("setup", "fragment"),
    [
        (lambda d: (d / "m.pgm").write_bytes(b"P7\n1 1\n255\n\x00"), "not an image"),
        (lambda d: None, "not found"),
        (lambda d: write_pgm(d / "m.pgm", [[254] * 3]), "no two connected free cells"),
    ],
)
def test_bad_image_is_one_error_naming_file_and_field(tmp_path, setup, fragment):
    setup(tmp_path)
    with pytest.raises(MapFormatError, match=fragment) as err:
        load_map_file(write_yaml(tmp_path))
    assert str(tmp_path / "m.yaml") in str(err.value)


@pytest.mark.parametrize(
    ("fields", "fragment"),
    [
        ({"occupied_thresh": 1.5}, "field 'occupied_thresh': 1.5 is out of range"),
        ({"free_thresh": -0.1}, "field 'free_thresh': -0.1 is out of range"),
        ({"free_thresh": 0.9}, "field 'free_thresh': 0.9 is above occupied_thresh"),
        ({"mode": "fancy"}, "field 'mode'"),
        ({"negate": 2}, "field 'negate'"),
        ({"resolution": 0}, "field 'resolution'"),
        ({"resolution": None}, "missing field 'resolution'"),
        ({"origin": "[1, 2]"}, "field 'origin'"),
    ],
)
def test_bad_yaml_fields(tmp_path, fields, fragment):
    open_room(tmp_path)
    with pytest.raises(MapFormatError, match=fragment.replace("(", r"\(")):
        load_map_file(write_yaml(tmp_path, image="room.pgm", **fields))


def test_bad_movingai_and_spec_errors(tmp_path):
    (tmp_path / "bad.map").write_text("type octile\nheight 2\nwidth 2\nmap\n..\n")
    with pytest.raises(MapFormatError, match=r"bad\.map"):
        parse_map_spec(str(tmp_path / "bad.map"))
    with pytest.raises(ValueError, match="unknown option 'colour'"):
        parse_map_spec(f"{open_room(tmp_path)},colour=red")
    with pytest.raises(ValueError, match="mixes generated maps and map files"):
        parse_map_spec(f"rooms:16,{open_room(tmp_path)}")


def test_movingai_swamp_is_passable(tmp_path):
    path = tmp_path / "s.map"
    path.write_text("type octile\nheight 1\nwidth 4\nmap\n.SWT\n")
    assert load_movingai(path).blocked.tolist() == [[False, False, True, True]]


def test_pairs_reachable_bucketed_reproducible():
    grid = GridMap(np.pad(np.zeros((30, 60), dtype=bool), 1, constant_values=True), name="hall")
    pairs = draw_pairs(grid, 200, seed=3, radius=0.25, min_distance=5.0, max_distance=45.0)
    again = draw_pairs(grid, 200, seed=3, radius=0.25, min_distance=5.0, max_distance=45.0)
    assert [(t.start, t.goal) for t, _ in pairs] == [(t.start, t.goal) for t, _ in again]
    other = draw_pairs(grid, 200, seed=4, radius=0.25, min_distance=5.0, max_distance=45.0)
    assert [(t.start, t.goal) for t, _ in pairs] != [(t.start, t.goal) for t, _ in other]
    lengths = np.array([length for _, length in pairs])
    assert lengths.min() >= 5.0 and lengths.max() <= 45.0
    counts = np.histogram(lengths, bins=np.linspace(5, 45, 11))[0]
    assert counts.min() >= 8  # every bucket drawn (20 expected each)
    for t, length in pairs[:20]:
        assert astar(grid, t.start, t.goal).length == pytest.approx(length)


def test_pairs_respect_the_robot_radius():
    # a corridor one cell of 0.1 m wide: a robot of radius 0.25 m fits nowhere in it
    blocked = np.ones((30, 30), dtype=bool)
    blocked[5:25, 5:12] = False  # room A, 0.7 m wide
    blocked[5:25, 18:25] = False  # room B
    blocked[15, 12:18] = False  # a 0.1 m slit between them
    grid = GridMap(blocked, cell_size=0.1, name="slit")
    ok = robot_cells(grid, 0.25)
    assert ok[15, 8] and not ok[15, 14] and not ok[5, 5]
    for t, _ in draw_pairs(grid, 50, seed=0, radius=0.25, min_distance=0.0):
        assert (t.start[1] < 12) == (t.goal[1] < 12)  # never across the slit


def test_directory_is_a_training_set(tmp_path):
    open_room(tmp_path)
    (tmp_path / "two.txt").write_text("#######\n#.....#\n#.....#\n#.....#\n#######\n")
    sampler = parse_map_spec(f"{tmp_path},min_distance=0.5")
    assert [m.path.name for m in sampler.maps] == ["room.yaml", "two.txt"]
    tasks = sampler.draw_pool(10, 0)
    assert {t.grid.name for t in tasks} == {"room", "two"} and len(tasks) == 10


@pytest.mark.skipif(not SHARED.exists(), reason="shared data not on this machine")
def test_shared_and_holdout_maps_load():
    """The development maps and the held-out ones load (held-out: only that they load)."""
    for directory in ("holdout/map_server", "holdout/movingai", "movingai/validation"):
        for mf in parse_map_spec(str(SHARED / directory)).maps:
            assert mf.grid.width >= 10 and mf.note
    assert load_map_file(SHARED / "map_server/tb3_sandbox.yaml").grid.shape == (192, 192)
    # nav2's own 10x10-pixel test map is 1 m across: a robot of 0.25 m radius fits nowhere in it
    with pytest.raises(MapFormatError, match=r"testmap\.yaml: no two connected free cells"):
        load_map_file(SHARED / "map_server/testmap.yaml")
    tiny = load_map_file(SHARED / "map_server/testmap.yaml", radius=0.04)
    assert tiny.grid.shape == (10, 10) and tiny.origin == (2.0, 3.0, 1.0)


def corridor_map(tmp_path: Path, resolution: float, name: str) -> Path:
    """A 3 m x 2 m map_server room at ``resolution`` (60 x 40 pixels): walls round it and a wall
    across with a 0.5 m door."""
    pixels = np.full((40, 60), 254, dtype=np.uint8)
    pixels[:2, :] = pixels[-2:, :] = pixels[:, :2] = pixels[:, -2:] = 0
    pixels[:, 30:32] = 0
    pixels[15:25, 30:32] = 254
    write_pgm(tmp_path / f"{name}.pgm", pixels.tolist())
    return write_yaml(
        tmp_path, image=f"{name}.pgm", name=f"{name}.yaml", resolution=resolution, origin=[-3.0, -2.0, 0.0]
    )


def test_a_map_for_a_smaller_robot_is_the_same_map_scaled(tmp_path):
    """radius=0.1 reads a 0.05 m map as the 0.125 m map the world's 0.25 m robot stands in for it:
    the same cells, the same cell size, the scale said, and ROS coordinates in the file's metres."""
    small = load_map_file(corridor_map(tmp_path, 0.05, "small"), radius=0.1)
    big = load_map_file(corridor_map(tmp_path, 0.125, "big"))
    assert small.scale == 2.5 and big.scale == 1.0 and small.resolution == 0.05
    np.testing.assert_array_equal(small.grid.blocked, big.grid.blocked)
    assert math.isclose(small.grid.cell_size, big.grid.cell_size) and small.grid.shape == (40, 60)
    assert "scaled x2.5 for a robot of radius 0.1 m" in small.note and "scaled" not in big.note
    # the world is 7.5 m x 5 m; its top-left corner is the file's (-3, -2 + 2 m) in ROS's frame
    assert np.allclose(small.to_ros(0.0, 0.0), (-3.0, 0.0)) and np.allclose(
        small.to_ros(7.5, 5.0), (0.0, -2.0)
    )
    # without the radius the 0.25 m robot does not fit through the 0.5 m door at 0.1 m cells: the
    # two rooms are apart, and pairs never cross; for the 0.1 m robot they do
    crossing = 0
    for task in parse_map_spec(f"{tmp_path / 'small.yaml'},radius=0.1,min_distance=1.0").draw_pool(40, 3):
        assert astar(task.grid, task.start, task.goal).length >= 1.0 * 2.5  # the file's metres, scaled
        crossing += (task.start[1] < 30) != (task.goal[1] < 30)
    assert crossing > 0
    for task in parse_map_spec(f"{tmp_path / 'small.yaml'},min_distance=1.0").draw_pool(40, 3):
        assert (task.start[1] < 15) == (task.goal[1] < 15)


def test_a_robot_too_big_for_the_map_is_named_in_the_files_metres(tmp_path):
    with pytest.raises(
        MapFormatError, match=r"small\.yaml: no two connected free cells a robot of radius 1\.5 m"
    ):
        load_map_file(corridor_map(tmp_path, 0.05, "small"), radius=1.5)
    with pytest.raises(MapFormatError, match="robot radius -1"):
        load_map_file(corridor_map(tmp_path, 0.05, "small"), radius=-1)
