"""Scenario and suite files: every shipped one reads, every malformed one gets file:line: key."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from grading import controller_environment, load_scenario, load_suite
from grading.metrics import HeadingStepParams, WallFollowingParams
from grading.scenario import SCENARIOS_DIR
from physics import ConfigError, RobotParams, Simulation, load_world
from physics.params import LidarParams

SHIPPED = sorted(path.stem for path in SCENARIOS_DIR.glob("*.yaml"))

HEADING = """\
world: empty
duration_s: 5
parameters:
  setpoint_rad: 1.0
metrics:
  - kind: heading_step
    threshold: 3.0
"""


def test_the_course_assignments_are_shipped() -> None:
    assert set(SHIPPED) == {"heading_pid", "heading_pid_payload", "wall_following_suite",
                            "go_to_goal"}


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_scenario_reads(name: str) -> None:
    suite = load_suite(name)
    assert suite.entries and all(entry.weight > 0 for entry in suite.entries)
    for entry in suite.entries:
        scenario = entry.scenario
        assert scenario.metrics and scenario.duration_s > 0
        assert any(spec.weight > 0 for spec in scenario.metrics)
        assert all(name.startswith("WEBSIM_") for name in controller_environment(scenario))


def test_the_heading_assignment_tells_the_controller_its_setpoint() -> None:
    scenario = load_scenario("heading_pid")
    assert scenario.world.name == "empty arena" and scenario.mode == "kinematic"
    assert scenario.controller_rate_hz == 10 and scenario.controller_period_ticks == 2
    assert controller_environment(scenario) == {"WEBSIM_SETPOINT_RAD": "1.5707963267948966"}
    heading, smooth = scenario.metrics
    assert isinstance(heading.params, HeadingStepParams)
    assert heading.params.setpoints == ((0.0, math.pi / 2),)
    assert (smooth.kind, smooth.weight) == ("smoothness", 0.0)  # reported, weight 0
    assert heading.origin.endswith("heading_pid.yaml:14")


def test_the_payload_bonus_doubles_the_payload_and_steps_back_at_five_seconds() -> None:
    scenario = load_scenario("heading_pid_payload")
    robot = RobotParams()
    assert scenario.mode == "dynamic" and scenario.robot == robot
    change, = scenario.changes
    assert change.at_s == 5.0 and change.payload is not None
    assert change.payload.mass_kg == pytest.approx(2 * robot.mass_kg)
    assert change.payload.inertia_kg_m2 == pytest.approx(2 * robot.inertia_kg_m2)
    assert scenario.metrics[0].params.setpoints == ((0.0, math.pi / 2), (5.0, 0.0))
    assert controller_environment(scenario) == {
        "WEBSIM_SETPOINT_RAD": "1.5707963267948966", "WEBSIM_SETPOINT_RAD_CHANGES": "5.0:0.0"}
    assert scenario.parameters_at(4.99) == {"setpoint_rad": math.pi / 2}
    assert scenario.parameters_at(5.0) == {"setpoint_rad": 0.0}


def test_the_wall_following_suite_covers_both_sides_two_distances_three_speeds() -> None:
    suite = load_suite("wall_following_suite")
    scenarios = [entry.scenario for entry in suite.entries]
    assert len(scenarios) == 6 and len({s.name for s in scenarios}) == 6
    told = [dict(s.parameters) for s in scenarios]
    assert {p["side"] for p in told} == {"left", "right"}
    assert {p["desired_distance_m"] for p in told} == {0.5, 0.35}
    assert {p["speed_mps"] for p in told} == {0.2, 0.3, 0.4}
    assert {s.world.name for s in scenarios} == {"corridor", "empty arena"}
    assert sum(s.world.name == "corridor" for s in scenarios) == 4
    for scenario in scenarios:
        assert scenario.end is not None and scenario.end.radius_m == 1.0  # MIT's end rule
        params = scenario.metrics[0].params
        assert isinstance(params, WallFollowingParams)
        assert (params.side, params.desired_distance_m) == (dict(scenario.parameters)["side"],
                                                           dict(scenario.parameters)[
                                                               "desired_distance_m"])
        assert (params.end_x_m, params.end_y_m) == (scenario.end.x_m, scenario.end.y_m)
        assert scenario.duration_s == 120.0  # MIT's timeout


def test_go_to_goal_reads_its_goal_from_the_parameters_it_tells() -> None:
    scenario = load_scenario("go_to_goal")
    assert scenario.world.name == "maze"
    assert controller_environment(scenario) == {"WEBSIM_GOAL_X_M": "2.5",
                                                "WEBSIM_GOAL_Y_M": "2.5",
                                                "WEBSIM_GOAL_RADIUS_M": "0.25"}
    params = scenario.metrics[0].params
    assert (params.goal_x_m, params.goal_y_m, params.goal_radius_m) == (2.5, 2.5, 0.25)
    assert params.duration_s == 90.0
    assert params.footprint_radius_m == RobotParams().footprint_radius_m


def write(tmp_path: Path, text: str, name: str = "scenario.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(("text", "message"), [
    (HEADING + "seeed: 3\n",
     ":8: seeed: unknown key 'seeed'; did you mean 'seed'?"),
    (HEADING.replace("threshold: 3.0", "treshold: 3.0"),
     ":7: metrics[0].treshold: unknown key 'treshold'; did you mean 'threshold'?"),
    (HEADING.replace("kind: heading_step", "kind: heading_stp"),
     ":6: metrics[0].kind: unknown metric 'heading_stp'; did you mean 'heading_step'?"),
    (HEADING.replace("duration_s: 5", "duration_s: five"),
     ":2: duration_s: expected a number, got str 'five'"),
    (HEADING.replace("threshold: 3.0", "threshold: [3]"),
     ":7: metrics[0].threshold: expected a number, got list [3]"),
    (HEADING.replace("world: empty", "world: nowhere.yaml"),
     ":1: world: "),
    (HEADING.replace("world: empty", "world: mazee"),
     ":1: world: no shipped world 'mazee'; did you mean 'maze'?"),
    (HEADING.replace("  setpoint_rad: 1.0\n", "  goal_x_m: 1.0\n"),
     ":6: metrics[0]: heading_step needs the parameter 'setpoint_rad'"),
    (HEADING + "controller_rate_hz: 3\n",
     ":8: controller_rate_hz: 3 Hz is not a whole number of 0.05 s simulation ticks"),
    (HEADING + "start: [2.95, 0, 0]\n",
     ":8: start: [2.95, 0.0, 0.0] puts the robot footprint (radius 0.11 m) 0.050 m from "
     "polylines[0].points[1]"),
    (HEADING + "changes:\n  - {at_s: 3, mode: dynamic}\n  - {at_s: 2, mode: kinematic}\n",
     ":10: changes[1].at_s: 2 s comes before the change above it (3 s)"),
    (HEADING + "changes:\n  - {at_s: 3, parameters: {setpont_rad: 0}}\n",
     ":9: changes[0].parameters.setpont_rad: unknown parameter 'setpont_rad'; did you mean "
     "'setpoint_rad'?"),
    (HEADING + "changes:\n  - {at_s: 9, mode: dynamic}\n",
     ":9: changes[0].at_s: 9 s is not within the run's 5 s"),
    (HEADING + "payload: {mass_kg: -1}\n",
     ":8: payload: mass_kg: must be between 0.01 and 1000, got -1"),
    (HEADING + "duration_s: 4\n",
     ":8: key 'duration_s' given twice (first at line 2)"),
    (HEADING + "  - {kind: [\n",
     ":9: not valid YAML: "),
    (HEADING.replace("setpoint_rad: 1.0", "Setpoint: 1.0"),
     ":4: parameters.Setpoint: a parameter's name is lower case letters"),
    (HEADING.replace("setpoint_rad: 1.0", "setpoint_rad: 1.0\n  side: lft left"),
     ":5: parameters.side: a text value is one word"),
    ("world: corridor\nduration_s: 5\nparameters: {side: lft, desired_distance_m: 0.5}\n"
     "end: {point: [5, 0]}\nmetrics:\n  - kind: wall_following\n",
     ":3: parameters.side (read by metrics[0]): must be one of left, right, got 'lft'"),
    ("world: corridor\nduration_s: 5\nparameters: {side: left, desired_distance_m: 0.5}\n"
     "metrics:\n  - kind: wall_following\n",
     ":5: metrics[0]: wall_following needs the scenario's 'end'"),
    ("world: corridor\nduration_s: 5\nparameters: {side: left, desired_distance_m: 0.5}\n"
     "end: {point: [0.5, 0.0]}\nmetrics:\n  - kind: wall_following\n",
     ":4: end: the start [0.0, 0.0, 0.0] is already within 1 m of the end point (0.5, 0)"),
    (HEADING.replace("    threshold: 3.0\n", "    weight: 0\n"),
     ":5: metrics: every metric has weight 0"),
    (HEADING.replace("duration_s: 5\n", ""),
     ":1: duration_s: missing"),
])
def test_a_bad_scenario_is_refused_with_file_line_and_entry(tmp_path: Path, text: str,
                                                            message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as refused:
        load_scenario(path)
    assert str(refused.value).startswith(str(path) + message)


def test_a_missing_world_file_is_named_with_the_scenarios_line(tmp_path: Path) -> None:
    path = write(tmp_path, HEADING.replace("world: empty", "world: worlds/nope.yaml"))
    with pytest.raises(ConfigError) as refused:
        load_scenario(path)
    assert str(refused.value) == (
        f"{path}:1: world: {tmp_path / 'worlds' / 'nope.yaml'}: cannot read world file: "
        f"No such file or directory (shipped worlds: corridor, empty, maze)")


def test_a_world_path_is_taken_from_the_scenarios_folder(tmp_path: Path) -> None:
    (tmp_path / "worlds").mkdir()
    (tmp_path / "worlds" / "box.yaml").write_text(
        "name: box\npolylines:\n  - {points: [[-2, -2], [2, -2], [2, 2], [-2, 2]], closed: true}\n")
    scenario = load_scenario(write(tmp_path, HEADING.replace("world: empty",
                                                             "world: worlds/box.yaml")))
    assert scenario.world.name == "box"


def test_a_missing_scenario_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope.yaml: cannot read scenario file: No such"):
        load_scenario(tmp_path / "nope.yaml")


def test_an_error_in_a_suites_scenario_names_the_suite_and_the_scenario(tmp_path: Path) -> None:
    write(tmp_path, HEADING + "seeed: 3\n", "one.yaml")
    suite = write(tmp_path, "scenarios:\n  - {file: one.yaml}\n", "suite.yaml")
    with pytest.raises(ConfigError) as refused:
        load_suite(suite)
    assert str(refused.value).startswith(
        f"{suite}:2: scenarios[0].file: {tmp_path / 'one.yaml'}:8: seeed: unknown key")
    inline = write(tmp_path, "scenarios:\n  - weight: 2\n    scenario: {name: x, world: empty, "
                             "duration_s: 2, metrics: [{kind: colisions}]}\n", "inline.yaml")
    with pytest.raises(ConfigError) as refused:
        load_suite(inline)
    assert str(refused.value).startswith(
        f"{inline}:3: scenarios[0].scenario.metrics[0].kind: unknown metric 'colisions'; "
        f"did you mean 'collisions'?")


def test_a_suite_of_scenarios_by_file_and_inline_with_weights(tmp_path: Path) -> None:
    write(tmp_path, HEADING, "one.yaml")
    suite = load_suite(write(tmp_path, """\
