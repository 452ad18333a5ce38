"""``websim grade --ros``: rclpy controllers graded on the ROS graph of their private simulator,
in the sandbox (bubblewrap, root), from the recording's ground truth."""

from __future__ import annotations

import json
import os
import shutil
import textwrap
from pathlib import Path
from typing import Any

import pytest

from grading import load_scenario
from grading.recorded import bag_folder, trajectory_from_bag
from websim import cli

pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytestmark = pytest.mark.skipif(
    shutil.which("bwrap") is None or os.geteuid() != 0,
    reason="bubblewrap (bwrap) not installed, or not root: the sandbox needs both "
           "(apt-get install bubblewrap)")

SOLUTIONS = Path(__file__).resolve().parent.parent / "examples" / "solutions"

SIM_TIME_PROBE = """
    import os
    import time
    import rclpy
    from nav_msgs.msg import Odometry

    rclpy.init()
    node = rclpy.create_node("probe")
    print("domain", os.environ.get("ROS_DOMAIN_ID"), flush=True)
    print("use_sim_time", node.get_parameter("use_sim_time").value, flush=True)
    seen = []

    def on_odom(odom):
        seen.append(odom)
        if len(seen) == 10:
            time.sleep(600)  # its executor stops: it can no longer see a tick

    node.create_subscription(Odometry, "/odom", on_odom, 10)
    rclpy.spin(node)
"""
"""Subscribes /odom, never answers, and blocks its executor at the 10th: deterministic mode
must end it with the reason."""

INCOMPATIBLE = """
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.qos import DurabilityPolicy, QoSProfile

    rclpy.init()
    node = rclpy.create_node("late_joiner")
    pub = node.create_publisher(Twist, "cmd_vel", 10)
    node.create_subscription(Odometry, "odom", lambda odom: pub.publish(Twist()),
                             QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    rclpy.spin(node)
"""
"""Subscribes /odom TRANSIENT_LOCAL (a volatile publisher cannot serve it): it gets nothing."""

STUDENTS = Path(__file__).resolve().parent / "grading_students"

CORRIDOR_RIGHT = """\
description: the right wall of the corridor's first leg, with rplidar_ros's scan angles
world: corridor
start: [-0.5, 0.0, 0.0]
duration_s: 30
lidar: {angle_min_rad: -pi}
parameters: {side: right, desired_distance_m: 0.5, speed_mps: 0.3}
end: {point: [4.0, 0.0], radius_m: 1.0}
metrics:
  - kind: wall_following
"""

CLOSE_FAST = """\
description: the suite's corridor_right_close_fast (0.35 m from the right wall at 0.4 m/s)
world: corridor
start: [-0.5, 0.0, 0.2]
duration_s: 120.0
parameters: {side: right, desired_distance_m: 0.35, speed_mps: 0.4}
end: {point: [5.5, 4.0], radius_m: 1.0}
metrics: [{kind: wall_following}, {kind: smoothness}]
"""

GOAL_IN_THE_OPEN = """\
description: to a point in the empty arena and stop there
world: empty
duration_s: 30
parameters: {goal_x_m: 1.0, goal_y_m: 0.5, goal_radius_m: 0.25}
metrics:
  - kind: go_to_goal
"""


def grade(folder: Path, out: Path, *command: str, options: tuple[str, ...] = ()) -> int:
    """``websim grade heading_pid --ros`` in this process; its exit code."""
    return cli.main(["grade", "heading_pid", "--ros", "--submission", str(folder),
                     "--out", str(out), *options, "--", *command])


def report(out: Path) -> dict[str, Any]:
    """heading_pid's report.json."""
    return json.loads((out / "heading_pid" / "report.json").read_text())


def test_reference_rclpy_heading_pid_passes_the_same_on_every_run(tmp_path: Path) -> None:
    """Deterministic mode on the graph: every /odom answered, three runs identical."""
    folder = tmp_path / "alice"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid_rclpy.py", folder)
    out = tmp_path / "out"
    assert grade(folder, out, "python3", "heading_pid_rclpy.py", options=("--runs", "3")) == 0
    graded = report(out)
    assert graded["score"] == 1.0 and graded["passed"] is True, graded["reason"]
    assert graded["spread"]["range"] == 0.0
    for name, spread in graded["spread"]["metric_values"].items():
        assert spread["range"] == 0.0, (name, spread["values"])
    for k in (1, 2, 3):
        run = json.loads((out / "heading_pid" / f"run-{k}" / "report.json").read_text())
        assert run["run"]["ended_by"] == "duration"
        assert run["run"]["missed_steps"] == 0
        # one /cmd_vel per /odom (the last /odom's comes after the run's end)
        assert run["run"]["commands"] == run["run"]["ticks"] - 1
        assert run["controller"]["sandboxed"] is True
        assert run["controller"]["command"][-3:] == ["--ros-args", "-p", "use_sim_time:=true"]


