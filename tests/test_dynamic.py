"""Dynamic mode: mass, inertia and traction limits shape the response; steady state is kinematic."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics import RobotParams, Simulation, World
from physics.robot import MAX_SUBSTEP_S

from conftest import make_sim


def rise_time_s(sim: Simulation, field: str, target: float, max_ticks: int = 200) -> float:
    """Time to 90 % of ``target`` for ground-truth ``field``, interpolated between ticks."""
    previous_t, previous = sim.time_s, getattr(sim.ground_truth(), field)
    for _ in range(max_ticks):
        sim.step()
        value = getattr(sim.ground_truth(), field)
        if value >= 0.9 * target:
            return previous_t + (0.9 * target - previous) / (value - previous) * sim.dt_s
        previous_t, previous = sim.time_s, value
    raise AssertionError(f"{field} never reached 90 % of {target}")


def test_step_command_reaches_and_holds_commanded_speed(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.3, 0.8)
    sim.step(20)
    for _ in range(40):
        sim.step()
        truth = sim.ground_truth()
        assert truth.v == pytest.approx(0.3, rel=1e-4)
        assert truth.omega == pytest.approx(0.8, abs=1e-12)


def test_acceleration_is_limited_by_traction(open_world: World) -> None:
    params = RobotParams()
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.5, 0.0)
    sim.step()
    expected = params.max_linear_accel_mps2 * sim.dt_s
    assert sim.ground_truth().v == pytest.approx(expected, rel=1e-9)
    assert sim.ground_truth().v < 0.5


@pytest.mark.parametrize("mass_kg", [0.6, 1.2, 3.0])
def test_rise_time_grows_in_proportion_to_mass(open_world: World, mass_kg: float) -> None:
    times = []
    for mass in (mass_kg, 2 * mass_kg):
        sim = Simulation(open_world, RobotParams(mass_kg=mass), mode="dynamic", seed=0)
        sim.command(0.5, 0.0)
        times.append(rise_time_s(sim, "v", 0.5))
    assert times[1] / times[0] == pytest.approx(2.0, rel=0.15)
    assert times[0] == pytest.approx(0.9 * 0.5 * mass_kg / (2 * 1.5), rel=0.05)


def test_yaw_response_slows_with_inertia(open_world: World) -> None:
    times = []
    for inertia in (0.0066, 0.0132, 0.0264):
        sim = Simulation(open_world, RobotParams(inertia_kg_m2=inertia), mode="dynamic", seed=0)
        sim.command(0.0, 2.5)
        times.append(rise_time_s(sim, "omega", 2.5))
    assert times[0] < times[1] < times[2]
    assert times[2] / times[1] == pytest.approx(2.0, rel=0.15)


def test_large_force_limits_converge_to_the_kinematic_trajectory(open_world: World) -> None:
    commands = [(0.3, 0.0, 20), (0.3, 0.6, 60), (-0.2, -1.0, 30), (0.5, 2.5, 40)]

    def run(mode: str, force_n: float, dt_s: float) -> np.ndarray:
        sim = Simulation(open_world, RobotParams(max_wheel_force_n=force_n), mode=mode,
                         seed=0, dt_s=dt_s)
        trace = []
        for v, w, ticks in commands:
            sim.command(v, w)
            for _ in range(ticks):
                sim.step(round(0.05 / dt_s))
                trace.append(sim.ground_truth()[:2])
        return np.array(trace)

    # Dynamic mode integrates in 0.01 s substeps, so its limit is Eq. 1-3 at that step.
    kinematic = run("kinematic", 1.5, MAX_SUBSTEP_S)
    deviations = [np.max(np.hypot(*(run("dynamic", force, 0.05) - kinematic).T))
                  for force in (1.5, 3.0, 15.0, 1e6)]
    assert deviations[0] > 0.1, "at the real traction limit the modes differ visibly"
    assert deviations[0] > deviations[1] > deviations[2] > deviations[3]
    # What remains is one substep of lag at each command change: |dv| * dt_sub = 0.5 * 0.01.
    assert deviations[3] == pytest.approx(0.5 * MAX_SUBSTEP_S, abs=1e-9)
    # Against the course's 0.05 s recurrence the difference is integration step only.
    coarse = run("kinematic", 1.5, 0.05)
    assert np.max(np.hypot(*(run("dynamic", 1e6, 0.05) - coarse).T)) < 0.03


def test_wheels_do_not_slip_sideways(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.5, 2.5)
    for _ in range(60):
        sim.step()
        body = sim.model._body  # the pymunk body: its velocity must point along the heading
        heading = body.rotation_vector
        lateral = body.velocity.cross(heading)
        # Contact-free: sideways velocity is only the rotation within the last substep.
        assert abs(lateral) <= 0.5 * math.sin(2.5 * 0.01) + 1e-12


def test_odometry_tracks_ground_truth_without_slip(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic", params=RobotParams(max_wheel_force_n=1e6))
    sim.command(0.3, 0.5)
    sim.step(100)
    truth, odom = sim.ground_truth(), sim.odometry()
    assert (odom.x, odom.y, odom.theta) == pytest.approx((truth.x, truth.y, truth.theta),
                                                         abs=1e-9)


def test_odometry_runs_ahead_when_wheels_slip_on_a_hard_start(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.5, 0.0)
    sim.step(40)
    truth, odom = sim.ground_truth(), sim.odometry()
    assert truth.v == pytest.approx(0.5, rel=1e-6)
    # Slipping wheels spin at 0.5 m/s while the body ramps at 2.5 m/s^2 for 0.2 s:
    # odometry gains 0.5 * 0.2 / 2 = 0.05 m on the truth.
    assert odom.x - truth.x == pytest.approx(0.05, abs=0.003)
