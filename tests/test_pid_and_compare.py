"""The pure heading PID and the kinematic-vs-dynamic comparison runner."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from physics import ConfigError, RobotParams, load_world
from physics.compare import (
    TRAJECTORY_COLUMNS,
    HeadingController,
    Segment,
    compare,
    load_commands,
    step_response,
)
from physics.pid import HeadingPid, PidGains, PidState, pid_step, wrap_angle

EXAMPLES = Path(__file__).parent.parent / "examples" / "commands"


@pytest.mark.parametrize(("angle", "wrapped"), [
    (0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2),
    (-3 * math.pi / 2, math.pi / 2), (4 * math.pi + 0.1, 0.1)])
def test_wrap_angle(angle: float, wrapped: float) -> None:
    assert wrap_angle(angle) == pytest.approx(wrapped, abs=1e-12)


def test_error_takes_the_short_way_round() -> None:
    step = pid_step(PidGains(kp=1.0), PidState(), math.radians(170), math.radians(-170))
    assert step.error == pytest.approx(math.radians(-20))
    assert step.output == pytest.approx(math.radians(-20))


def test_output_is_clamped_and_integral_does_not_wind_up() -> None:
    gains = PidGains(kp=10.0, ki=5.0, output_limit=2.5)
    state = PidState()
    for _ in range(50):
        step = pid_step(gains, state, math.pi / 2, 0.0)
        state = step.state
        assert step.output == 2.5
    assert state.integral == 0.0, "saturated in the error's direction: no integration"


def test_derivative_acts_on_the_measurement_not_the_setpoint() -> None:
    gains = PidGains(kp=0.0, kd=1.0)
    first = pid_step(gains, PidState(), 0.0, 0.0)
    jump = pid_step(gains, first.state, 1.0, 0.0)
    assert jump.output == 0.0, "a setpoint jump gives no derivative kick"
    moved = pid_step(gains, jump.state, 1.0, 0.1)
    assert moved.output == pytest.approx(-1.0)


def test_heading_pid_settles_a_kinematic_robot_on_90_degrees() -> None:
    rows = compare(load_world("empty"), [Segment(5.0, 0.0, 0.0)],
                   controller=HeadingController(PidGains(kp=4.0), math.pi / 2)
                   ).mode_rows("kinematic")
    settled = [r for r in rows if r.t_s >= 1.5]
    assert all(abs(math.degrees(r.theta) - 90) < 2 for r in settled)


def test_compare_runs_both_modes_with_one_row_per_tick_from_zero() -> None:
    segments = load_commands(EXAMPLES / "step.yaml")
    result = compare(load_world("empty"), segments)
    for mode in ("kinematic", "dynamic"):
        rows = result.mode_rows(mode)
        assert rows[0].t_s == 0.0 and len(rows) == 1 + round(5.0 / 0.05)
        assert rows[-1].t_s == pytest.approx(5.0)
    assert list(rows[0]._fields) == list(TRAJECTORY_COLUMNS)
    summary = result.summary
    kinematic_rise = summary["kinematic"]["steps"][0]["v"]["rise_time_s"]
    dynamic_rise = summary["dynamic"]["steps"][0]["v"]["rise_time_s"]
    assert kinematic_rise == pytest.approx(0.045)  # the whole step in the first tick
    # Traction-limited: 0.9 * 0.4 m/s at 2.5 m/s^2 takes 0.144 s.
    assert dynamic_rise == pytest.approx(0.9 * 0.4 / RobotParams().max_linear_accel_mps2)
    assert summary["difference"]["max_path_deviation_m"] > 0.01


def test_payload_change_in_a_segment_acts_in_dynamic_mode_only() -> None:
    plain = compare(load_world("empty"), [Segment(1.0, 0.0, 0.0), Segment(1.0, 0.4, 0.0)])
    loaded = compare(load_world("empty"), [Segment(1.0, 0.0, 0.0, mass_kg=2.4),
                                           Segment(1.0, 0.4, 0.0)])
    assert loaded.mode_rows("kinematic") == plain.mode_rows("kinematic")
    rise = [r.summary["dynamic"]["steps"][1]["v"]["rise_time_s"] for r in (plain, loaded)]
    assert rise[1] / rise[0] == pytest.approx(2.0, rel=0.05)


def test_every_example_command_file_loads() -> None:
    files = sorted(EXAMPLES.glob("*.yaml"))
    assert {f.stem for f in files} >= {"step", "square", "circle", "payload_bonus"}
    for path in files:
        assert load_commands(path)


def test_csv_commands(tmp_path: Path) -> None:
    path = tmp_path / "c.csv"
    path.write_text("duration_s,linear_mps,angular_rps,mass_kg\n1.0,0.2,0.0,\n0.5,0,1,2.4\n")
    assert load_commands(path) == (Segment(1.0, 0.2, 0.0), Segment(0.5, 0.0, 1.0, 2.4))


@pytest.mark.parametrize(("text", "expected"), [
    ("[]", "expected a non-empty list"),
    ("- {duration_s: 1, linear: 0.2}", "segment 1: unknown key 'linear'; did you mean"),
    ("- {linear_mps: 0.2}", "segment 1: missing duration_s"),
    ("- {duration_s: 1}\n- {duration_s: -2}", r"segment 2.duration_s: must be > 0"),
    ("- {duration_s: 1, angular_rps: fast}", r"segment 1.angular_rps: expected a number"),
    ("- {duration_s: 1, mass_kg: 0}", r"segment 1.mass_kg: must be > 0"),
])
def test_bad_command_file_names_segment_and_field(tmp_path: Path, text: str,
                                                  expected: str) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=expected):
        load_commands(path)


def test_step_response_metrics() -> None:
    times = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    values = [0.0, 0.5, 1.2, 0.95, 1.0, 1.0]
    metrics = step_response(times, values, 1.0)
    assert metrics["rise_time_s"] == pytest.approx(0.1 + 0.4 / 0.7 * 0.1)
    assert metrics["overshoot_pct"] == pytest.approx(20.0)
    assert metrics["settling_time_s"] == pytest.approx(0.4)
    assert step_response(times, [1.0] * 6, 1.0)["rise_time_s"] is None


def test_heading_pid_object_matches_pid_step() -> None:
    pid = HeadingPid(PidGains(kp=3.0, ki=0.5, kd=0.2), math.pi / 2)
    state = PidState()
    for heading in (0.0, 0.3, 0.8, 1.3, 1.6, 1.55):
        step = pid_step(pid.gains, state, math.pi / 2, heading)
        state = step.state
        assert pid.update(heading) == step.output


@pytest.mark.skipif(shutil.which("node") is None, reason="node not installed")
def test_browser_pid_equals_python_pid() -> None:
    rng = np.random.default_rng(4)
    headings = np.cumsum(rng.normal(0.0, 0.4, size=200)).tolist()
    headings += [math.pi, -math.pi, 3.0, -3.0, 0.0]
    gains = PidGains(kp=3.0, ki=1.5, kd=0.4, output_limit=2.0)
    setpoint = math.radians(170)
    trace = json.dumps({"gains": {"kp": gains.kp, "ki": gains.ki, "kd": gains.kd,
                                  "outputLimit": gains.output_limit},
                        "setpoint": setpoint, "dt": 0.1, "headings": headings})
    result = subprocess.run(["node", str(Path(__file__).parent / "web" / "pid_trace.mjs"),
                             trace], capture_output=True, text=True, timeout=30, check=True)
    browser = json.loads(result.stdout)
    state = PidState()
    saturated = 0
    for heading, js in zip(headings, browser, strict=True):
        step = pid_step(gains, state, setpoint, heading)
        state = step.state
        saturated += abs(step.output) == gains.output_limit
        assert js["output"] == pytest.approx(step.output, abs=1e-12)
        assert js["error"] == pytest.approx(step.error, abs=1e-12)
        assert js["integral"] == pytest.approx(state.integral, abs=1e-12)
    assert 0 < saturated < len(headings), "the trace exercises anti-windup and the linear range"