def test_an_rclpy_node_whose_executor_blocks_is_stopped_with_the_reason(
        tmp_path: Path) -> None:
    """It gets a ROS domain and sim time; a blocked executor is missed steps, not a hang."""
    folder = tmp_path / "mute"
    folder.mkdir()
    (folder / "probe.py").write_text(textwrap.dedent(SIM_TIME_PROBE))
    out = tmp_path / "out"
    assert grade(folder, out, "python3", "probe.py") == 1  # it failed
    graded = report(out)
    assert graded["score"] == 0.0 and graded["passed"] is False
    assert graded["run"]["ended_by"] == "no_answer" and graded["run"]["step_on"] == "handshake"
    assert "did not answer the simulator's handshake" in graded["reason"]
    # its 10th /odom blocks it: ticks 11 and 12 run after a missed handshake each, the third
    # miss ends the run
    assert graded["run"]["ticks"] == 12 and graded["run"]["missed_steps"] == 3
    assert graded["run"]["first_miss_s"] == 0.5
    output = graded["controller"]["output_tail"]
    assert "use_sim_time True" in output, output
    domain = output.split("domain ", 1)[1].split()[0]
    assert 1 <= int(domain) <= 101


def submission(folder: Path, script: str, declaration: str) -> Path:
    """A submission folder with one of tests/grading_students/ and its declaration."""
    folder.mkdir()
    shutil.copy(STUDENTS / script, folder)
    (folder / "websim-submission.yaml").write_text(textwrap.dedent(declaration))
    return folder


def grade_scenario(tmp_path: Path, name: str, text: str, folder: Path) -> dict[str, Any]:
    """Grade the submission ``folder`` declares on the scenario ``text``; its report."""
    scenario = tmp_path / f"{name}.yaml"
    scenario.write_text(text)
    out = tmp_path / "out"
    assert cli.main(["grade", str(scenario), "--submission", str(folder), "--out",
                     str(out)]) == 0
    graded: dict[str, Any] = json.loads((out / name / "report.json").read_text())
    return graded


def test_a_timer_driven_node_regrades_identically_to_the_last_digit(tmp_path: Path) -> None:
    """The usual course style: a 7 Hz timer on sim time (not the 20 Hz tick), the latest
    /odom from a callback, its start time read before the first /clock, its setpoint a ROS
    parameter the submission maps from the scenario's. Three re-grades, one trajectory."""
    folder = submission(tmp_path / "carol", "timer_heading_pid.py", """\
        command: python3 timer_heading_pid.py --ros-args -p rate_hz:=7.0 -p run_s:=6.0
        ros: true
        ros_parameters: {setpoint_rad: WEBSIM_SETPOINT_RAD}
        """)
    out = tmp_path / "out"
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     "--runs", "3"]) == 0
    graded = report(out)
    assert graded["passed"] is True, graded["reason"]
    assert graded["spread"]["range"] == 0.0
    for name, spread in graded["spread"]["metric_values"].items():
        assert spread["range"] == 0.0, (name, spread["values"])
    runs = [json.loads((out / "heading_pid" / f"run-{k}" / "report.json").read_text())
            for k in (1, 2, 3)]
    for run in runs:
        assert run["run"]["step_on"] == "handshake" and run["run"]["missed_steps"] == 0
        assert run["run"]["epoch_s"] == 0.0 and not run["run"]["wall_paced"]
        assert run["controller"]["command"][-2:] == ["-p", "setpoint_rad:=1.5707963267948966"]
        # a command at every tick its timer fired: t = k / 7 s, for 8 s less the last tick
        assert run["run"]["commands"] == 55
    recordings = [trajectory_from_bag(bag_folder(out / "heading_pid" / f"run-{k}" /
                                                 "recording"), load_scenario("heading_pid"),
                                      0.0) for k in (1, 2, 3)]
    assert recordings[0] == recordings[1] == recordings[2]


