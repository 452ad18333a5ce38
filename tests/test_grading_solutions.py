"""The reference solutions of every shipped assignment, in roslibpy, roslibjs and rclpy, each
graded by ``websim grade`` on its scenario (deterministic mode, in the sandbox) and passing.

The heading PID's three are graded in tests/test_grade_command.py and tests/test_grade_rclpy.py;
here are wall following and go to goal. Each language's controller is the same algorithm, so
each is held to the same bar: wall following's whole six-scenario suite, the maze's goal.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
from pathlib import Path
from typing import Any

import pytest

from grading import load_suite
from websim import cli

SOLUTIONS = Path(__file__).resolve().parent.parent / "examples" / "solutions"
ROSLIB = SOLUTIONS.parent.parent / "web-interface" / "node_modules"
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
"""Where the sandbox can run, the tests grade in it; elsewhere with --no-sandbox (no skip)."""

needs_node = pytest.mark.skipif(
    shutil.which("node") is None or not (ROSLIB / "roslib").is_dir(),
    reason="Node or roslib missing: run npm ci in web-interface/")
needs_rclpy = pytest.mark.skipif(importlib.util.find_spec("rclpy") is None,
                                 reason="rclpy not installed (pip install .[ros])")


def grade(suite: str, solution: str, tmp_path: Path, *command: str,
          ros: bool = False) -> dict[str, Any]:
    """Grade one reference solution in a folder of its own; the suite's summary."""
    folder = tmp_path / "submission"
    folder.mkdir()
    shutil.copy(SOLUTIONS / solution, folder)
    if solution.endswith(".js"):
        shutil.copytree(ROSLIB, folder / "node_modules", symlinks=True)
    out = tmp_path / "out"
    options = ([] if SANDBOXED else ["--no-sandbox"]) + (["--ros"] if ros else [])
    assert cli.main(["grade", suite, "--submission", str(folder), "--out", str(out),
                     *options, "--", *command]) == 0
    summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
    return summary


def passes_every_scenario(summary: dict[str, Any], suite: str) -> None:
    names = [entry.scenario.name for entry in load_suite(suite).entries]
    assert [row["name"] for row in summary["scenarios"]] == names
    for row in summary["scenarios"]:
        assert row["passed"] is True, (row["name"], row["reason"])


@pytest.mark.parametrize("suite, solution, command, ros", [
    pytest.param("wall_following_suite", "wall_follower.js", ("node",), False,
                 marks=needs_node, id="roslibjs-wall-following"),
    pytest.param("wall_following_suite", "wall_follower_rclpy.py", ("python3",), True,
                 marks=needs_rclpy, id="rclpy-wall-following"),
    pytest.param("go_to_goal", "go_to_goal.js", ("node",), False,
                 marks=needs_node, id="roslibjs-go-to-goal"),
    pytest.param("go_to_goal", "go_to_goal_rclpy.py", ("python3",), True,
                 marks=needs_rclpy, id="rclpy-go-to-goal"),
])
def test_a_reference_solution_passes_every_scenario_of_its_assignment(
        tmp_path: Path, suite: str, solution: str, command: tuple[str, ...],
        ros: bool) -> None:
    summary = grade(suite, solution, tmp_path, *command, solution, ros=ros)
    passes_every_scenario(summary, suite)
    assert summary["total"] > 0.9
