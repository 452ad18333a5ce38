"""Course code as students write it, over rosbridge, graded as-is in deterministic mode.

``--step-on auto`` steps a controller on what it subscribes to (an obstacle avoider that reads
only /scan needs no option, and waits no start-up timeout), learns that one subscribed to both
/odom and /scan answers only its scans, and a controller paced by ``time.sleep`` is told to
use ``--mode wall-clock``; the reason of a controller that stops answering never suggests the
trigger already in use. (rclpy nodes on the ROS graph: tests/test_grade_rclpy.py.)
"""

from __future__ import annotations

import json
import os
import shutil
import textwrap
from pathlib import Path
from typing import Any

import pytest

from grading import load_scenario
from physics import ConfigError
from websim import cli
from websim.grade_class import SUBMISSION_FILE, Declared, submission_declaration
from websim.grade_run import GradeOptions, ros_arguments

SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
"""Where the sandbox can run, the tests grade in it; elsewhere with --no-sandbox (no skip)."""

CONNECT = """\
    import math, os, time
    from urllib.parse import urlsplit
    import roslibpy
    url = urlsplit(os.environ["WEBSIM_URL"])
    ros = roslibpy.Ros(url.hostname, url.port)
    ros.run()
    cmd = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    cmd.advertise()

    def drive(linear, angular):
        cmd.publish(roslibpy.Message({"linear": {"x": linear, "y": 0.0, "z": 0.0},
                                      "angular": {"x": 0.0, "y": 0.0, "z": angular}}))
"""
"""What every roslibpy controller here starts with."""

OBSTACLE_AVOIDER = CONNECT + """\

    def on_scan(scan):  # one /cmd_vel per /scan: turn away from what is ahead
        ahead = [r for i, r in enumerate(scan["ranges"]) if r is not None and
                 abs(math.remainder(scan["angle_min"] + i * scan["angle_increment"],
                                    2 * math.pi)) < 0.4]
        drive(0.0, 1.0) if min(ahead) < 0.6 else drive(0.3, 0.0)

    roslibpy.Topic(ros, "/scan", "sensor_msgs/msg/LaserScan").subscribe(on_scan)
    while ros.is_connected:
        time.sleep(0.2)
"""
"""A roslibpy obstacle avoider as course templates write it: /scan in, /cmd_vel out."""

SCAN_ANSWERER = CONNECT + """\
    latest = {}
    roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(latest.update)
    roslibpy.Topic(ros, "/scan", "sensor_msgs/msg/LaserScan").subscribe(
        lambda scan: drive(0.2, 0.0) if latest else None)
    while ros.is_connected:
        time.sleep(0.2)
"""
"""Keeps the latest /odom, answers each /scan."""

SLEEPER = CONNECT + """\
    latest = {}
    roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(latest.update)
    while ros.is_connected:  # paced by its own clock, not by what it is sent
        drive(0.0, 0.5)
        time.sleep(0.1)
"""

MUTE = CONNECT + """\
    roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(lambda odom: None)
    while ros.is_connected:
        time.sleep(0.2)
"""

OPEN_ARENA = """\
description: the empty arena, {duration} s
world: empty
duration_s: {duration}
metrics:
  - kind: collisions
"""


def grade(tmp_path: Path, program: str, duration_s: float = 3.0) -> dict[str, Any]:
    """Grade ``program`` on the open arena; its report."""
    folder = tmp_path / "submission"
    folder.mkdir()
    (folder / "controller.py").write_text(textwrap.dedent(program))
    scenario = tmp_path / "open_arena.yaml"
    scenario.write_text(OPEN_ARENA.format(duration=duration_s))
    out = tmp_path / "out"
    sandbox = [] if SANDBOXED else ["--no-sandbox"]
    assert cli.main(["grade", str(scenario), "--submission", str(folder), "--out", str(out),
                     "--startup-timeout", "30", *sandbox, "--", "python3",
                     "controller.py"]) in (0, 1)  # graded: every scenario passed, or not
    report: dict[str, Any] = json.loads((out / "open_arena" / "report.json").read_text())
    return report


