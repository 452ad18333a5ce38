"""The motor driver between /cmd_vel and the wheels: lag, scale, ramp (physics.command_pipeline)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from physics import ConfigError, RobotParams, Simulation, load_params
from physics.command_pipeline import AT_REST, drive, drive_sequence, passes_through
from physics.snapshots import Command, Pose2D
from physics.world import World

DT_S = 0.05


def open_world() -> World:
    return World("open", Pose2D(0.0, 0.0, 0.0), (), (), "<test>")


def run(params: RobotParams, linear: float, angular: float, seconds: float,
        mode: str = "kinematic") -> Simulation:
    sim = Simulation(open_world(), params, mode=mode, seed=0)
    sim.command(linear, angular)
    sim.step(round(seconds / sim.dt_s))
    return sim


def test_the_shipped_driver_passes_every_command_through_as_it_is():
    params = RobotParams()
    assert passes_through(params)
    rng = np.random.default_rng(1)
    commands = [Command(float(v), float(w)) for v, w in rng.uniform(-1, 1, (200, 2))]
    commands += [Command(-0.0, 0.0), Command(0.0, -0.0)]
    # the very objects: not a copy that could differ in a last bit or the sign of a zero
    assert all(out is given for out, given in
               zip(drive_sequence(commands, params, DT_S), commands, strict=True))


def test_the_shipped_robot_moves_as_eq_1_to_3_say():
    sim = run(RobotParams(), 0.3, 0.5, 1.0)
    x = y = theta = 0.0
    for _ in range(20):
        x, y, theta = (x + 0.3 * math.cos(theta) * DT_S, y + 0.3 * math.sin(theta) * DT_S,
                       theta + 0.5 * DT_S)
    truth = sim.ground_truth()
    assert (truth.x, truth.y, truth.theta) == (x, y, theta)  # bit for bit


@pytest.mark.parametrize("lag_s", [0.1, 0.12, 0.37])
def test_a_lag_delays_the_distance_driven_by_exactly_the_lag(lag_s):
    params = dataclasses.replace(RobotParams(), cmd_lag_s=lag_s)
    sim = run(params, 0.3, 0.0, 1.0)
    assert sim.ground_truth().x == pytest.approx(0.3 * (1.0 - lag_s), abs=1e-12)
    assert sim.last_command == Command(0.3, 0.0)  # what was commanded, not what acts yet


def test_a_lag_of_whole_ticks_holds_the_robot_still_for_those_ticks():
    params = dataclasses.replace(RobotParams(), cmd_lag_s=0.1)
    sim = Simulation(open_world(), params, seed=0)
    sim.command(0.3, 0.4)
    sim.step(2)
    assert sim.ground_truth() == (0.0, 0.0, 0.0, 0.0, 0.0)
    sim.step()
    assert sim.ground_truth().v == 0.3 and sim.ground_truth().omega == 0.4


def test_scales_multiply_what_the_wheels_give():
    params = dataclasses.replace(RobotParams(), linear_scale=0.9, angular_scale=1.2)
    sim = run(params, 0.3, 0.0, 1.0)
    assert sim.ground_truth().x == pytest.approx(0.27, abs=1e-12)
    assert sim.odometry().v == pytest.approx(0.27)  # the encoders see the scaled motion
    turned = run(params, 0.0, 0.5, 1.0)
    assert turned.ground_truth().theta == pytest.approx(0.6, abs=1e-12)


def test_an_acceleration_limit_ramps_the_speed_up_and_down():
    params = dataclasses.replace(RobotParams(), linear_accel_limit_mps2=0.5,
                                 angular_accel_limit_rps2=2.0)
    sim = Simulation(open_world(), params, seed=0)
    sim.command(0.3, 1.0)
    speeds = []
    for _ in range(20):
        sim.step()
        speeds.append((sim.ground_truth().v, sim.ground_truth().omega))
    assert speeds[0] == pytest.approx((0.025, 0.1))
    assert speeds[11] == pytest.approx((0.3, 1.0))  # 0.3 m/s at 0.5 m/s^2: 12 ticks
    assert speeds[8][1] == pytest.approx(0.9)
    x = y = theta = 0.0  # Eq. 1-3 over the ramped speeds
    for k in range(1, 21):
        v, w = min(0.025 * k, 0.3), min(0.1 * k, 1.0)
        x, y, theta = x + v * math.cos(theta) * DT_S, y + v * math.sin(theta) * DT_S, \
            theta + w * DT_S
    assert tuple(sim.ground_truth()[:3]) == pytest.approx((x, y, theta), abs=1e-12)
    sim.command(0.0, 0.0)
    sim.step()
    assert sim.ground_truth().v == pytest.approx(0.275)  # and down again


def test_lag_scale_and_ramp_act_in_dynamic_mode_too():
    params = dataclasses.replace(RobotParams(), cmd_lag_s=0.2)
    sim = Simulation(open_world(), params, mode="dynamic", seed=0)
    sim.command(0.3, 0.0)
    sim.step(4)
    assert sim.ground_truth().x == pytest.approx(0.0, abs=1e-12)
    sim.step(20)
    assert sim.ground_truth().x > 0.2
    scaled = run(dataclasses.replace(RobotParams(), linear_scale=0.5), 0.3, 0.0, 3.0,
                 mode="dynamic")
    assert scaled.ground_truth().v == pytest.approx(0.15, abs=1e-6)


def test_a_reset_forgets_the_commands_waiting_in_the_lag():
    params = dataclasses.replace(RobotParams(), cmd_lag_s=0.5)
    sim = Simulation(open_world(), params, seed=0)
    sim.command(0.3, 0.0)
    sim.step(5)
    sim.reset()
    sim.step(20)
    assert sim.ground_truth().x == 0.0


def test_a_lag_raised_at_runtime_repeats_the_command_in_force_not_a_stop():
    sim = Simulation(open_world(), RobotParams(), seed=0)
    sim.command(0.3, 0.0)
    sim.step(10)
    sim.update_params(cmd_lag_s=0.3)
    sim.step()
    assert sim.ground_truth().v == 0.3


def test_the_driver_parameters_load_from_a_file_and_are_range_checked(tmp_path):
    path = tmp_path / "fitted.yaml"
    path.write_text("robot:\n  cmd_lag_s: 0.15\n  linear_scale: 0.92\n"
                    "  angular_accel_limit_rps2: 4.0\n")
    robot = load_params(path).robot
    assert (robot.cmd_lag_s, robot.linear_scale, robot.angular_scale,
            robot.angular_accel_limit_rps2) == (0.15, 0.92, 1.0, 4.0)
    assert not passes_through(robot)
    for key, value in (("cmd_lag_s", -0.1), ("linear_scale", 0.0),
                       ("linear_accel_limit_mps2", -1.0), ("cmd_lag_s", 10.0)):
        path.write_text(f"robot:\n  {key}: {value}\n")
        with pytest.raises(ConfigError, match=key):
            load_params(path)


def test_drive_is_pure():
    params = dataclasses.replace(RobotParams(), cmd_lag_s=0.12, linear_accel_limit_mps2=1.0)
    first = drive(AT_REST, Command(0.3, 0.1), params, DT_S)
    again = drive(AT_REST, Command(0.3, 0.1), params, DT_S)
    assert first == again
    assert AT_REST.recent == ()
