"""One world, many robots (``physics.world_sim.WorldSim``): they see and stop at each other.

Real pymunk, analytic expectations worked by hand, and the one-ray-at-a-time pymunk reference
for the batched scan with the other robots in it.
"""

from __future__ import annotations

import math
from itertools import combinations
from typing import Any

import numpy as np
import pytest

from physics import (
    ConfigError,
    NoiseParams,
    Pose2D,
    RobotParams,
    Simulation,
    WorldSim,
    load_world,
    raycast,
)
from physics.robot import CONTACT_SKIN_M, MAX_SUBSTEP_S
from physics.space import COLLISION_SLOP_M, WALLS_ONLY
from physics.world import world_from_dict

RADIUS_M = RobotParams().footprint_radius_m
RANGE_MAX_M = 3.5


def beam(angle_deg: float) -> int:
    return round(angle_deg) % 360


def facing_pair(mode: str = "kinematic", gap_m: float = 2.0) -> WorldSim:
    """Robots a and b on the x axis of the empty world, ``gap_m`` apart, facing each other."""
    world = WorldSim(load_world("empty"), seed=0)
    world.spawn("a", Pose2D(-gap_m / 2, 0.0, 0.0), mode=mode)
    world.spawn("b", Pose2D(gap_m / 2, 0.0, math.pi), mode=mode)
    return world


def test_two_robots_facing_each_other_read_each_other_at_the_distance_worked_by_hand() -> None:
    world = facing_pair(gap_m=2.0)
    scans = world.cast_scans()
    # Centres 2 m apart, the laser at each centre: the other's footprint (0.11 m) at 1.89 m.
    for name in ("a", "b"):
        assert scans[name].ranges[beam(0)] == pytest.approx(2.0 - RADIUS_M, abs=1e-12)
        # Behind each robot, the wall at x = -3 (a) or +3 (b): 3 - 1 = 2 m.
        assert scans[name].ranges[beam(180)] == pytest.approx(2.0, abs=1e-12)
    # A beam 3 degrees off the axis grazes the disc: the chord's near end, worked by hand.
    angle = math.radians(3.0)
    along, across = 2.0 * math.cos(angle), 2.0 * math.sin(angle)
    expected = along - math.sqrt(RADIUS_M**2 - across**2)
    assert scans["a"].ranges[beam(3)] == pytest.approx(expected, abs=1e-12)
    # 4 degrees off, the beam passes the disc (2 sin 4 deg = 0.1395 m > 0.11 m) and the wall
    # 4 / cos 4 deg away is beyond range_max.
    assert scans["a"].ranges[beam(4)] == RANGE_MAX_M


def test_a_robot_never_sees_itself_but_sees_every_other() -> None:
    world = WorldSim(load_world("empty"), seed=0)
    world.spawn("alone", Pose2D(0.0, 0.0, 0.0))
    assert set(world.cast_scans()["alone"].ranges[::90]) == {3.0}
    world.spawn("north", Pose2D(0.0, 1.0, 0.0))
    ranges = world.cast_scans()["alone"].ranges
    assert ranges[beam(90)] == pytest.approx(1.0 - RADIUS_M, abs=1e-12)
    assert ranges[beam(0)] == pytest.approx(3.0, abs=1e-12)


@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
def test_one_driving_into_the_other_stops_at_contact(mode: str) -> None:
    """b stands with its back to the wall at x = 3; a drives into it and stops at contact."""
    world = WorldSim(load_world("empty"), seed=0)
    world.spawn("a", Pose2D(0.0, 0.0, 0.0), mode=mode)
    world.spawn("b", Pose2D(3.0 - RADIUS_M - 0.001, 0.0, 0.0), mode=mode)
    world.command("a", 0.5, 0.0)
    gaps = []
    for _ in range(200):
        world.step()
        a, b = world.footprints()
        gaps.append(math.hypot(*(b[:2] - a[:2])) - a[2] - b[2])
    a_sim = Simulation.of(world, "a")
    assert a_sim.state().collided, "state says collided"
    assert min(gaps) < 0.005, "a reached b"
    if mode == "kinematic":
        assert min(gaps) >= 0.0
        assert gaps[-1] == pytest.approx(CONTACT_SKIN_M, abs=1e-9)
        assert a_sim.ground_truth().v == pytest.approx(0.0, abs=1e-9)
    else:
        assert min(gaps) > -0.5 * MAX_SUBSTEP_S
        assert gaps[-1] > -COLLISION_SLOP_M - 1e-4
        assert abs(a_sim.ground_truth().v) < 1e-3
        assert a_sim.odometry().x > a_sim.ground_truth().x + 0.3, "its wheels slipped on"


