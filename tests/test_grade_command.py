"""``websim grade``: real submissions (the reference roslibpy controllers and wrong ones) graded
against a private simulator, in the sandbox where bubblewrap and root are here (else with
--no-sandbox, which the reports then say), from the recording's ground truth."""

from __future__ import annotations

import json
import os
import shutil
import textwrap
from pathlib import Path
from typing import Any

import pytest

from websim import cli
from websim.grade_command import umask_for
from websim.grade_run import WALL_CLOCK_SCORE_TOLERANCE

SOLUTIONS = Path(__file__).resolve().parent.parent / "examples" / "solutions"
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
"""Where the sandbox can run, the tests grade in it; elsewhere with --no-sandbox (no skip)."""


def submission(folder: Path, *solutions: str, **files: str) -> Path:
    """A submission folder holding reference solutions and files written here."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in solutions:
        shutil.copy(SOLUTIONS / name, folder / name)
    for name, text in files.items():
        (folder / name).write_text(textwrap.dedent(text))
    return folder


def grade(suite: str, folder: Path, out: Path, *command: str,
          options: tuple[str, ...] = ()) -> int:
    """``websim grade`` in this process; its exit code."""
    sandbox = () if SANDBOXED else ("--no-sandbox",)
    return cli.main(["grade", suite, "--submission", str(folder), "--out", str(out),
                     *sandbox, *options, "--", *command])


def report(out: Path, scenario: str) -> dict[str, Any]:
    """A scenario's report.json."""
    return json.loads((out / scenario / "report.json").read_text())


def test_reference_heading_pid_passes_and_the_report_holds_everything(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = submission(tmp_path / "alice", "heading_pid.py")
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "heading_pid.py") == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith("heading_pid: 1.0000 passed: passed [deterministic, 8.0 s of sim")
    graded = report(out, "heading_pid")
    assert graded["score"] == 1.0 and graded["passed"] is True
    assert graded["run"]["ended_by"] == "duration" and graded["run"]["missed_steps"] == 0
    heading = graded["metrics"][0]
    assert heading["kind"] == "heading_step"
    assert {"value", "threshold", "passed", "score", "inputs", "weight"} <= set(heading)
    assert 0.5 < heading["value"] < 3.0 and heading["inputs"]["heading"] == "ground truth"
    assert graded["controller"]["sandboxed"] is SANDBOXED
    assert "reason" in graded["controller"] and "output_tail" in graded["controller"]
    bag = Path(graded["recording"])
    assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap"))
    page = (out / "heading_pid" / "report.html").read_text()
    assert graded["report_html"] == "report.html"
    assert page.count("<svg") >= 3 and "heading step: true heading and setpoint" in page
    assert "src=" not in page and 'href="http' not in page  # self-contained
    # the controller ran in a copy: the submission folder is as it was handed in
    assert sorted(p.name for p in folder.iterdir()) == ["heading_pid.py"]


def test_deterministic_mode_gives_the_same_score_to_the_last_digit(tmp_path: Path) -> None:
    folder = submission(tmp_path / "bob", "heading_pid.py")
    out = tmp_path / "out"
    assert grade("heading_pid_payload", folder, out, "python3", "heading_pid.py",
                 options=("--runs", "5")) == 1
    graded = report(out, "heading_pid_payload")
    assert graded["spread"]["range"] == 0.0
    runs = [json.loads((out / "heading_pid_payload" / f"run-{k}" / "report.json").read_text())
            for k in range(1, 6)]
    metrics = [run["metrics"] for run in runs]
    assert all(m == metrics[0] for m in metrics), "metrics differ between identical runs"
    # the payload bonus: the plain PID slips and fails, the same way every time, and the
    # reason says what changed at 5 s and how the controller is told
    assert runs[0]["score"] < 1.0
    assert "the scenario changed setpoint_rad to 0.0 and the payload at t = 5 s" \
        in graded["reason"]
    assert "WEBSIM_SETPOINT_RAD_CHANGES tells the controller" in graded["reason"]


