"""The LiDAR: LaserScan-consistent beams, analytic ranges, and fast path == pymunk reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics import LidarParams, NoiseParams, Pose2D, Simulation, World, load_world
from physics.simulation import cast_scans
from physics.world import world_from_dict

from conftest import SHIPPED_WORLDS, make_sim

SQRT2 = math.sqrt(2.0)

pytestmark = pytest.mark.usefixtures("raycast_path")  # each test in numpy, then compiled


def beam(angle_deg: float, params: LidarParams | None = None) -> int:
    params = params or LidarParams()
    return round(math.radians(angle_deg) / params.angle_increment_rad)


def test_beam_count_identity_holds() -> None:
    p = LidarParams()
    assert p.num_rays == 360
    assert p.angle_min_rad + (p.num_rays - 1) * p.angle_increment_rad == p.angle_max_rad
    assert (p.angle_max_rad - p.angle_min_rad) / p.angle_increment_rad + 1 == pytest.approx(360)
    assert p.angle_max_rad < 2 * math.pi, "no direction is counted twice"
    assert p.time_increment_s == pytest.approx(p.scan_time_s / 360)


def test_scan_message_fields(arena: World) -> None:
    scan = make_sim(arena).scan()
    assert len(scan.ranges) == 360
    assert scan.angle_min == 0.0
    assert scan.angle_increment == pytest.approx(2 * math.pi / 360)
    assert scan.angle_max == pytest.approx(2 * math.pi * 359 / 360)
    assert (scan.range_min, scan.range_max, scan.scan_time) == (0.12, 3.5, 0.1)
    assert scan.time_increment == pytest.approx(0.1 / 360)


def test_arena_from_origin(arena: World) -> None:
    ranges = make_sim(arena).scan().ranges
    for angle in (0, 90, 180, 270):
        assert ranges[beam(angle)] == pytest.approx(3.0, abs=1e-12)
    # The corners are 3*sqrt(2) = 4.24 m away, beyond range_max: no return.
    assert ranges[beam(45)] == 3.5
    # A 30 degree beam meets the x = 3 wall at 3 / cos(30) = 3.46 m.
    assert ranges[beam(30)] == pytest.approx(3.0 / math.cos(math.radians(30)), abs=1e-12)


def test_45_degree_ray_into_a_corner(arena: World) -> None:
    sim = make_sim(arena)
    ranges = sim.lidar.scan(Pose2D(2.0, 2.0, 0.0)).ranges
    assert ranges[beam(45)] == pytest.approx(SQRT2, abs=1e-12)
    assert ranges[beam(0)] == pytest.approx(1.0, abs=1e-12)
    assert ranges[beam(90)] == pytest.approx(1.0, abs=1e-12)
    assert ranges[beam(180)] == 3.5
    # Heading rotates the beams: facing 90 degrees, beam 0 looks along +y.
    turned = sim.lidar.scan(Pose2D(2.0, 2.0, math.pi / 2)).ranges
    assert turned[beam(0)] == pytest.approx(1.0, abs=1e-12)
    assert turned[beam(315)] == pytest.approx(SQRT2, abs=1e-12)


def test_ray_grazing_along_a_wall() -> None:
    # A wall lying on beam 0's line is seen edge-on: a zero-thickness wall shows no surface,
    # so beam 0 reads the wall behind it; beams just either side read the back wall too.
    world = world_from_dict({"walls": [[1.0, 0.0, 2.0, 0.0], [3.0, -1.0, 3.0, 1.0]]})
    sim = Simulation(world, seed=0)
    ranges = sim.scan().ranges
    assert ranges[0] == pytest.approx(3.0, abs=1e-12)
    assert ranges[1] == pytest.approx(3.0 / math.cos(math.radians(1)), abs=1e-12)
    assert ranges[359] == pytest.approx(3.0 / math.cos(math.radians(1)), abs=1e-12)
    # A beam through a wall's end point hits it there.
    world = world_from_dict({"walls": [[1.0, 1.0, 2.0, 1.0]]})
    ranges = Simulation(world, seed=0).scan().ranges
    assert ranges[beam(45)] == pytest.approx(SQRT2, abs=1e-12)


def test_robot_never_sees_itself(open_world: World) -> None:
    sim = make_sim(open_world)
    for mode in ("kinematic", "dynamic"):
        sim.mode = mode
        sim.command(0.3, 0.5)
        sim.step(5)
        assert set(sim.scan().ranges) == {3.5}
        assert set(sim.lidar.raw_ranges_reference(Pose2D(*sim.ground_truth()[:3]))) == {math.inf}


def test_mount_offset_moves_the_laser(arena: World) -> None:
    lidar = LidarParams(mount_x_m=0.1, mount_yaw_rad=math.pi / 2)
    ranges = make_sim(arena, lidar=lidar).scan().ranges
    # The laser sits 0.1 m ahead, turned left: its beam 0 looks along +y, beam 270 along +x.
    assert ranges[beam(270)] == pytest.approx(2.9, abs=1e-12)
    assert ranges[beam(90)] == pytest.approx(3.1, abs=1e-12)


def test_rep117_values_for_no_return_and_too_close() -> None:
    world = world_from_dict({"walls": [[0.115, -1.0, 0.115, 1.0]]})
    course = Simulation(world, seed=0).scan().ranges
    rep117 = Simulation(world, lidar=LidarParams(no_return="inf"), seed=0).scan().ranges
    assert course[0] == 0.0, "a hit closer than range_min reads 0.0 (discarded by consumers)"
    assert rep117[0] == -math.inf
    assert course[180] == 3.5 and rep117[180] == math.inf


def test_scan_noise_is_seeded_and_has_the_asked_sigma(arena: World) -> None:
    noise = NoiseParams(scan_sigma_m=0.01)
    first = np.array(Simulation(arena, seed=7, noise=noise).scan().ranges)
    again = np.array(Simulation(arena, seed=7, noise=noise).scan().ranges)
    other = np.array(Simulation(arena, seed=8, noise=noise).scan().ranges)
    exact = np.array(Simulation(arena, seed=7).scan().ranges)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)
    hits = exact < 3.5
    errors = (first - exact)[hits]
    assert 0.008 < errors.std() < 0.012
    assert np.all(first[~hits] == 3.5), "no-return beams stay exact"


def random_poses(world: World, count: int, seed: int) -> list[Pose2D]:
    rng = np.random.default_rng(seed)
    x_lo, y_lo, x_hi, y_hi = world.bounds
    return [Pose2D(rng.uniform(x_lo, x_hi), rng.uniform(y_lo, y_hi), rng.uniform(-7, 7))
            for _ in range(count)]


def random_world(seed: int, walls: int, circles: int) -> World:
    rng = np.random.default_rng(seed)
    segments = []
    for _ in range(walls):
        x, y = rng.uniform(-5, 5, size=2)
        angle, length = rng.uniform(0, 2 * math.pi), rng.uniform(0.2, 2.0)
        segments.append([x, y, x + length * math.cos(angle), y + length * math.sin(angle)])
    discs = [{"center": rng.uniform(-5, 5, size=2).tolist(), "radius": rng.uniform(0.05, 0.5)}
             for _ in range(circles)]
    boxes = [{"center": [1.0, -4.0], "size": [1.0, 0.5], "yaw": 0.4}]
    return world_from_dict({"walls": segments, "circles": discs, "boxes": boxes,
                            "start": [50, 50, 0]}, source=f"random-{seed}")


def assert_paths_agree(sim: Simulation, poses: list[Pose2D]) -> None:
    for pose in poses:
        fast = sim.lidar.raw_ranges(pose)
        reference = sim.lidar.raw_ranges_reference(pose)
        assert np.array_equal(np.isinf(fast), np.isinf(reference)), pose
        finite = np.isfinite(reference)
        assert np.max(np.abs(fast[finite] - reference[finite]), initial=0.0) <= 1e-9, pose


@pytest.mark.parametrize("name", SHIPPED_WORLDS)
def test_fast_scan_equals_pymunk_reference_in_shipped_worlds(name: str) -> None:
    world = load_world(name)
    assert_paths_agree(Simulation(world, seed=0), random_poses(world, 150, seed=1))


@pytest.mark.parametrize("name", SHIPPED_WORLDS)
def test_many_robots_cast_together_equal_the_reference(name: str) -> None:
    world = load_world(name)
    sim = Simulation(world, seed=0)
    poses = random_poses(world, 40, seed=2)
    together = sim.lidar.raw_ranges_many(poses)
    for pose, row in zip(poses, together, strict=True):
        reference = sim.lidar.raw_ranges_reference(pose)
        assert np.array_equal(np.isinf(row), np.isinf(reference)), pose
        finite = np.isfinite(reference)
        assert np.max(np.abs(row[finite] - reference[finite]), initial=0.0) <= 1e-9, pose


def test_a_class_cast_together_reads_what_each_robot_reads_alone() -> None:
    """Same world, different seeds, noise on: each keeps its own noise stream."""
    noise = NoiseParams(scan_sigma_m=0.01)

    def robots() -> list[Simulation]:
        sims = [Simulation(load_world("maze"), noise=noise, seed=seed) for seed in range(6)]
        for index, sim in enumerate(sims):
            sim.command(0.1 + 0.02 * index, 0.3 - 0.1 * index)
            sim.step(4 + index)
        return sims

    together, alone = robots(), robots()
    cast_scans(together)
    assert all(sim.scan_is_current for sim in together)
    for sim_together, sim_alone in zip(together, alone, strict=True):
        assert sim_together.scan().ranges == pytest.approx(sim_alone.scan().ranges, abs=1e-12)
        assert sim_together.scan().ranges != together[0].scan().ranges or sim_together is \
            together[0]  # different poses and noise: different scans


@pytest.mark.parametrize("seed", range(4))
def test_fast_scan_equals_pymunk_reference_in_random_worlds(seed: int) -> None:
    world = random_world(seed, walls=80, circles=12)
    assert_paths_agree(Simulation(world, seed=0), random_poses(world, 60, seed=seed))


def test_fast_scan_equals_reference_on_exact_corners_and_axes(arena: World) -> None:
    sim = make_sim(arena)
    poses = [Pose2D(x, y, theta) for x in (-2.0, 0.0, 1.5, 2.0) for y in (-2.0, 0.0, 2.0)
             for theta in (0.0, math.pi / 4, math.pi / 2, -3 * math.pi / 4)]
    assert_paths_agree(sim, poses)
