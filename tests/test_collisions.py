"""The footprint never passes through a wall, in either mode."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics import Pose2D, RobotParams, Simulation, World, load_world
from physics.robot import CONTACT_SKIN_M, MAX_SUBSTEP_S
from physics.space import COLLISION_SLOP_M, WALLS_ONLY

from conftest import ARENA_HALF_M, make_sim

RADIUS_M = RobotParams().footprint_radius_m


def wall_clearance(sim: Simulation) -> float:
    """Distance from the footprint's edge to the nearest arena wall (negative = overlap)."""
    truth = sim.ground_truth()
    return ARENA_HALF_M - max(abs(truth.x), abs(truth.y)) - RADIUS_M


def test_kinematic_stops_at_contact_and_reports_it(arena: World) -> None:
    sim = make_sim(arena)
    sim.command(0.5, 0.0)
    sim.step(120)
    truth = sim.ground_truth()
    assert truth.x == pytest.approx(ARENA_HALF_M - RADIUS_M - CONTACT_SKIN_M, abs=1e-9)
    assert truth.v == pytest.approx(0.0, abs=1e-6)
    assert sim.state().collided
    assert sim.odometry().x == pytest.approx(truth.x, abs=1e-12), "no slip in kinematic mode"


def test_kinematic_moves_again_when_commanded_away(arena: World) -> None:
    sim = make_sim(arena)
    sim.command(0.5, 0.0)
    sim.step(120)
    sim.command(-0.2, 0.0)
    sim.step()
    assert not sim.state().collided
    assert sim.ground_truth().v == -0.2
    assert sim.ground_truth().x == pytest.approx(ARENA_HALF_M - RADIUS_M - 0.01, abs=1e-5)


def test_kinematic_turns_in_place_and_drives_along_a_wall(arena: World) -> None:
    sim = make_sim(arena)
    sim.command(0.5, 0.0)
    sim.step(120)
    sim.command(0.0, math.pi / 2 / 1.0)
    sim.step(20)
    assert sim.ground_truth().theta == pytest.approx(math.pi / 2, abs=1e-9)
    sim.command(0.3, 0.0)
    sim.step(20)
    assert sim.ground_truth().y == pytest.approx(0.3, abs=1e-9)
    assert not sim.state().collided


@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
@pytest.mark.parametrize("heading_deg", [0, 10, 37, 45, 89, 135, 200, 271])
def test_footprint_never_passes_a_wall(arena: World, mode: str, heading_deg: float) -> None:
    sim = make_sim(arena, mode=mode)
    sim.teleport(Pose2D(0.0, 0.0, math.radians(heading_deg)))
    sim.command(0.5, 0.0)
    clearances = []
    for _ in range(20 * 20):
        sim.step()
        clearances.append(wall_clearance(sim))
    assert min(clearances) < 0.01, "the robot did reach the wall"
    if mode == "kinematic":
        assert min(clearances) >= 0.0
    else:
        # pymunk finds contacts after a substep's motion (<= 0.5 m/s * 0.01 s = 5 mm), then
        # pushes the footprint back out to within its collision slop while it keeps pushing.
        assert min(clearances) > -0.5 * MAX_SUBSTEP_S
        assert clearances[-1] > -COLLISION_SLOP_M - 1e-4


def test_dynamic_contact_is_reported_and_odometry_drifts_while_pushing(arena: World) -> None:
    sim = make_sim(arena, mode="dynamic")
    sim.command(0.3, 0.0)
    sim.step(20 * 12)
    truth, odom = sim.ground_truth(), sim.odometry()
    assert sim.state().collided
    assert truth.x == pytest.approx(ARENA_HALF_M - RADIUS_M, abs=1e-3)
    assert abs(truth.v) < 1e-3
    assert odom.v == pytest.approx(0.3), "slipping wheels still turn at the commanded speed"
    assert odom.x - truth.x > 0.3 * 2.0, "odometry ran on while the robot was stuck"


def test_random_driving_in_the_maze_stays_clear_of_every_wall() -> None:
    world = load_world("maze")
    rng = np.random.default_rng(3)
    for mode in ("kinematic", "dynamic"):
        sim = Simulation(world, mode=mode, seed=0)
        space = sim.world_sim.space.space
        for _ in range(60):
            sim.command(rng.uniform(-0.5, 0.5), rng.uniform(-2.5, 2.5))
            for _ in range(10):
                sim.step()
                truth = sim.ground_truth()
                nearest = space.point_query_nearest((truth.x, truth.y), 1.0, WALLS_ONLY)
                if nearest is not None:
                    assert nearest.distance > RADIUS_M - 0.5 * MAX_SUBSTEP_S, (mode, truth)