def test_wall_clock_mode_reports_its_spread_within_the_tolerance(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = submission(tmp_path / "carol", "heading_pid.py")
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "heading_pid.py",
                 options=("--mode", "wall-clock", "--runs", "3")) == 0
    printed = capsys.readouterr().out
    assert "median of 3 runs, spread" in printed
    graded = report(out, "heading_pid")
    spread = graded["spread"]
    assert len(spread["scores"]) == 3 and graded["mode"] == "wall-clock"
    assert spread["range"] <= WALL_CLOCK_SCORE_TOLERANCE
    assert len(spread["metric_values"]["heading_step"]["values"]) == 3


def test_wrong_sign_fails_on_the_heading_step(tmp_path: Path) -> None:
    folder = submission(tmp_path / "dave", "heading_pid.py")
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "env", "WEBSIM_KP=-4", "python3",
                 "heading_pid.py") == 1
    graded = report(out, "heading_pid")
    assert graded["passed"] is False and graded["score"] == 0.0
    assert graded["reason"].startswith("heading_step: ")
    assert "never settled" in graded["reason"]
    assert graded["run"]["ended_by"] == "duration"


def test_reference_wall_follower_passes_a_wall_scenario(tmp_path: Path) -> None:
    folder = submission(tmp_path / "erin", "wall_follower.py")
    out = tmp_path / "out"
    suite = tmp_path / "one_wall.yaml"
    suite.write_text(textwrap.dedent("""\
        name: one_wall
        scenarios:
          - scenario:
              name: corridor_right_close_fast
              world: corridor
              start: [-0.5, 0.0, 0.2]
              duration_s: 120.0
              parameters: {side: right, desired_distance_m: 0.35, speed_mps: 0.4}
              end: {point: [5.5, 4.0], radius_m: 1.0}
              metrics: [{kind: wall_following}]
        """))
    assert grade(str(suite), folder, out, "python3", "wall_follower.py") == 0
    graded = report(out, "corridor_right_close_fast")
    assert graded["passed"] is True and graded["score"] > 0.95
    assert graded["run"]["ended_by"] == "end_point"


def test_a_controller_that_never_connects_scores_zero_with_the_reason(tmp_path: Path) -> None:
    folder = submission(tmp_path / "frank", **{"hang.py": "import time\ntime.sleep(600)\n"})
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "hang.py",
                 options=("--startup-timeout", "3")) == 1
    graded = report(out, "heading_pid")
    assert graded["score"] == 0.0 and graded["passed"] is False
    assert graded["run"]["ended_by"] == "no_start"
    assert "did not subscribe to /odom or /scan or /clock" in graded["reason"]
    assert "within 3 s" in graded["reason"]
    assert graded["controller"]["ended_by"] == "server_exit"


def test_a_controller_that_stops_answering_scores_zero_with_the_reason(tmp_path: Path) -> None:
    folder = submission(tmp_path / "grace", **{"mute.py": """\
        import os, time
        from urllib.parse import urlsplit
        import roslibpy
        url = urlsplit(os.environ["WEBSIM_URL"])
        ros = roslibpy.Ros(url.hostname, url.port)
        ros.run()
        roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(lambda m: None)
        print("subscribed, answering nothing", flush=True)
        while ros.is_connected:
            time.sleep(0.2)
        """})
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "mute.py") == 1
    graded = report(out, "heading_pid")
    assert graded["score"] == 0.0 and graded["run"]["ended_by"] == "no_answer"
    assert "did not answer /odom within 5 s 3 times" in graded["reason"]
    assert "--mode wall-clock" in graded["reason"]
    assert "answering nothing" in graded["controller"]["output_tail"]


