"""World files: every shipped world works, every malformed file gets a clear error."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from physics import ConfigError, Simulation, load_world
from physics.world import world_from_dict
from ros_nodes.robot_messages import MARKER_CUBE, world_markers_msg

from conftest import SHIPPED_WORLDS


def test_the_three_required_worlds_are_shipped() -> None:
    assert {"empty", "maze", "corridor"} <= set(SHIPPED_WORLDS)


@pytest.mark.parametrize("name", SHIPPED_WORLDS)
@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
def test_shipped_world_runs_200_ticks_with_finite_state(name: str, mode: str) -> None:
    world = load_world(name)
    assert tuple(world.start) == (0.0, 0.0, 0.0), "odom and map agree at spawn"
    sim = Simulation(world, mode=mode, seed=0)
    for tick in range(200):
        if tick % 25 == 0:
            sim.command(0.5 * math.cos(tick), 2.0 * math.sin(tick))
        sim.step()
        assert all(math.isfinite(v) for v in (*sim.ground_truth(), *sim.odometry()))
        if tick % 2:
            assert len(sim.scan().ranges) == 360


def test_empty_is_a_closed_six_metre_arena() -> None:
    world = load_world("empty")
    assert world.bounds == (-3.0, -3.0, 3.0, 3.0)
    assert len(world.walls) == 4
    assert sum(wall.length_m for wall in world.walls) == pytest.approx(24.0)


def test_load_world_by_path_and_by_name_agree() -> None:
    by_name = load_world("maze")
    by_path = load_world(Path(__file__).parent.parent / "worlds" / "maze.yaml")
    assert by_name.walls == by_path.walls and by_name.circles == by_path.circles


def test_boxes_polylines_and_circles() -> None:
    world = world_from_dict({
        "walls": [[0, 5, 1, 5]],
        "polylines": [{"points": [[0, 6], [1, 6], [1, 7]]},
                      {"points": [[3, 3], [4, 3], [4, 4]], "closed": True}],
        "boxes": [{"center": [-3, 0], "size": [2, 1], "yaw": math.pi / 2}],
        "circles": [{"center": [0, -3], "radius": 0.5}],
        "start": [0, 0, math.pi / 2],
    })
    assert len(world.walls) == 1 + 2 + 3 + 4
    box = [w for w in world.walls if w.origin == "boxes[0]"]
    xs = sorted({round(c, 9) for w in box for c in (w.x1, w.x2)})
    assert xs == [-3.5, -2.5], "a 2 x 1 box turned 90 degrees is 1 m wide in x"
    assert world.circles[0].radius_m == 0.5
    assert world.start.theta == math.pi / 2
    sim = Simulation(world, seed=0)
    assert sim.scan().ranges[180] == pytest.approx(2.5, abs=1e-9)
    solid, = world.boxes  # kept whole too, for drawing it filled
    assert (solid.x, solid.y, solid.width_m, solid.height_m, solid.yaw_rad) == \
        (-3, 0, 2, 1, math.pi / 2)


def test_the_world_message_carries_each_box_as_a_cube() -> None:
    world = load_world("maze")
    markers = world_markers_msg(world, 0.0)["markers"]
    cubes = [m for m in markers if m["type"] == MARKER_CUBE]
    assert len(cubes) == len(world.boxes) >= 1
    box, cube = world.boxes[0], cubes[0]
    assert (cube["pose"]["position"]["x"], cube["pose"]["position"]["y"]) == (box.x, box.y)
    assert (cube["scale"]["x"], cube["scale"]["y"]) == (box.width_m, box.height_m)
    assert cube["pose"]["orientation"]["z"] == pytest.approx(math.sin(box.yaw_rad / 2))
    assert len({m["id"] for m in markers}) == len(markers)  # one id each


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(("text", "expected"), [
    ("walls: [[0, 0, 1]\n", "not valid YAML"),
    ("- 1\n- 2\n", "expected a mapping"),
    ("walls: 5\n", "walls: expected a list"),
    ("walls:\n  - [0, 0, 1, 1]\n  - [0, 0, 'x', 1]\n", r"walls\[1\]\[2\]: expected a number"),
    ("walls:\n  - [0, 0, 1, 1]\n  - [2, 2, 2, 2]\n", r"walls\[1\]: zero-length wall"),
    ("walls:\n  - [0, 0, .nan, 1]\n", r"walls\[0\]\[2\]: expected a finite number"),
    ("wals: []\n", "unknown key 'wals'; did you mean 'walls'"),
    ("start: [0, 0]\n", "start: expected a list of 3 numbers"),
    ("start: [0, 0, true]\n", r"start\[2\]: expected a number"),
    ("circles:\n  - {center: [0, 0], radius: 0.5}\n", r"inside the circle circles\[0\]"),
    ("boxes:\n  - {center: [0, 0], size: [1, 1]}\n", r"inside the box boxes\[0\]"),
    ("boxes:\n  - {center: [3, 0], size: [1, 0]}\n", r"boxes\[0\].size: height must be > 0"),
    ("boxes:\n  - {centre: [3, 0], size: [1, 1]}\n", "did you mean 'center'"),
    ("circles:\n  - {center: [3, 0], radius: -1}\n", r"circles\[0\].radius: must be > 0"),
    ("polylines:\n  - {points: [[0, 1]]}\n", r"polylines\[0\].points: expected a list of 2"),
    ("polylines:\n  - {points: [[0, 1], [0, 1]]}\n", r"polylines\[0\].points\[0\]: zero-length"),
    ("polylines:\n  - {points: [[0, 1], [1, 1]], closed: 1}\n", "expected true or false"),
    ("name: [1]\n", "name: expected text"),
])
def test_malformed_world_names_file_and_entry(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=expected) as caught:
        load_world(path)
    assert str(caught.value).startswith(str(path))


def test_start_too_close_to_a_wall_names_the_wall(tmp_path: Path) -> None:
    path = write(tmp_path, "walls:\n  - [-5, 5, 5, 5]\n  - [0.05, -1, 0.05, 1]\n")
    world = load_world(path)
    with pytest.raises(ConfigError, match=r"start .* 0\.050 m from walls\[1\]") as caught:
        Simulation(world)
    assert str(caught.value).startswith(str(path))


def test_missing_world_lists_the_shipped_ones() -> None:
    with pytest.raises(ConfigError, match=r"shipped worlds: .*corridor.*empty.*maze"):
        load_world("no-such-world")


def test_empty_file_is_an_empty_world(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, ""))
    assert world.walls == () and tuple(world.start) == (0.0, 0.0, 0.0)