def test_an_obstacle_avoider_that_reads_only_scan_is_stepped_on_scan(tmp_path: Path) -> None:
    graded = grade(tmp_path, OBSTACLE_AVOIDER)
    run = graded["run"]
    assert run["ended_by"] == "duration" and graded["passed"] is True, graded["reason"]
    assert run["step_on"] == "scan" and run["subscribed"] == ["/scan"]
    assert run["missed_steps"] == 0 and not run["wall_paced"]
    # one answer per /scan (every second tick), the last one's after the run's end
    assert run["commands"] == run["ticks"] // 2 - 1


def test_a_controller_on_odom_and_scan_that_answers_scans_is_stepped_on_scan(
        tmp_path: Path) -> None:
    graded = grade(tmp_path, SCAN_ANSWERER)
    run = graded["run"]
    assert run["ended_by"] == "duration" and graded["passed"] is True, graded["reason"]
    assert run["subscribed"] == ["/odom", "/scan"] and run["step_on"] == "scan"
    assert run["missed_steps"] == 0  # the /odom it left unanswered taught, not counted


def test_a_controller_paced_by_time_sleep_is_told_to_use_wall_clock_mode(
        tmp_path: Path) -> None:
    graded = grade(tmp_path, SLEEPER, duration_s=2.0)
    run = graded["run"]
    assert run["wall_paced"] is True and run["probe_commands"] >= 2
    assert "not deterministic" in graded["reason"]
    assert "grade it with --mode wall-clock" in graded["reason"]


def test_the_reason_of_a_silent_controller_suggests_other_triggers_only(
        tmp_path: Path) -> None:
    graded = grade(tmp_path, MUTE)
    assert graded["run"]["ended_by"] == "no_answer" and graded["score"] == 0.0
    reason = graded["reason"]
    assert "did not answer /odom" in reason and "--mode wall-clock" in reason
    assert "--step-on scan" in reason and "--step-on rate" in reason
    assert "--step-on odom" not in reason


def test_ros_parameters_map_a_scenarios_values_onto_a_nodes_parameters(tmp_path: Path) -> None:
    declaration = tmp_path / SUBMISSION_FILE
    declaration.write_text("command: python3 node.py\nros: true\n"
                           "ros_parameters: {kp: WEBSIM_KP, target.yaw: WEBSIM_SETPOINT_RAD}\n")
    declared = submission_declaration(tmp_path)
    assert declared.ros_parameters == (("kp", "WEBSIM_KP"), ("target.yaw", "WEBSIM_SETPOINT_RAD"))
    options = GradeOptions(ros=True, ros_parameters=(("target.yaw", "WEBSIM_SETPOINT_RAD"),))
    assert ros_arguments(load_scenario("heading_pid"), options) == [
        "--ros-args", "-p", "use_sim_time:=true", "-p", "target.yaw:=1.5707963267948966"]
    with pytest.raises(ConfigError, match="WEBSIM_KP is not set in scenario heading_pid "
                                          r"\(it sets: WEBSIM_SETPOINT_RAD\)"):
        ros_arguments(load_scenario("heading_pid"), declared_options(declared))


@pytest.mark.parametrize("entry, message", [
    ("ros_parameters: {kp: WEBSIM_KP}", "needs 'ros: true'"),
    ("ros: true\nros_parameters: {kp: KP}", "expected a scenario's variable"),
    ("ros: true\nros_parameters: {'k p': WEBSIM_KP}", "not a ROS parameter name"),
    ("ros: true\nros_parameters: [kp]", "'parameter: WEBSIM_NAME' entries"),
])
def test_bad_ros_parameters_are_refused_with_the_reason(tmp_path: Path, entry: str,
                                                        message: str) -> None:
    (tmp_path / SUBMISSION_FILE).write_text(f"command: python3 node.py\n{entry}\n")
    with pytest.raises(ConfigError, match=message):
        submission_declaration(tmp_path)


def declared_options(declared: Declared) -> GradeOptions:
    """The grading options a declaration gives."""
    return GradeOptions(ros=declared.ros, ros_parameters=declared.ros_parameters)