def test_a_node_that_answers_odom_from_the_latest_scan_regrades_identically(
        tmp_path: Path) -> None:
    """Two topics, one callback reading the other's latest: the tick's messages reach it one
    at a time, in the robot's order, so it reads the same scan on every re-grade (when they
    raced, four re-grades of this scenario scored 0.9811, 0.9814, 0.9825, 0.9817)."""
    folder = tmp_path / "gina"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "wall_follower_rclpy.py", folder)
    scenario = tmp_path / "close_fast.yaml"
    scenario.write_text(CLOSE_FAST)
    out = tmp_path / "out"
    assert cli.main(["grade", str(scenario), "--ros", "--submission", str(folder), "--out",
                     str(out), "--runs", "3", "--", "python3", "wall_follower_rclpy.py"]) == 0
    graded = json.loads((out / "close_fast" / "report.json").read_text())
    assert graded["passed"] is True, graded["reason"]
    for name, spread in graded["spread"]["metric_values"].items():
        assert spread["range"] == 0.0, (name, spread["values"])


def test_a_reliable_scan_subscriber_reading_minus_pi_to_pi_follows_the_wall(
        tmp_path: Path) -> None:
    """/scan is offered reliable in a graded run, and the scenario sets -pi..pi."""
    folder = submission(tmp_path / "dave", "reliable_scan_follower.py", """\
        command: python3 reliable_scan_follower.py
        ros: true
        ros_parameters: {distance: WEBSIM_DESIRED_DISTANCE_M, speed: WEBSIM_SPEED_MPS}
        """)
    graded = grade_scenario(tmp_path, "corridor_right", CORRIDOR_RIGHT, folder)
    assert graded["passed"] is True, graded["reason"]
    assert graded["run"]["ended_by"] == "end_point"
    assert "/scan" in graded["run"]["subscribed"] and graded["run"]["incompatible_qos"] == []


def test_an_incompatible_subscription_is_named_in_the_reason(tmp_path: Path) -> None:
    folder = tmp_path / "erin"
    folder.mkdir()
    (folder / "late.py").write_text(textwrap.dedent(INCOMPATIBLE))
    out = tmp_path / "out"
    assert grade(folder, out, "python3", "late.py") == 1  # graded, and failed
    graded = report(out)
    assert graded["score"] == 0.0 and graded["run"]["commands"] == 0
    assert "/odom: /late_joiner subscribes RELIABLE, TRANSIENT_LOCAL, the simulator " \
           "publishes RELIABLE, VOLATILE: incompatible QoS" in graded["reason"]
    assert len(graded["run"]["incompatible_qos"]) == 1


def test_a_node_that_exits_after_its_goal_is_scored_until_then(tmp_path: Path) -> None:
    folder = submission(tmp_path / "frank", "goal_then_exit.py", """\
        command: [python3, goal_then_exit.py]
        ros: true
        ros_parameters: {goal_x: WEBSIM_GOAL_X_M, goal_y: WEBSIM_GOAL_Y_M}
        """)
    graded = grade_scenario(tmp_path, "goal_in_the_open", GOAL_IN_THE_OPEN, folder)
    assert graded["passed"] is True and graded["score"] > 0.9, graded["reason"]
    assert graded["controller"]["exit_code"] == 0 and graded["run"]["ended_by"] == "stopped"
    assert "the controller exited with code 0 after its last command" in graded["reason"]
    assert "score_if_completed" not in graded


def test_wall_clock_mode_grades_a_node_its_submission_declares_rclpy(tmp_path: Path) -> None:
    """``ros: true`` in websim-submission.yaml is --ros; at 1x the run starts once the node
    is on the graph (its /clock or /odom)."""
    folder = tmp_path / "bob"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid_rclpy.py", folder)
    (folder / "websim-submission.yaml").write_text(
        "command: python3 heading_pid_rclpy.py\nros: true\n")
    out = tmp_path / "out"
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     "--mode", "wall-clock"]) == 0
    graded = report(out)
    assert graded["passed"] is True, graded["reason"]
    assert graded["run"]["mode"] == "wall-clock" and graded["run"]["ended_by"] == "duration"
    assert graded["run"]["commands"] > 100