name: two
defaults: &shared {world: empty, duration_s: 2}
scenarios:
  - {file: one.yaml, weight: 3}
  - weight: 1
    scenario:
      <<: *shared
      name: still
      metrics: [{kind: collisions}]
""", "suite.yaml"))
    assert suite.name == "two"
    assert [(e.scenario.name, e.weight) for e in suite.entries] == [("one", 3.0), ("still", 1.0)]
    assert suite.entries[1].scenario.duration_s == 2.0
    same_name = write(tmp_path, "scenarios:\n  - {file: one.yaml}\n  - {file: one.yaml}\n",
                      "twice.yaml")
    with pytest.raises(ConfigError, match=r"twice.yaml:3: scenarios\[1\]: a second scenario "
                                          r"named 'one'"):
        load_suite(same_name)


def test_a_scenario_file_is_a_suite_of_one(tmp_path: Path) -> None:
    suite = load_suite(write(tmp_path, HEADING, "alone.yaml"))
    assert [(e.scenario.name, e.weight) for e in suite.entries] == [("alone", 1.0)]


def test_an_oversized_file_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = write(tmp_path, HEADING + "#" * (1 << 20))
    with pytest.raises(ConfigError, match=r"scenario file longer than 1048576 bytes"):
        load_scenario(path)


SCAN_TURN = """\
world: {world}
duration_s: 5
lidar: {{angle_min_rad: {angle}}}
parameters:
  setpoint_rad: 1.0
