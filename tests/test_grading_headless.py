"""The shipped assignments graded headless with Python controllers, right and wrong ones.

Real simulations (physics.Simulation on pymunk), the shipped scenario files, the metrics on
the runs' ground truth; and the same run twice gives the same numbers to the last bit.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from grading import Observation, evaluate, load_scenario, load_suite, run_headless
from grading.metrics.collisions import find_contacts
from physics import ConfigError

from grading_controllers import (
    MAZE_ROUTE,
    HeadingPidController,
    IntoTheWall,
    WallFollower,
    Waypoints,
    WrongSignP,
    standing_still,
)

WALL_FOLLOWING = load_suite("wall_following_suite")


def test_a_correct_heading_pid_passes_the_heading_assignment() -> None:
    scenario = load_scenario("heading_pid")
    result = evaluate(scenario, run_headless(scenario, HeadingPidController(kp=4.0)))
    heading = result.metrics[0]
    assert result.passed and result.score == 1.0, result.reason
    assert heading.value is not None and heading.value <= 3.0
    assert heading.figures["overshoot"] <= 0.1
    assert heading.figures["steady_state_error_rad"] < 0.01


def test_kp_of_the_wrong_sign_fails_the_heading_step_never_settling() -> None:
    scenario = load_scenario("heading_pid")
    result = evaluate(scenario, run_headless(scenario, WrongSignP()))
    assert not result.passed and result.score == 0.0
    assert result.reason.startswith("heading_step: step to 1.571 rad at 0 s: never settled "
                                    "within ±0.035 rad")
    heading = result.metrics[0]
    assert heading.value is None
    # It turned away and came to rest on the far side, half a turn from the setpoint.
    assert abs(heading.figures["steps"][0]["final_error_rad"]) > 3.0


def test_the_payload_bonus_fails_a_saturating_pid_and_passes_one_that_spares_the_wheels() -> None:
    scenario = load_scenario("heading_pid_payload")
    saturating = evaluate(scenario, run_headless(scenario, HeadingPidController(kp=4.0)))
    assert not saturating.passed
    # Its odometry says it arrived; the wheels slipped, and the true heading stopped short.
    assert "never settled" in saturating.reason and "error at the end +0.07" in saturating.reason
    gentle = evaluate(scenario, run_headless(scenario, HeadingPidController(kp=4.0,
                                                                           slew_rps=0.5)))
    assert gentle.passed and gentle.score == 1.0, gentle.reason
    assert len(gentle.metrics[0].figures["steps"]) == 2


def test_a_controller_is_called_at_the_scenarios_rate_and_sees_the_changes() -> None:
    scenario = load_scenario("heading_pid_payload")
    seen: list[Observation] = []

    def watch(observation: Observation) -> None:
        seen.append(observation)

    trajectory = run_headless(scenario, watch)
    assert [round(o.time_s, 9) for o in seen[:3]] == [0.0, 0.1, 0.2]  # 10 Hz
    assert len(seen) == 100 and len(trajectory) == 201  # 10 s at 20 Hz, and the start
    assert {o.parameters["setpoint_rad"] for o in seen if o.time_s < 4.99} == {math.pi / 2}
    assert {o.parameters["setpoint_rad"] for o in seen if o.time_s > 4.99} == {0.0}
    assert len(seen[0].scan.ranges) == 360 and seen[0].odometry.theta == 0.0
    assert all(sample.v_cmd_mps == 0.0 for sample in trajectory)  # None keeps the command


def test_a_controller_that_never_moves_fails_go_to_goal() -> None:
    scenario = load_scenario("go_to_goal")
    result = evaluate(scenario, run_headless(scenario, standing_still))
    assert not result.passed
    assert result.reason == ("go_to_goal: did not come within 0.25 m of the goal (2.5, 2.5) "
                             "(closest 3.54 m)")
    assert result.metrics[0].score < 0.05


def test_a_controller_that_drives_the_maze_passes_go_to_goal() -> None:
    scenario = load_scenario("go_to_goal")
    result = evaluate(scenario, run_headless(scenario, Waypoints(MAZE_ROUTE)))
    goal = result.metrics[0]
    assert result.passed, result.reason
    assert goal.value is not None and goal.value < 60.0
    assert goal.figures["path_length_m"] > goal.figures["reference_path_m"] - 0.25
    assert 0.7 < goal.score < 1.0


@pytest.mark.parametrize("index", range(6))
def test_a_wall_follower_passes_every_wall_following_scenario(index: int) -> None:
    scenario = WALL_FOLLOWING.entries[index].scenario
    trajectory = run_headless(scenario, WallFollower())
    result = evaluate(scenario, trajectory)
    assert result.passed, f"{scenario.name}: {result.reason}"
    assert result.metrics[0].score > 0.9
    end = scenario.end
    assert end is not None and trajectory[-1].t_s < scenario.duration_s  # it ended there
    assert math.hypot(trajectory[-1].x_m - end.x_m, trajectory[-1].y_m - end.y_m) <= end.radius_m


def test_driving_into_the_wall_fails_wall_following_with_a_crash() -> None:
    scenario = WALL_FOLLOWING.entries[0].scenario
    trajectory = run_headless(scenario, IntoTheWall())
    result = evaluate(scenario, trajectory)
    follow = result.metrics[0]
    assert not result.passed and follow.score == 0.0
    assert follow.reason.startswith("crashed: polylines[0].points[0] at t = ")
    assert follow.figures["contacts"] >= 1
    assert follow.inputs["contact_source"] == "simulation"
    # The pose alone (as a recording gives it) finds the same first contact.
    radius = scenario.robot.footprint_radius_m
    from_flags = find_contacts(trajectory, scenario.world, radius)
    from_poses = find_contacts([s._replace(collided=None) for s in trajectory],
                               scenario.world, radius)
    assert from_poses.source == "geometry"
    assert from_poses.contacts[0].start_s == from_flags.contacts[0].start_s
    assert from_poses.contacts[0].wall == from_flags.contacts[0].wall


def test_the_same_run_twice_gives_the_same_numbers() -> None:
    for scenario, make in ((load_scenario("heading_pid_payload"), HeadingPidController),
                           (WALL_FOLLOWING.entries[3].scenario, WallFollower)):
        first = run_headless(scenario, make())
        second = run_headless(scenario, make())
        assert first == second  # every float to the last bit
        assert evaluate(scenario, first).to_json() == evaluate(scenario, second).to_json()


def test_a_dynamic_scenario_runs_dynamic_and_its_payload_changes_the_motion() -> None:
    scenario = load_scenario("heading_pid_payload")
    light = dataclasses.replace(scenario, changes=())
    heavy_run = run_headless(scenario, HeadingPidController(kp=4.0))
    light_run = run_headless(light, HeadingPidController(kp=4.0))
    assert heavy_run[100] == light_run[100]  # the same until 5 s
    assert heavy_run[-1].yaw_rad != light_run[-1].yaw_rad  # then the payload tells


def test_an_answer_that_is_not_a_command_is_refused_with_when() -> None:
    scenario = load_scenario("heading_pid")
    with pytest.raises(ConfigError, match=r"the controller's answer at t = 0.00 s: "):
        run_headless(scenario, lambda observation: ("fast", 0.0))  # type: ignore[arg-type,return-value]


def test_a_worlds_noise_reaches_the_controller_and_the_seed_repeats_it(tmp_path: Path) -> None:
    (tmp_path / "noisy.yaml").write_text(
        "name: noisy\npolylines:\n  - {points: [[-3, -3], [3, -3], [3, 3], [-3, 3]], "
        "closed: true}\nnoise: {odom_angular_sigma_rps: 0.05}\n")
    (tmp_path / "turn.yaml").write_text(
        "world: noisy.yaml\nduration_s: 3\nparameters: {setpoint_rad: 1.0}\n"
        "metrics: [{kind: heading_step}]\n")
    scenario = load_scenario(tmp_path / "turn.yaml")

    def drifts() -> list[float]:
        drift: list[float] = []

        def turn(observation: Observation) -> tuple[float, float]:
            drift.append(observation.odometry.theta - observation.ground_truth.theta)
            return 0.0, 0.5
        run_headless(scenario, turn)
        return drift

    first = drifts()
    assert first[0] == 0.0 and abs(first[-1]) > 1e-3  # odometry wanders from the truth
    assert drifts() == first  # the same seed, the same noise
