"""Kinematic mode is exactly the course's Eq. 1-3, clamped to the limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics import ConfigError, RobotParams, Simulation, World

from conftest import make_sim


def hand_recurrence(pose, commands, dt, max_v=0.5, max_w=2.5):
    """Eq. 1-3 written out independently of the simulator, as a student would."""
    x, y, theta = pose
    trace = []
    for v, w, ticks in commands:
        v = max(-max_v, min(max_v, v))
        w = max(-max_w, min(max_w, w))
        for _ in range(ticks):
            x, y, theta = (x + v * math.cos(theta) * dt, y + v * math.sin(theta) * dt,
                           theta + w * dt)
            trace.append((x, y, theta))
    return trace


def test_straight_line_gives_x_equals_v_t(open_world: World) -> None:
    sim = make_sim(open_world)
    sim.command(linear_mps=0.3, angular_rps=0.0)
    for tick in range(1, 41):
        sim.step()
        truth = sim.ground_truth()
        assert truth.x == pytest.approx(0.3 * tick * sim.dt_s, abs=1e-12)
        assert truth.y == 0.0 and truth.theta == 0.0
    assert sim.time_s == pytest.approx(2.0)


def test_full_circle_returns_to_start_with_radius_v_over_omega(open_world: World) -> None:
    ticks_per_turn = 200
    v = 0.3
    omega = 2 * math.pi / (ticks_per_turn * 0.05)
    sim = make_sim(open_world)
    sim.command(v, omega)
    points = []
    for _ in range(ticks_per_turn):
        sim.step()
        points.append(sim.ground_truth()[:2])
    end = sim.ground_truth()
    assert (end.x, end.y) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert end.theta == pytest.approx(2 * math.pi, abs=1e-12)
    centre = np.mean(points, axis=0)
    radii = np.hypot(*(np.array(points) - centre).T)
    assert np.ptp(radii) < 1e-9, "the discrete trajectory lies on one circle"
    assert radii.mean() == pytest.approx(v / omega, rel=1e-4)
    assert centre == pytest.approx((0.0, v / omega), abs=0.01)


def test_mixed_command_sequence_matches_recurrence_to_1e_12(open_world: World) -> None:
    commands = [(0.3, 0.0, 10), (0.2, 0.5, 15), (-0.1, -1.2, 7), (0.9, 3.0, 12),
                (0.0, 2.5, 5), (0.45, -0.7, 30)]
    sim = make_sim(open_world)
    expected = hand_recurrence((0.0, 0.0, 0.0), commands, sim.dt_s)
    got = []
    for v, w, ticks in commands:
        sim.command(v, w)
        for _ in range(ticks):
            sim.step()
            got.append(sim.ground_truth()[:3])
    assert np.max(np.abs(np.array(got) - np.array(expected))) <= 1e-12


def test_commands_are_clamped_to_the_limits(open_world: World) -> None:
    sim = make_sim(open_world)
    assert sim.command(5.0, -10.0) == (0.5, -2.5)
    assert sim.command(-0.7, 2.6) == (-0.5, 2.5)
    assert sim.command(0.2, -0.3) == (0.2, -0.3)
    sim.command(5.0, 0.0)
    sim.step(20)
    assert sim.ground_truth().x == pytest.approx(0.5, abs=1e-12)


def test_limits_come_from_params(open_world: World) -> None:
    sim = make_sim(open_world, params=RobotParams(max_linear_mps=0.2, max_angular_rps=1.0))
    assert sim.command(1.0, 9.0) == (0.2, 1.0)


def test_robot_keeps_last_command_between_messages(open_world: World) -> None:
    sim = make_sim(open_world)
    sim.command(0.25, 0.0)
    sim.step(10)
    sim.step(10)
    assert sim.ground_truth().x == pytest.approx(0.25, abs=1e-12)
    assert sim.odometry().v == 0.25


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "fast", None, True])
def test_non_finite_or_non_numeric_command_is_refused_and_keeps_the_old_one(
        open_world: World, bad: object) -> None:
    sim = make_sim(open_world)
    sim.command(0.1, 0.2)
    with pytest.raises(ConfigError, match="linear_mps"):
        sim.command(bad, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="angular_rps"):
        sim.command(0.0, bad)  # type: ignore[arg-type]
    assert sim.last_command == (0.1, 0.2)
    sim.step(100)
    assert all(math.isfinite(value) for value in sim.ground_truth())


def test_odometry_equals_ground_truth_relative_to_spawn(open_world: World) -> None:
    spawn = (1.0, -2.0, 0.7)
    world = World(name="w", start=type(open_world.start)(*spawn), walls=(), circles=(),
                  source="w")
    sim = Simulation(world, seed=0)
    sim.command(0.3, 0.4)
    sim.step(73)
    truth, odom = sim.ground_truth(), sim.odometry()
    dx, dy = truth.x - spawn[0], truth.y - spawn[1]
    c, s = math.cos(spawn[2]), math.sin(spawn[2])
    assert odom.x == pytest.approx(c * dx + s * dy, abs=1e-12)
    assert odom.y == pytest.approx(-s * dx + c * dy, abs=1e-12)
    assert odom.theta == pytest.approx(truth.theta - spawn[2], abs=1e-12)
    assert (odom.v, odom.omega) == (truth.v, truth.omega)


def test_reset_returns_to_spawn_with_odometry_zeroed(arena: World) -> None:
    sim = make_sim(arena)
    sim.command(0.3, 0.3)
    sim.step(30)
    sim.reset()
    assert sim.ground_truth() == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert sim.odometry() == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert sim.time_s == 0.0 and sim.tick == 0
    assert sim.last_command == (0.0, 0.0)
    sim.step()
    assert sim.ground_truth()[:3] == (0.0, 0.0, 0.0)