metrics:
  - kind: heading_step
"""


@pytest.mark.parametrize("angle, expected", [("-pi", -math.pi), ("pi/2", math.pi / 2),
                                             ("-pi/2", -math.pi / 2), ("0", 0.0)])
def test_a_scenario_sets_the_scans_angles_and_the_beams_follow(
        tmp_path: Path, angle: str, expected: float) -> None:
    path = tmp_path / "turn.yaml"
    path.write_text(SCAN_TURN.format(world="empty", angle=angle))
    lidar = load_scenario(path).lidar
    n = lidar.num_rays
    assert lidar.angle_min_rad == expected
    assert lidar.angle_increment_rad == 2 * math.pi / n  # a full turn, as the default
    assert lidar.angle_max_rad == lidar.angle_min_rad + (n - 1) * lidar.angle_increment_rad
    scan = Simulation(load_world("empty"), lidar=lidar).scan()
    assert (scan.angle_min, scan.angle_max, scan.angle_increment) == \
        (lidar.angle_min_rad, lidar.angle_max_rad, lidar.angle_increment_rad)
    # the beam at angle 0 (ahead: index 180 for -pi, 0 for 0) reads the arena's east wall
    ahead = round(-expected / lidar.angle_increment_rad) % n
    beam_rad = lidar.angle_min_rad + ahead * lidar.angle_increment_rad
    assert math.remainder(beam_rad, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert scan.ranges[ahead] == pytest.approx(3.0, abs=1e-9)
    assert ahead == {"-pi": 180, "pi/2": 270, "-pi/2": 90, "0": 0}[angle]


def test_the_shipped_scan_is_unchanged_and_a_world_may_set_its_angles(tmp_path: Path) -> None:
    shipped = load_scenario("heading_pid").lidar
    assert shipped == LidarParams() and shipped.angle_min_rad == 0.0
    assert shipped.angle_max_rad == 359 * (2 * math.pi / 360)  # 0..2pi less one beam
    world = tmp_path / "centred.yaml"
    world.write_text("walls: [[2.0, -5.0, 2.0, 5.0]]\nlidar: {angle_min_rad: -pi}\n")
    assert load_world(world).lidar_over(LidarParams()).angle_min_rad == -math.pi
    path = tmp_path / "turn.yaml"
    path.write_text(SCAN_TURN.format(world="centred.yaml", angle="-pi/2"))
    assert load_scenario(path).lidar.angle_min_rad == -math.pi / 2  # the scenario's wins
    path.write_text(SCAN_TURN.format(world="centred.yaml", angle="-pi").replace(
        "lidar: {angle_min_rad: -pi}\n", ""))
    assert load_scenario(path).lidar.angle_min_rad == -math.pi  # the world's


@pytest.mark.parametrize("angle, message", [
    ("tau", "a multiple of pi"), ("7.0", "angle_min_rad"), ("2pi", "a multiple of pi"),
    ("[1]", "expected a number")])
def test_a_bad_scan_angle_is_refused_with_its_line(tmp_path: Path, angle: str,
                                                   message: str) -> None:
    path = tmp_path / "turn.yaml"
    path.write_text(SCAN_TURN.format(world="empty", angle=angle))
    with pytest.raises(ConfigError, match=message) as error:
        load_scenario(path)
    assert "turn.yaml:3: lidar" in str(error.value)