@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
def test_two_robots_driving_head_on_stop_at_contact(mode: str) -> None:
    world = facing_pair(mode, gap_m=2.0)
    world.command("a", 0.5, 0.0)
    world.command("b", 0.5, 0.0)
    world.step(100)
    a, b = world.footprints()
    gap = math.hypot(*(b[:2] - a[:2])) - 2 * RADIUS_M
    assert -COLLISION_SLOP_M - 1e-4 < gap < 0.01
    for name in ("a", "b"):
        assert Simulation.of(world, name).state().collided
        assert abs(world.ground_truth(name).v) < 1e-3


@pytest.mark.parametrize("mode", ["kinematic", "dynamic", "mixed"])
def test_random_driving_robots_never_overlap_beyond_the_wall_tolerance(mode: str) -> None:
    world = WorldSim(load_world("maze"), seed=0)
    rng = np.random.default_rng(5)
    for index in range(8):
        robot_mode = mode if mode != "mixed" else ("kinematic", "dynamic")[index % 2]
        world.spawn(f"r{index}", mode=robot_mode)
    worst = math.inf
    for _ in range(40):
        for name in world.names:
            world.command(name, rng.uniform(-0.5, 0.5), rng.uniform(-2.5, 2.5))
        for _ in range(5):
            world.step()
            discs = world.footprints()
            for i, j in combinations(range(len(discs)), 2):
                gap = math.hypot(*(discs[i, :2] - discs[j, :2])) - discs[i, 2] - discs[j, 2]
                worst = min(worst, gap)
    tolerance = 0.0 if mode == "kinematic" else 0.5 * MAX_SUBSTEP_S
    assert worst >= -tolerance - 1e-12


def random_arena(count: int, seed: int) -> WorldSim:
    world = WorldSim(load_world("maze"), seed=seed)
    rng = np.random.default_rng(seed)
    for index in range(count):
        world.spawn(f"r{index}")  # the nearest free pose to the start: a crowd around it
    for _ in range(30):
        for name in world.names:
            world.command(name, rng.uniform(0.1, 0.5), rng.uniform(-2.5, 2.5))
        world.step(3)
    return world


@pytest.mark.parametrize("seed", range(3))
def test_the_batched_scan_equals_the_reference_for_every_robot_others_included(
        seed: int) -> None:
    world = random_arena(12, seed)
    scans = world.cast_scans()
    seen_another = 0
    for name in world.names:
        reference = world.scan_reference(name)
        expected = np.where(np.isinf(reference), RANGE_MAX_M, reference)
        got = np.array(scans[name].ranges)
        hit = np.isfinite(reference) & (reference >= 0.12)
        assert np.max(np.abs(got[hit] - expected[hit]), initial=0.0) <= 1e-9, name
        assert np.array_equal(np.isinf(reference), got == RANGE_MAX_M), name
        alone = world.scan(name)  # the same robot's scan cast on its own is the same
        assert alone.ranges == scans[name].ranges
        walls_only = Simulation.of(world, name).lidar.raw_ranges(
            Pose2D(*world.ground_truth(name)[:3]))
        seen_another += int(np.any(np.abs(walls_only[hit] - reference[hit]) > 1e-6))
    assert seen_another > 0, "the robots saw each other"