def test_a_crash_scores_zero_with_its_last_output(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The reason says why, where the instructor looks: the exception's last line in the
    terminal and report.json; report.html shows no passing row for the run."""
    folder = submission(tmp_path / "heidi", **{"crash.py": "import json\njson.loads('{')\n"})
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "crash.py") == 1
    graded = report(out, "heading_pid")
    assert graded["score"] == 0.0
    assert "the controller ended before the run did" in graded["reason"]
    assert "exited with code 1: json.decoder.JSONDecodeError: Expecting property name" \
        in graded["reason"]
    assert "JSONDecodeError: Expecting property name" in capsys.readouterr().out
    assert "json.loads('{')" in graded["controller"]["output_tail"]
    page = (out / "heading_pid" / "report.html").read_text()
    assert "<td>yes</td>" not in page and "not judged" in page


def test_the_controller_cannot_reset_pause_or_fake_the_graded_run(tmp_path: Path) -> None:
    folder = submission(tmp_path / "ivan", "heading_pid.py", **{"reset.py": """\
        import os, time
        from urllib.parse import urlsplit
        import roslibpy
        from heading_pid import HeadingPid
        url = urlsplit(os.environ["WEBSIM_URL"])
        ros = roslibpy.Ros(url.hostname, url.port)
        ros.run()
        goal = {"position": {"x": 9.0, "y": 9.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.7071, "w": 0.7071}}
        for name, kind, args in (
                ("/reset_simulation", "std_srvs/srv/Empty", {}),
                ("/websim/pause", "websim/srv/Pause", {"paused": True}),
                ("/set_entity_state", "simulation_interfaces/srv/SetEntityState",
                 {"entity": "robot", "state": {"pose": goal}}),
                ("/robot/teleport_absolute", "turtlesim/srv/TeleportAbsolute",
                 {"x": 9.0, "y": 9.0, "theta": 1.5708}),
                ("/set_simulation_state", "simulation_interfaces/srv/SetSimulationState",
                 {"state": {"state": 2}})):
            try:
                roslibpy.Service(ros, name, kind).call(roslibpy.ServiceRequest(args), timeout=5)
                print(name, "ACCEPTED", flush=True)
            except Exception as error:
                print(name, "REFUSED:", error, flush=True)
        fake = roslibpy.Topic(ros, "/ground_truth", "nav_msgs/msg/Odometry")
        fake.advertise()
        for _ in range(3):  # a pose that "settled" at once, 9 m away
            fake.publish(roslibpy.Message({"header": {"frame_id": "map"}, "pose": {"pose": {
                "position": {"x": 9.0, "y": 9.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.7071, "w": 0.7071}}}}))
        HeadingPid(ros, 0.0)  # never turns: only a fake could pass it
        while ros.is_connected:
            time.sleep(0.2)
        """})
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "python3", "reset.py") == 1
    graded = report(out, "heading_pid")
    output = graded["controller"]["output_tail"]
    assert "/reset_simulation REFUSED" in output and "cannot be reset" in output
    assert "/websim/pause REFUSED" in output and "needs admin rights" in output
    for name in ("/set_entity_state", "/robot/teleport_absolute", "/set_simulation_state"):
        assert f"{name} REFUSED" in output  # no simulation services in a graded run
    # graded on the robot's own ground truth, as recorded from its tap: the fake is not in it
    assert graded["passed"] is False and graded["score"] == 0.0
    assert "never settled" in graded["reason"]


def test_bad_input_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = submission(tmp_path / "judy", "heading_pid.py")
    assert cli.main(["grade", "heading_pid", "--submission", str(folder)]) == 2
    assert "no controller command: give it after --" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("world: empty\nduration_s: 5\nmetrics: [{kind: heading_stp}]\n")
    assert grade(str(bad), folder, tmp_path / "out", "python3", "heading_pid.py") == 2
    assert "did you mean 'heading_step'" in capsys.readouterr().err


ROSLIB = SOLUTIONS.parent.parent / "web-interface" / "node_modules"


@pytest.mark.skipif(shutil.which("node") is None or not (ROSLIB / "roslib").is_dir(),
                    reason="Node or roslib missing: run npm ci in web-interface/")
def test_roslibjs_heading_pid_grades_as_the_roslibpy_one(tmp_path: Path) -> None:
    python_folder = submission(tmp_path / "py", "heading_pid.py")
    node_folder = submission(tmp_path / "js", "heading_pid.js")  # websim gives it roslib
    assert grade("heading_pid", python_folder, tmp_path / "out-py", "python3",
                 "heading_pid.py") == 0
    assert grade("heading_pid", node_folder, tmp_path / "out-js", "node", "heading_pid.js") == 0
    by_python = report(tmp_path / "out-py", "heading_pid")
    by_node = report(tmp_path / "out-js", "heading_pid")
    assert by_node["passed"] is True and by_node["score"] == 1.0
    # the same controller in two languages, in lock step: the same trajectory, to the digit
    assert by_node["metrics"] == by_python["metrics"]


def test_a_node_modules_folder_without_roslib_is_refused_before_grading(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = submission(tmp_path / "js", "heading_pid.js")
    empty = tmp_path / "modules"
    empty.mkdir()
    out = tmp_path / "out"
    assert grade("heading_pid", folder, out, "node", "heading_pid.js",
                 options=("--node-modules", str(empty))) == 2
    assert f"--node-modules {empty}: no roslib there" in capsys.readouterr().err
    assert not (out / "heading_pid" / "report.json").exists()


def test_reference_go_to_goal_passes_the_maze(tmp_path: Path) -> None:
    folder = submission(tmp_path / "kim", "go_to_goal.py")
    out = tmp_path / "out"
    assert grade("go_to_goal", folder, out, "python3", "go_to_goal.py") == 0
    graded = report(out, "go_to_goal")
    assert graded["passed"] is True and graded["score"] > 0.9
    by_name = {metric["name"]: metric for metric in graded["metrics"]}
    assert by_name["collisions"]["value"] == 0
    assert by_name["go_to_goal"]["value"] < 40.0  # seconds to the goal


def test_the_slew_limited_heading_pid_passes_the_payload_bonus(tmp_path: Path) -> None:
    folder = submission(tmp_path / "lee", "heading_pid.py")
    out = tmp_path / "out"
    assert grade("heading_pid_payload", folder, out, "python3", "heading_pid.py", "--slew",
                 "0.25") == 0
    graded = report(out, "heading_pid_payload")
    assert graded["passed"] is True and graded["score"] == 1.0
    steps = graded["metrics"][0]["figures"]["steps"]
    assert len(steps) == 2 and all(step["settling_time_s"] < 3.0 for step in steps)


def test_the_exit_status_follows_the_verdict_or_fail_under(tmp_path: Path) -> None:
    """0 passed, 1 failed, 2 bad input; --fail-under moves the bar to a total."""
    good = submission(tmp_path / "alice", "heading_pid.py")
    assert grade("heading_pid", good, tmp_path / "a", "python3", "heading_pid.py",
                 options=("--fail-under", "0.99")) == 0
    wrong = submission(tmp_path / "dave", "heading_pid.py")
    assert grade("heading_pid", wrong, tmp_path / "d", "env", "WEBSIM_KP=-4", "python3",
                 "heading_pid.py", options=("--fail-under", "0")) == 0
    assert grade("heading_pid", wrong, tmp_path / "d", "python3", "missing.py") == 1
    assert grade("heading_pid", wrong, tmp_path / "d", "python3", "heading_pid.py",
                 options=("--fail-under", "2")) == 2


def test_output_modes_give_folders_x_where_files_have_r() -> None:
    assert umask_for(0o600) == 0o077
    assert umask_for(0o640) == 0o027
    assert umask_for(0o644) == 0o022
