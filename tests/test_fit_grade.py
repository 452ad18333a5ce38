"""``websim grade --params``: a graded run on the robot of a parameter file (``websim fit``'s)."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import pytest

from grading import load_scenario
from physics import RobotParams
from websim import cli
from websim.grade_server import on_robot

SOLUTIONS = Path(__file__).resolve().parent.parent / "examples" / "solutions"
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0


def heading_metric(tmp_path: Path, name: str, *options: str) -> dict:
    folder = tmp_path / name
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid.py", folder / "heading_pid.py")
    out = tmp_path / f"{name}-out"
    sandbox = () if SANDBOXED else ("--no-sandbox",)
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     *sandbox, *options, "--", "python3", "heading_pid.py"]) in (0, 1)  # graded
    report = json.loads((out / "heading_pid" / "report.json").read_text())
    assert report["run"]["ended_by"] == "duration"
    return report["metrics"][0]


def test_a_graded_run_uses_the_robot_of_the_parameter_file(tmp_path: Path) -> None:
    slow = tmp_path / "fitted.yaml"
    slow.write_text("robot:\n  cmd_lag_s: 0.3\n  angular_scale: 0.6\n"
                    "  angular_accel_limit_rps2: 2.0\n")
    shipped = heading_metric(tmp_path, "shipped")
    lagged = heading_metric(tmp_path, "lagged", "--params", str(slow))
    assert shipped["inputs"] == lagged["inputs"]
    assert lagged["value"] != pytest.approx(shipped["value"], rel=0.05)


def test_a_bad_parameter_file_is_refused_before_any_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot:\n  cmd_lag_s: -1\n")
    assert cli.main(["grade", "heading_pid", "--submission", str(tmp_path), "--params",
                     str(bad), "--no-sandbox", "--", "python3", "x.py"]) == 2
    assert "cmd_lag_s" in capsys.readouterr().err


def test_the_scenarios_payload_stays_on_the_fitted_robot(tmp_path: Path) -> None:
    fitted = tmp_path / "fitted.yaml"
    fitted.write_text("robot:\n  linear_scale: 0.9\n  mass_kg: 1.5\n")
    plain = on_robot(load_scenario("heading_pid"), str(fitted))
    assert plain.robot.linear_scale == 0.9 and plain.robot.mass_kg == 1.5
    heavy = tmp_path / "heavy.yaml"  # heading_pid with a payload from the start
    heavy.write_text((Path(__file__).resolve().parent.parent / "examples" / "scenarios" /
                      "heading_pid.yaml").read_text() + "payload: {scale: 2.0}\n")
    payload = on_robot(load_scenario(heavy), str(fitted))
    assert payload.robot.linear_scale == 0.9
    assert payload.robot.mass_kg == load_scenario(heavy).robot.mass_kg == 2.4
    assert on_robot(load_scenario("heading_pid"), None) == load_scenario("heading_pid")
    assert dataclasses.replace(plain.robot, linear_scale=1.0, mass_kg=1.2) == RobotParams()
