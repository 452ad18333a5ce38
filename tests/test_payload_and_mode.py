"""Payload perturbation and mode switching at runtime, without a reset."""

from __future__ import annotations

import math

import pytest

from physics import ConfigError, RobotParams, Simulation, World

from conftest import make_sim


def drive(sim: Simulation, ticks: int) -> list[tuple[float, ...]]:
    trace = []
    for _ in range(ticks):
        sim.step()
        trace.append(tuple(sim.ground_truth()))
    return trace


def test_payload_has_no_effect_on_kinematic_motion(open_world: World) -> None:
    plain, loaded = make_sim(open_world), make_sim(open_world)
    for sim in (plain, loaded):
        sim.command(0.4, 1.0)
    drive(plain, 10)
    drive(loaded, 10)
    loaded.set_payload(mass_kg=5.0, inertia_kg_m2=0.05)
    plain.command(-0.2, -2.0)
    loaded.command(-0.2, -2.0)
    assert drive(plain, 30) == drive(loaded, 30)
    assert loaded.params.mass_kg == 5.0 and loaded.params.inertia_kg_m2 == 0.05


def test_payload_acts_at_once_in_dynamic_mode(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.5, 0.0)
    sim.step()
    first = sim.ground_truth().v
    sim.set_payload(mass_kg=2 * RobotParams().mass_kg)
    sim.step()
    second = sim.ground_truth().v - first
    assert second == pytest.approx(first / 2, rel=1e-9), "doubled mass halves the acceleration"


def test_inertia_change_acts_at_once_in_dynamic_mode(open_world: World) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.set_payload(inertia_kg_m2=0.066)
    sim.command(0.0, 2.5)
    sim.step()
    expected = RobotParams().max_wheel_force_n * RobotParams().wheelbase_m / 0.066 * sim.dt_s
    assert sim.ground_truth().omega == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("name", ["mass_kg", "inertia_kg_m2"])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, -math.inf, "2.0", None, True])
def test_invalid_payload_is_refused_and_changes_nothing(open_world: World, name: str,
                                                        bad: object) -> None:
    sim = make_sim(open_world, mode="dynamic")
    sim.command(0.3, 0.3)
    sim.step(7)
    before = (sim.params, sim.ground_truth(), sim.odometry(), sim.time_s)
    with pytest.raises(ValueError, match=name) as caught:
        sim.update_params(**{name: bad})
    if bad is not None:
        assert repr(bad) in str(caught.value)
    assert (sim.params, sim.ground_truth(), sim.odometry(), sim.time_s) == before
    sim.step()
    assert sim.time_s > before[3]


def test_set_payload_with_one_bad_value_changes_neither(open_world: World) -> None:
    sim = make_sim(open_world)
    with pytest.raises(ValueError, match="inertia_kg_m2"):
        sim.set_payload(mass_kg=2.0, inertia_kg_m2=-1.0)
    assert sim.params == RobotParams()


def test_unknown_parameter_gets_a_hint(open_world: World) -> None:
    sim = make_sim(open_world)
    with pytest.raises(ConfigError, match="did you mean 'mass_kg'"):
        sim.update_params(mas_kg=2.0)


def test_lowering_a_limit_clamps_the_command_in_force(open_world: World) -> None:
    sim = make_sim(open_world)
    sim.command(0.5, 2.0)
    sim.update_params(max_linear_mps=0.2, max_angular_rps=1.0)
    assert sim.last_command == (0.2, 1.0)


def test_mode_switch_carries_pose_and_velocity(open_world: World) -> None:
    sim = make_sim(open_world)
    sim.command(0.4, 0.5)
    sim.step(20)
    before = sim.ground_truth()
    sim.mode = "dynamic"
    assert sim.ground_truth() == before
    sim.step()
    after = sim.ground_truth()
    assert after.v == pytest.approx(0.4, rel=1e-6), "already at speed: no restart from rest"
    assert math.hypot(after.x - before.x, after.y - before.y) == pytest.approx(0.02, rel=0.01)
    sim.mode = "kinematic"
    odom_before = sim.odometry()
    sim.step()
    assert sim.ground_truth().v == 0.4
    assert sim.odometry().x != odom_before.x


def test_unknown_mode_is_refused(open_world: World) -> None:
    sim = make_sim(open_world)
    with pytest.raises(ValueError, match="kinematic, dynamic"):
        sim.mode = "warp"
    assert sim.mode == "kinematic"
