"""``websim compare``, run in-process through ``main(argv)`` into a temporary directory."""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from pathlib import Path

import pytest

from physics import RobotParams, compare_modes, load_commands, load_world
from physics.compare import TRAJECTORY_COLUMNS, HeadingController
from physics.pid import PidGains
from websim.cli import main
from websim.compare_command import plots_hint, progress_bar

EXAMPLES = Path(__file__).parent.parent / "examples" / "commands"
STEP = EXAMPLES / "step.yaml"
STEP_TICKS = round(5.0 / 0.05)
"""step.yaml lasts 5 s: 100 ticks of 0.05 s."""

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run_compare(tmp_path: Path, *extra: str, commands: Path = STEP) -> int:
    return main(["compare", "--commands", str(commands), "--out", str(tmp_path / "out"),
                 *extra])


def read_rows(tmp_path: Path) -> list[dict[str, str]]:
    with (tmp_path / "out" / "trajectory.csv").open(encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


def read_summary(tmp_path: Path) -> dict[str, object]:
    return dict(json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8")))


def test_writes_trajectory_summary_and_figure(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    assert run_compare(tmp_path) == 0
    out = tmp_path / "out"
    header = (out / "trajectory.csv").read_text(encoding="utf-8").splitlines()[0]
    assert header.split(",") == list(TRAJECTORY_COLUMNS)
    rows = read_rows(tmp_path)
    assert len(rows) == 2 * (1 + STEP_TICKS)
    for mode in ("kinematic", "dynamic"):
        times = [float(row["t_s"]) for row in rows if row["mode"] == mode]
        assert times[0] == 0.0 and times[-1] == pytest.approx(5.0)
        assert len(times) == 1 + STEP_TICKS
    png = (out / "comparison.png").read_bytes()
    assert png.startswith(PNG_MAGIC) and len(png) > 10_000
    assert "comparison.png" in capsys.readouterr().out


def test_summary_is_what_physics_compare_returns(tmp_path: Path) -> None:
    assert run_compare(tmp_path, "--seed", "3") == 0
    expected = compare_modes(load_world("empty"), load_commands(STEP), seed=3).summary
    assert read_summary(tmp_path) == json.loads(json.dumps(expected))


def test_trajectory_rows_are_the_simulated_ticks(tmp_path: Path) -> None:
    assert run_compare(tmp_path) == 0
    expected = compare_modes(load_world("empty"), load_commands(STEP)).rows
    rows = read_rows(tmp_path)
    assert [row["mode"] for row in rows] == [r.mode for r in expected]
    for row, tick in zip(rows, expected, strict=True):
        for column in TRAJECTORY_COLUMNS[2:]:
            assert float(row[column]) == getattr(tick, column), "written at full precision"


def test_without_matplotlib_the_rest_still_runs(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    for name in [name for name in sys.modules if name.partition(".")[0] == "matplotlib"]:
        monkeypatch.setitem(sys.modules, name, None)  # importing it, or any part, fails
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    assert run_compare(tmp_path) == 0
    out = tmp_path / "out"
    assert (out / "trajectory.csv").exists() and (out / "summary.json").exists()
    assert not (out / "comparison.png").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(f"matplotlib is not installed: {plots_hint()}")
    checkout = Path(__file__).resolve().parent.parent  # run from a checkout: its own extra
    assert f"pip install -e '{checkout}[plots]'" in err[0]


def test_heavier_robot_doubles_the_dynamic_rise_time(tmp_path: Path) -> None:
    assert run_compare(tmp_path / "plain") == 0
    assert run_compare(tmp_path / "heavy", "--set", "mass_kg=2.4") == 0
    rises = [read_summary(tmp_path / name)["dynamic"]["steps"][0]["v"]["rise_time_s"]  # type: ignore[index]
             for name in ("plain", "heavy")]
    accel = RobotParams().max_linear_accel_mps2
    assert rises[0] == pytest.approx(0.9 * 0.4 / accel)  # traction-limited
    assert rises[1] / rises[0] == pytest.approx(2.0, rel=0.05)
    kinematic = [read_summary(tmp_path / name)["kinematic"] for name in ("plain", "heavy")]
    assert kinematic[0] == kinematic[1], "mass does not affect the kinematic model"


@pytest.mark.parametrize(("override", "message"), [
    ("mas_kg=2.4", "--set: unknown key 'mas_kg'; did you mean 'mass_kg'?"),
    ("mass_kg=heavy", "--set mass_kg: expected a number, got 'heavy'"),
    ("mass_kg=-1", "--set mass_kg: must be between 0.01 and 1000, got -1.0"),
    ("mass_kg=nan", "--set mass_kg: expected a finite number"),
    ("mass_kg", "--set 'mass_kg': expected NAME=VALUE"),
])
def test_bad_override_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          override: str, message: str) -> None:
    assert run_compare(tmp_path, "--set", override) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"websim: error: {message}")
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists(), "nothing is written before the inputs are valid"


def test_bad_command_file_is_a_one_line_error(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    commands = tmp_path / "bad.yaml"
    commands.write_text("- {duration_s: 1.0, linear_mps: 0.2}\n- {duration_s: 1.0, linear: 0.2}\n")
    assert run_compare(tmp_path, commands=commands) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"websim: error: {commands}: segment 2: unknown key 'linear'; "
                          "did you mean 'linear_mps'?")
    assert len(err.strip().splitlines()) == 1


def test_a_shipped_command_file_is_found_by_name_from_any_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # no examples/ here: the name is looked up where websim ships it
    assert main(["compare", "--commands", "step", "--out", str(tmp_path / "out")]) == 0
    assert len(read_rows(tmp_path)) == 2 * (1 + STEP_TICKS)
    assert load_commands("step") == load_commands(STEP)


def test_an_unknown_command_name_lists_the_shipped_ones(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert run_compare(tmp_path, commands=Path("stpe")) == 2
    err = capsys.readouterr().err
    assert err.startswith("websim: error: stpe: cannot read command file")
    assert "(shipped command files: circle, payload_bonus, square, step)" in err


@pytest.mark.parametrize(("prefix", "from_checkout", "hint"), [
    ("/home/s/websim/.venv", True, "pip install -e '/home/s/websim[plots]'"),
    ("/home/s/.local/pipx/venvs/websim", False, "pipx inject websim matplotlib"),
    ("/home/s/venv", False, "/home/s/venv/bin/python -m pip install matplotlib"),
])
def test_the_plots_hint_fits_how_websim_was_installed(prefix: str, from_checkout: bool,
                                                      hint: str) -> None:
    assert plots_hint(prefix, from_checkout, Path("/home/s/websim")) == hint
    assert "websim[plots]" not in plots_hint(prefix, False, Path("/x"))  # PyPI's is not ours


def test_controller_options_need_the_controller(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert run_compare(tmp_path, "--kp", "4") == 2
    assert "websim: error: --kp needs --controller pid" in capsys.readouterr().err


def test_heading_pid_settles_near_the_setpoint(tmp_path: Path) -> None:
    commands = tmp_path / "hold.yaml"
    commands.write_text("- {duration_s: 5.0}\n")
    assert run_compare(tmp_path, "--controller", "pid", "--setpoint-deg", "90", "--kp", "4",
                       commands=commands) == 0
    settled = [row for row in read_rows(tmp_path)
               if row["mode"] == "kinematic" and float(row["t_s"]) >= 2.0]
    assert settled and all(abs(math.degrees(float(row["theta"])) - 90.0) < 2.0
                           for row in settled)
    heading = read_summary(tmp_path)["kinematic"]["heading"]  # type: ignore[index]
    assert abs(heading["final_error_deg"]) < 2.0


def test_odometry_fed_pid_hides_wheel_slip_that_true_heading_shows(tmp_path: Path) -> None:
    """Turning in place at the traction limit: odometry reaches the setpoint, the robot not."""
    segments = load_commands(EXAMPLES / "step.yaml")[2:]  # a 1 s standstill
    gains = PidGains(kp=6.0)
    heavy = RobotParams(mass_kg=4.8, inertia_kg_m2=0.0264)
    fed = {feedback: compare_modes(load_world("empty"), segments * 5, heavy,
                                   controller=HeadingController(gains, math.pi / 2, feedback)
                                   ).summary["dynamic"]
           for feedback in ("odometry", "ground_truth")}
    assert abs(fed["odometry"]["heading"]["final_error_deg"]) < 0.5
    assert fed["odometry"]["true_heading"]["final_error_deg"] < -5.0, "the robot falls short"
    assert abs(fed["ground_truth"]["true_heading"]["final_error_deg"]) < 1.0
    assert fed["ground_truth"]["true_heading"]["overshoot_pct"] > 5.0


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_the_progress_bar_shows_on_a_terminal_only() -> None:
    terminal = Terminal()
    with progress_bar(100, terminal, delay_s=0.0) as progress:
        for _ in range(100):
            progress.update()
        progress.refresh()
        shown = terminal.getvalue()
    assert "simulating" in shown and "100/100" in shown
    log = io.StringIO()  # a log file, CI: no bar at all
    with progress_bar(100, log, delay_s=0.0) as progress:
        for _ in range(100):
            progress.update()
    assert log.getvalue() == ""


def test_a_short_run_shows_no_bar() -> None:
    terminal = Terminal()
    with progress_bar(100, terminal) as progress:  # the default delay: one second
        for _ in range(100):
            progress.update()
    assert "simulating" not in terminal.getvalue()


@pytest.mark.parametrize(("fmt", "magic"), [("svg", b"<?xml"), ("pdf", b"%PDF")])
def test_figure_formats_for_slides(tmp_path: Path, fmt: str, magic: bytes) -> None:
    pytest.importorskip("matplotlib")
    assert run_compare(tmp_path, "--format", fmt) == 0
    figure = tmp_path / "out" / f"comparison.{fmt}"
    assert figure.read_bytes().startswith(magic)
    assert not (tmp_path / "out" / "comparison.png").exists()


def test_a_pid_figure_has_a_title_and_the_heading_with_its_setpoint(tmp_path: Path) -> None:
    matplotlib = pytest.importorskip("matplotlib")
    with matplotlib.rc_context({"svg.fonttype": "none"}):  # text as text, to read it back
        assert run_compare(tmp_path, "--format", "svg", "--controller", "pid",
                           "--setpoint-deg", "90", "--kp", "2.5") == 0
    svg = (tmp_path / "out" / "comparison.svg").read_text(encoding="utf-8")
    assert "step.yaml in " in svg and "seed 0" in svg and "mass " in svg  # what made it
    assert "heading PID to 90° (Kp 2.5" in svg
    assert "Heading: the PID" in svg and "setpoint 90°" in svg
    assert "θ (°)" in svg


def test_a_run_without_controller_has_no_heading_panel(tmp_path: Path) -> None:
    matplotlib = pytest.importorskip("matplotlib")
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        assert run_compare(tmp_path, "--format", "svg") == 0
    svg = (tmp_path / "out" / "comparison.svg").read_text(encoding="utf-8")
    assert "Velocity response" in svg and "Heading: the PID" not in svg
