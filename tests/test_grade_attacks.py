"""``websim grade`` attacked as a student would, and installed as an instructor would.

Real grade runs (a private simulator, the sandbox where bubblewrap and root are here, else
--no-sandbox): the ROS graph cannot change a graded run; the score reads the simulation's
own record; a CPU burner cannot starve a classmate's simulator; a checkout's ``.venv`` and
``node_modules`` are not copied and an oversized submission is a zero with its size; a
non-editable install gives controllers its Python with roslibpy whatever ``python3`` is.
"""

from __future__ import annotations

import csv
import itertools
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from grading import load_suite
from grading.recorded import (
    TRUTH_FILE,
    IncompleteRecordError,
    bag_folder,
    trajectory_from_bag,
    trajectory_from_truth,
)
from websim import cli

ROOT = Path(__file__).resolve().parent.parent
SOLUTIONS = ROOT / "examples" / "solutions"
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
SANDBOX_OPTIONS = () if SANDBOXED else ("--no-sandbox",)

pytestmark = pytest.mark.slow


def report(out: Path, scenario: str) -> dict[str, Any]:
    return json.loads((out / scenario / "report.json").read_text())


# --- the ROS graph is the bridge's equal ---------------------------------------------------

GRAPH_TAMPERER = """
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from std_srvs.srv import Empty

    rclpy.init()
    node = rclpy.create_node("tamperer")
    cmd = node.create_publisher(Twist, "/cmd_vel", 10)
    params = node.create_client(SetParameters, "/virtual_robot/set_parameters")
    reset = node.create_client(Empty, "/reset_simulation")
    state = {"odom": 0}

    def said(what):
        def done(future):
            answer = future.result()
            results = getattr(answer, "results", None)
            if results is None:
                print(what, "answered", flush=True)
            for result in results or []:
                print(what, "successful", result.successful, "reason", result.reason,
                      flush=True)
        return done

    def on_odom(odom):
        state["odom"] += 1
        if state["odom"] == 20:
            request = SetParameters.Request()
            for name, value in (("max_linear_mps", 0.01), ("mass_kg", 9.0)):
                request.parameters.append(Parameter(name=name, value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE, double_value=value)))
            params.call_async(request).add_done_callback(said("set_parameters"))
        if state["odom"] == 40:
            reset.call_async(Empty.Request()).add_done_callback(said("reset"))
        twist = Twist()
        twist.linear.x = 0.1
        cmd.publish(twist)

    node.create_subscription(Odometry, "/odom", on_odom, 10)
    rclpy.spin(node)
"""


def test_the_ros_graph_cannot_change_or_reset_a_graded_run(tmp_path: Path) -> None:
    """An rclpy controller sets the robot's limits and mass on the graph and calls
    /reset_simulation mid-run: both refused as the bridge refuses them; the robot drives on
    at 0.1 m/s, never sent back to its start."""
    pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
    folder = tmp_path / "mallory"
    folder.mkdir()
    (folder / "tamper.py").write_text(textwrap.dedent(GRAPH_TAMPERER))
    out = tmp_path / "out"
    assert cli.main(["grade", "heading_pid", "--ros", "--submission", str(folder), "--out",
                     str(out), *SANDBOX_OPTIONS, "--", "python3", "tamper.py"]) == 1
    graded = report(out, "heading_pid")
    output = graded["controller"]["output_tail"]
    refusal = "a graded run's robot cannot be changed or reset (websim grade)"
    assert output.count(f"set_parameters successful False reason {refusal}") == 2, output
    assert "reset answered" in output, output
    assert graded["run"]["ended_by"] == "duration"
    trajectory, _ = trajectory_from_truth(out / "heading_pid" / TRUTH_FILE,
                                          load_suite("heading_pid").entries[0].scenario)
    xs = [sample.x_m - trajectory[0].x_m for sample in trajectory]
    assert all(later >= earlier - 1e-9 for earlier, later in itertools.pairwise(xs))
    assert xs[-1] > 0.5  # 0.1 m/s for 8 s, less the start: the limit of 0.01 never held


# --- the score reads the simulation's own record -------------------------------------------

def test_the_score_reads_the_simulations_record_which_agrees_with_the_recording(
        tmp_path: Path) -> None:
    """truth.json (every tick, from the simulation) and the recording's /ground_truth give
    the same poses; a record with a gap is refused, never scored."""
    folder = tmp_path / "alice"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid.py", folder)
    out = tmp_path / "out"
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     *SANDBOX_OPTIONS, "--", "python3", "heading_pid.py"]) == 0
    graded = report(out, "heading_pid")
    scenario = load_suite("heading_pid").entries[0].scenario
    truth, notes = trajectory_from_truth(out / "heading_pid" / TRUTH_FILE, scenario)
    recorded = trajectory_from_bag(bag_folder(out / "heading_pid" / "recording"), scenario,
                                   graded["run"]["epoch_s"])
    assert len(truth) == round(scenario.duration_s / 0.05) + 1
    by_time = {round(sample.t_s, 6): sample for sample in recorded}
    common = [sample for sample in truth[1:] if round(sample.t_s, 6) in by_time]
    assert len(common) >= len(truth) - 2
    for sample in common:
        other = by_time[round(sample.t_s, 6)]
        assert (sample.x_m, sample.y_m) == pytest.approx((other.x_m, other.y_m), abs=1e-9)
    assert notes["recording"][0]["messages_lost"] == 0
    document = json.loads((out / "heading_pid" / TRUTH_FILE).read_text())
    del document["rows"][50]
    (out / "heading_pid" / TRUTH_FILE).write_text(json.dumps(document))
    with pytest.raises(IncompleteRecordError, match="has no tick 51"):
        trajectory_from_truth(out / "heading_pid" / TRUTH_FILE, scenario)