def count_intersections(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """From now on, the (laser, beam, disc) triples each cast of discs intersects, in order."""
    intersected: list[int] = []
    cast = raycast._DiscPairs.cast

    def counted(pairs: raycast._DiscPairs, ranges: np.ndarray, which: Any) -> None:
        intersected.append(int(pairs.spans[which].sum()))
        cast(pairs, ranges, which)

    monkeypatch.setattr(raycast._DiscPairs, "cast", counted)
    return intersected


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.usefixtures("numpy_raycast")  # numpy's culling of discs
def test_a_crowds_scans_cast_nearest_first_are_the_same_to_the_bit(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """80 robots packed in the empty world (``--class 80 --arena``): most of the robots a
    laser could hit hide behind nearer ones. Casting each laser's nearest first and leaving
    out what hides behind them gives exactly the ranges of casting every robot, for a
    fraction of the beam-robot pairs, and equals the one-ray-at-a-time reference."""
    world = WorldSim(load_world("empty"), seed=seed)
    rng = np.random.default_rng(seed)
    for index in range(80):
        world.spawn(f"r{index}")  # the nearest free pose to the start: a crowd
    for name in world.names:
        world.command(name, rng.uniform(-0.3, 0.3), rng.uniform(-2.0, 2.0))
    world.step(4)
    lidar = Simulation.of(world, world.names[0]).lidar
    poses = [Pose2D(*pose) for pose in world.poses()]
    own = list(range(len(poses)))
    intersected = count_intersections(monkeypatch)
    culled = lidar.raw_ranges_many(poses, world.footprints(), own)
    culled_pairs = sum(intersected)
    intersected.clear()
    monkeypatch.setattr(raycast, "CULL_MIN_DEPTH", 1e9)
    every = lidar.raw_ranges_many(poses, world.footprints(), own)
    assert np.array_equal(culled, every)
    assert culled_pairs < 0.5 * sum(intersected), (culled_pairs, sum(intersected))
    for index in range(0, len(poses), 7):
        reference = world.scan_reference(world.names[index])
        assert np.array_equal(np.isinf(reference), np.isinf(culled[index]))
        finite = np.isfinite(reference)
        assert np.max(np.abs(culled[index][finite] - reference[finite]),
                      initial=0.0) <= 1e-9


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.usefixtures("numpy_raycast")  # numpy's culling of discs
def test_scattered_discs_half_hidden_cast_nearest_first_are_the_same_to_the_bit(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``physics.raycast``: lasers among discs of every size at random, many half hidden
    behind nearer ones, so a cull a hair too eager would change some beam."""
    rng = np.random.default_rng(seed)
    lasers, discs = 60, 90
    origins = rng.uniform(-3.0, 3.0, size=(lasers, 2))
    headings = rng.uniform(-math.pi, math.pi, size=lasers)
    centre = rng.uniform(-3.0, 3.0, size=(discs, 2))
    radius = rng.uniform(0.02, 0.4, size=discs)
    angles = -math.pi + np.arange(360) * (2 * math.pi / 360)
    walls = raycast.Walls.of(np.array([[-4.0, -4.0], [4.0, -4.0]]),
                             np.array([[4.0, -4.0], [4.0, 4.0]]))

    def ranges() -> np.ndarray:
        return raycast.cast(origins, headings, np.cos(angles), np.sin(angles), -math.pi,
                            2 * math.pi / 360, 12.0, walls, centre, radius)

    intersected = count_intersections(monkeypatch)
    culled = ranges()
    assert len(intersected) > 1, "cast in tiers of nearness"
    monkeypatch.setattr(raycast, "CULL_MIN_DEPTH", 1e9)
    assert np.array_equal(culled, ranges())


def test_the_same_seed_gives_the_same_run() -> None:
    noise = NoiseParams(odom_linear_sigma_mps=0.02, odom_angular_sigma_rps=0.05,
                        scan_sigma_m=0.01)

    def run(seed: int) -> tuple[np.ndarray, list[tuple[float, ...]]]:
        world = WorldSim(load_world("maze"), seed=seed, noise=noise)
        rng = np.random.default_rng(1)
        for index in range(5):
            world.spawn(f"r{index}", mode=("kinematic", "dynamic")[index % 2])
        scans = []
        for _ in range(40):
            for name in world.names:
                world.command(name, rng.uniform(-0.5, 0.5), rng.uniform(-2.5, 2.5))
            world.step(2)
            scans += [scan.ranges for scan in world.cast_scans().values()]
        odometry = np.array([tuple(world.odometry(name)) for name in world.names])
        return np.hstack([world.poses(), odometry]), scans

    first, again, other = run(3), run(3), run(4)
    assert np.array_equal(first[0], again[0])
    assert first[1] == again[1]
    assert not np.array_equal(first[0], other[0])


def test_spawn_refuses_a_taken_name_a_wall_and_another_robot() -> None:
    world = WorldSim(load_world("empty"), seed=0)
    assert world.spawn("a", Pose2D(0.0, 0.0, 0.0)) == Pose2D(0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match="already"):
        world.spawn("a", Pose2D(1.0, 1.0, 0.0))
    with pytest.raises(ConfigError, match="from robot 'a'"):
        world.spawn("b", Pose2D(0.15, 0.0, 0.0))
    with pytest.raises(ConfigError, match=r"0.050 m from polylines\[0\]"):
        world.spawn("b", Pose2D(2.95, 0.0, 0.0))
    with pytest.raises(ConfigError, match="mode"):
        world.spawn("b", Pose2D(1.0, 0.0, 0.0), mode="flying")
    assert world.names == ("a",)
    placed = world.spawn("b")  # no pose: the start (taken by a), else the nearest free pose
    assert math.hypot(placed.x, placed.y) >= 2 * RADIUS_M
    assert math.hypot(placed.x, placed.y) < 2 * RADIUS_M + 0.06


def first_free_one_at_a_time(world: WorldSim, pose: Pose2D, radius_m: float) -> Pose2D:
    """``free_pose_near``'s search as it reads, one candidate and one robot at a time: each
    candidate of each ring, in order, kept if nothing overlaps it (``WorldSim._blocked``, the
    check a teleport makes) and no wall stands between it and ``pose``."""
    space = world.space.space
    if world._blocked(pose.x, pose.y, radius_m, ()) is None:
        return pose
    min_x, min_y, max_x, max_y = world.world.bounds
    for ring in range(1, int(math.hypot(max_x - min_x, max_y - min_y) / 0.05) + 2):
        distance = ring * 0.05
        count = max(8, int(2.0 * math.pi * distance / 0.05))
        for k in range(count):
            angle = 2.0 * math.pi * k / count
            x, y = pose.x + distance * math.cos(angle), pose.y + distance * math.sin(angle)
            if world._blocked(x, y, radius_m, ()) is None and space.segment_query_first(
                    (pose.x, pose.y), (x, y), 0.0, WALLS_ONLY) is None:
                return Pose2D(x, y, pose.theta)
    raise AssertionError("no free pose")


@pytest.mark.parametrize("name", ["empty", "maze"])
def test_a_crowds_free_places_are_the_ones_a_search_one_at_a_time_finds(name: str) -> None:
    """Spawns without a pose pack a crowd around the start (``--class N --arena``); each
    ring's candidates are tried against every robot at once. The same places, to the bit,
    as trying each candidate against each robot in turn."""
    world = WorldSim(load_world(name), seed=0)
    rng = np.random.default_rng(7)
    for index in range(60):
        radius_m = float(rng.uniform(0.06, 0.2))
        wanted = first_free_one_at_a_time(world, world.world.start, radius_m)
        assert world.free_pose_near(world.world.start, radius_m) == wanted
        spawned = world.spawn(f"r{index}", params=RobotParams(footprint_radius_m=radius_m))
        assert spawned == wanted
    probe = Pose2D(float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), 0.3)
    assert world.free_pose_near(probe, 0.15) == first_free_one_at_a_time(world, probe, 0.15)


def test_three_hundred_spawns_in_one_world_never_overlap() -> None:
    world = WorldSim(load_world("empty"), seed=0)
    for index in range(300):
        world.spawn(f"r{index}")
    footprints = world.footprints()
    gaps = np.hypot(footprints[:, None, 0] - footprints[None, :, 0],
                    footprints[:, None, 1] - footprints[None, :, 1]) \
        - footprints[:, None, 2] - footprints[None, :, 2]
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= 0.0, "no two footprints overlap"


def test_delete_teleport_and_reset() -> None:
    world = WorldSim(load_world("empty"), seed=0)
    world.spawn("a", Pose2D(0.0, 0.0, 0.0))
    world.spawn("b", Pose2D(1.0, 0.0, 0.0))
    with pytest.raises(KeyError, match="no robot 'c'"):
        world.delete("c")
    world.command("a", 0.3, 0.5)
    world.step(10)
    odometry = world.odometry("a")
    with pytest.raises(ConfigError, match="from robot 'b'"):
        world.teleport("a", Pose2D(1.1, 0.0, 0.0))
    world.teleport("a", Pose2D(-1.0, -1.0, 1.0))
    assert world.ground_truth("a") == (-1.0, -1.0, 1.0, 0.0, 0.0)
    assert world.odometry("a")[:3] == odometry[:3], "a teleport is not seen by odometry"
    assert world.state("a").command == (0.0, 0.0)
    # b now stands on a's spawn: a reset puts a on the nearest free pose instead.
    world.teleport("b", Pose2D(0.05, 0.0, 0.0))
    placed = world.reset_robot("a")
    assert placed != Pose2D(0.0, 0.0, 0.0)
    assert math.hypot(placed.x - 0.05, placed.y) >= 2 * RADIUS_M
    assert world.odometry("a") == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert world.robot_tick("a") == 0 and world.tick == 10
    world.delete("b")
    assert world.reset_robot("a") == Pose2D(0.0, 0.0, 0.0), "free again: back to its spawn"
    assert world.names == ("a",)
    world.step()
    assert world.robot_tick("a") == 1


def test_a_robot_spawned_later_counts_its_own_time() -> None:
    world = WorldSim(load_world("empty"), seed=0)
    world.spawn("a", Pose2D(0.0, 0.0, 0.0))
    world.step(7)
    world.spawn("b", Pose2D(1.0, 0.0, 0.0))
    world.step(3)
    assert (world.tick, world.robot_tick("a"), world.robot_tick("b")) == (10, 10, 3)
    assert Simulation.of(world, "b").time_s == pytest.approx(0.15)


def test_a_world_file_places_robots_by_name_and_checks_them() -> None:
    world = world_from_dict({
        "start": [0.0, 0.0, 0.0],
        "robots": [{"name": "alice", "start": [0.1, 0.0, 0.0]},
                   {"name": "bob", "start": [1.0, 0.0, 3.0],
                    "params": {"mass_kg": 2.0, "footprint_radius_m": 0.2}}]}, source="w.yaml")
    assert [robot.name for robot in world.robots] == ["alice", "bob"]
    bob = world.placed("bob")
    assert bob is not None and bob.params_over(RobotParams()).mass_kg == 2.0
    assert world.placed("carol") is None
    arena = WorldSim(world, seed=0)
    # carol comes first: the world's start is free of robots, but alice's start is kept
    carol = arena.spawn("carol")
    assert math.hypot(carol.x - 0.1, carol.y) >= 2 * RADIUS_M
    assert arena.spawn("alice", world.robots[0].start) == world.robots[0].start
    for bad, match in [
        ({"robots": [{"name": "a", "start": [0, 0, 0]}, {"name": "a", "start": [1, 0, 0]}]},
         r"robots\[1\]\.name: 'a' is placed twice"),
        ({"robots": [{"name": "a", "start": [0, 0, 0]}, {"name": "b", "start": [0.1, 0, 0]}]},
         r"robots\[1\]\.start: .* overlaps that of 'a'"),
        ({"robots": [{"name": "a", "start": [0, 0, 0], "params": {"mas_kg": 1}}]},
         "did you mean 'mass_kg'"),
        ({"robots": [{"name": "a", "start": [0, 0, 0], "params": {"mass_kg": -1}}]},
         r"robots\[0\]\.params\.mass_kg: must be between"),
        ({"robots": [{"name": "a"}]}, r"robots\[0\]\.start: missing"),
        ({"circles": [{"center": [0, 0], "radius": 0.5}], "start": [2, 2, 0],
          "robots": [{"name": "a", "start": [0.1, 0, 0]}]}, "inside the circle"),
    ]:
        with pytest.raises(ConfigError, match=match):
            world_from_dict(bad, source="w.yaml")
