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

from websim import cli

pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytestmark = pytest.mark.skipif(
    shutil.which("bwrap") is None or os.geteuid() != 0,
    reason="bubblewrap (bwrap) not installed, or not root: the sandbox needs both "
           "(apt-get install bubblewrap)")

SOLUTIONS = Path(__file__).resolve().parent.parent / "examples" / "solutions"

SIM_TIME_PROBE = """
    import os
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry

    rclpy.init()
    node = rclpy.create_node("probe")
    print("domain", os.environ.get("ROS_DOMAIN_ID"), flush=True)
    print("use_sim_time", node.get_parameter("use_sim_time").value, flush=True)
    node.create_subscription(Odometry, "/odom", lambda odom: None, 10)
    rclpy.spin(node)
"""
"""Subscribes /odom and never answers: deterministic mode must end it with the reason."""


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


def test_an_rclpy_node_that_does_not_answer_is_stopped_with_the_reason(
        tmp_path: Path) -> None:
    """It gets a ROS domain and sim time; its silence is missed steps, not a hang."""
    folder = tmp_path / "mute"
    folder.mkdir()
    (folder / "probe.py").write_text(textwrap.dedent(SIM_TIME_PROBE))
    out = tmp_path / "out"
    assert grade(folder, out, "python3", "probe.py") == 1  # it failed
    graded = report(out)
    assert graded["score"] == 0.0 and graded["passed"] is False
    assert graded["run"]["ended_by"] == "no_answer"
    assert "did not answer /odom" in graded["reason"]
    output = graded["controller"]["output_tail"]
    assert "use_sim_time True" in output, output
    domain = output.split("domain ", 1)[1].split()[0]
    assert 1 <= int(domain) <= 101


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