# --- one student's CPU is not a classmate's zero -------------------------------------------

CPU_BURNER = """
    import os
    for _ in range(15):
        if os.fork() == 0:
            break
    while True:
        pass
"""


def test_a_cpu_burner_does_not_starve_a_classmates_run(tmp_path: Path) -> None:
    """Graded in parallel (--jobs 2 on a 2-core machine): mallory's 16 spinning processes
    beside alice's reference. Her simulator starts and her run passes; mallory's controller
    runs at a low CPU weight within a one-core quota (its cgroup), or niced without one."""
    submissions = tmp_path / "submissions"
    for name, command, code in (("alice", "python3 heading_pid.py", None),
                                ("mallory", "python3 burn.py", CPU_BURNER)):
        folder = submissions / name
        folder.mkdir(parents=True)
        (folder / "websim-submission.yaml").write_text(f"command: {command}\n")
        if code is None:
            shutil.copy(SOLUTIONS / "heading_pid.py", folder)
        else:
            (folder / "burn.py").write_text(textwrap.dedent(code))
    out = tmp_path / "out"
    status = cli.main(["grade", "heading_pid", "--submissions", str(submissions), "--out",
                       str(out), "--jobs", "2", "--startup-timeout", "30", *SANDBOX_OPTIONS])
    assert status == 1  # mallory failed
    rows = {row["student"]: row for row in csv.DictReader((out / "grades.csv").open())}
    assert rows["alice"]["reason"] == "passed", rows["alice"]["reason"]
    assert float(rows["alice"]["total"]) == 1.0
    assert "did not subscribe to /odom" in rows["mallory"]["reason"]
    assert "within 30 s" in rows["mallory"]["reason"]
    if SANDBOXED:
        isolation = report(out / "mallory", "heading_pid")["controller"]["isolation"]
        assert "CPU share bounded by its cgroup" in isolation or "sampled" in isolation


# --- what is copied, what is refused ---------------------------------------------------------

def test_a_checkouts_venv_and_node_modules_are_not_copied_and_a_huge_file_is_a_zero(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Run from a checkout: its .venv and node_modules (here 300 MB each, sparse) are left
    out, as are its .websimignore's patterns; a 200 MB file it does not ignore is refused
    before copying, with its size, in the terminal and the report."""
    folder = tmp_path / "checkout"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid.py", folder)
    for name in (".venv/lib/big.bin", "node_modules/roslib/big.bin", "logs/run.bag"):
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as file:
            file.truncate(300 * 1024 * 1024)
    (folder / ".websimignore").write_text("# recordings\nlogs/*.bag\n")
    out = tmp_path / "out"
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     *SANDBOX_OPTIONS, "--", "python3", "heading_pid.py"]) == 0
    assert report(out, "heading_pid")["passed"] is True
    with (folder / "data.bin").open("wb") as file:
        file.truncate(200 * 1024 * 1024)
    assert cli.main(["grade", "heading_pid", "--submission", str(folder), "--out", str(out),
                     *SANDBOX_OPTIONS, "--", "python3", "heading_pid.py"]) == 1
    printed = capsys.readouterr().out
    graded = report(out, "heading_pid")
    assert graded["score"] == 0.0
    assert "not run: the submission is more than 200 MiB" in graded["reason"]
    assert "more than the 128 MiB a submission may be" in graded["reason"]
    assert "the submission is more than 200 MiB" in printed


# --- the runtime the docs promise, from a non-editable install -----------------------------

def test_a_wheel_install_gives_controllers_its_python_with_roslibpy(tmp_path: Path) -> None:
    """websim installed from its wheel into a venv of its own (as pipx does), run with the
    system's python3 first on PATH, which has no roslibpy: the roslibpy controller passes,
    because ``python3`` in the sandbox is websim's Python."""
    system_python = shutil.which("python3", path="/usr/bin")
    if system_python is None:
        pytest.skip("no /usr/bin/python3 to stand for the system's Python")
    lacks = subprocess.run([system_python, "-c", "import roslibpy"], capture_output=True,
                           check=False)
    assert lacks.returncode != 0, "the system's python3 has roslibpy: nothing to prove"
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q",
                    "-w", str(wheels)], check=True, timeout=600)
    wheel, = wheels.glob("websim-*.whl")
    venv = tmp_path / "pipx-venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True, timeout=300)
    # its dependencies, as pip would have installed them: this environment's, by path (not
    # its .pth files, whose editable hook would import this checkout instead of the wheel)
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig."
                              "get_paths()['purelib'])"], capture_output=True, text=True,
                             check=True).stdout.strip()
    dependencies = next(path for path in sys.path if path.endswith("site-packages"))
    (Path(purelib) / "dependencies.pth").write_text(f"{dependencies}\n")
    folder = tmp_path / "alice"
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid.py", folder)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {"PATH": "/usr/bin:/bin:/usr/sbin:/sbin", "HOME": str(elsewhere), "LANG": "C.UTF-8",
           "XDG_DATA_HOME": str(elsewhere / "data")}
    done = subprocess.run(
        [str(python), "-c", "import websim, sys; assert websim.__file__.startswith("
         f"{str(venv)!r}), websim.__file__; from websim.cli import main; "
         "sys.exit(main())", "grade", "heading_pid", "--submission", str(folder), "--out",
         str(elsewhere / "out"), *SANDBOX_OPTIONS, "--", "python3", "heading_pid.py"],
        cwd=elsewhere, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    graded = report(elsewhere / "out", "heading_pid")
    assert graded["passed"] is True, graded["reason"]
    assert "ModuleNotFoundError" not in graded["controller"]["output_tail"]
