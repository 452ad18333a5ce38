"""The simulation against the real robot: one recording through both models, and the gap.

``compare_real`` replays a recording's commands (``physics.recorded_run``) through the
kinematic and the dynamic model, measures each against the real trajectory
(``physics.trajectory_error``: APE, RPE, final pose), sets the commanded speeds against the
measured ones (ratio and lag), and says where the gap comes from: each of the linear scale,
the angular scale and the lag is corrected alone in the kinematic model, and the error that
correction takes away is its share, in a sentence a student can read.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from physics.command_fit import timeout_hint
from physics.params import NoiseParams, RobotParams, field_range
from physics.recorded_run import FloatArray, GridRun, replay, tick_speeds
from physics.trajectory_error import speed_response, trajectory_errors

MODELS = ("kinematic", "dynamic")

MOVING_AT_START_MPS = 0.02
"""A real robot faster than this at the window's start was moving: the models start at rest."""

WORTH_SAYING = 0.05
"""A correction that takes away less than this share of the error is not a cause worth naming."""


class RealRow(NamedTuple):
    """One tick: the command in force, the real robot, each model (m, rad, m/s, rad/s).

    Speeds are over the tick that ended at ``t_s`` (0 on the first row).
    """

    t_s: float
    cmd_v: float
    cmd_omega: float
    real_x: float
    real_y: float
    real_yaw: float
    real_v: float
    real_omega: float
    measured: int
    kinematic_x: float
    kinematic_y: float
    kinematic_yaw: float
    kinematic_v: float
    kinematic_omega: float
    dynamic_x: float
    dynamic_y: float
    dynamic_yaw: float
    dynamic_v: float
    dynamic_omega: float


REAL_COLUMNS = RealRow._fields
"""The columns of ``trajectory.csv`` of ``websim compare --real``."""


@dataclass(frozen=True)
class RealComparison:
    """What ``compare_real`` found.

    Attributes:
        rows: one per tick.
        summary: the content of ``summary.json``: per model its errors and speed response,
            the real robot's speed response, the causes and the sentences.
        grid: the recording on the ticks.
        poses: each model's poses (N + 1, 3).
    """

    rows: tuple[RealRow, ...]
    summary: dict[str, Any]
    grid: GridRun
    poses: dict[str, FloatArray]


def _errors(grid: GridRun, poses: FloatArray) -> dict[str, Any]:
    valid = grid.measured
    return trajectory_errors(grid.poses[valid], poses[valid], grid.dt_s)


def compare_real(grid: GridRun, params: RobotParams | None = None, *, seed: int = 0,
                 noise: NoiseParams | None = None) -> RealComparison:
    """Replay ``grid`` through both models and measure them against the real robot."""
    params = RobotParams() if params is None else params
    measured = grid.speeds()
    valid_speeds = grid.speeds_measured()
    poses: dict[str, FloatArray] = {}
    summary: dict[str, Any] = {}
    given: FloatArray = grid.commands
    for mode in MODELS:
        poses[mode], given = replay(grid, mode, params, seed=seed, noise=noise)
        speeds = tick_speeds(poses[mode], grid.dt_s)
        summary[mode] = {**_errors(grid, poses[mode]),
                         "speeds": speed_response(given, speeds, grid.dt_s)}
    summary["real"] = {"speeds": speed_response(given[valid_speeds], measured[valid_speeds],
                                                grid.dt_s)}
    causes = gap_causes(grid, params, summary, seed=seed, noise=noise)
    summary["causes"] = causes
    summary["explanation"] = explain(summary, causes, grid, measured)
    summary["ticks"] = grid.ticks
    summary["dt_s"] = grid.dt_s
    summary["duration_s"] = float(grid.t_s[-1])
    summary["measured_ticks"] = int(grid.measured.sum())
    rows = _rows(grid, given, measured, poses)
    return RealComparison(tuple(rows), summary, grid, poses)


def _rows(grid: GridRun, given: FloatArray, measured: FloatArray,
          poses: dict[str, FloatArray]) -> list[RealRow]:
    zero = np.zeros((1, 2))
    speeds = {mode: np.vstack([zero, tick_speeds(poses[mode], grid.dt_s)]) for mode in MODELS}
    real_speeds = np.vstack([zero, measured])
    commands = np.vstack([given[:1], given])
    table = np.column_stack([
        np.round(grid.t_s, 9), commands, grid.poses, real_speeds, grid.measured.astype(float),
        *(np.column_stack([poses[mode], speeds[mode]]) for mode in MODELS)])
    return [RealRow._make([*row[:8], int(row[8]), *row[9:]]) for row in table.tolist()]


def _clipped(name: str, value: float) -> float:
    low, high = field_range(RobotParams, name)
    return min(max(value, low), high)


def gap_causes(grid: GridRun, params: RobotParams, summary: dict[str, Any], *, seed: int = 0,
               noise: NoiseParams | None = None) -> list[dict[str, Any]]:
    """Each simple cause, corrected alone in the kinematic model, and the error it removes.

    A cause is a linear scale, an angular scale or a lag, sized from the real robot's speed
    ratio and lag against the model's. Returns them largest share first, each with
    ``name``, ``value`` (the parameter that corrects it), ``error_m`` (the kinematic APE
    RMSE with it) and ``share`` (of the error it takes away, 0 to 1).
    """
    base_error = summary["kinematic"]["ape"]["translation_m"]["rmse"]
    real, model = summary["real"]["speeds"], summary["kinematic"]["speeds"]
    candidates: list[tuple[str, str, float]] = []
    for speed, name in (("linear", "linear_scale"), ("angular", "angular_scale")):
        ratio, model_ratio = real[speed]["ratio"], model[speed]["ratio"]
        if ratio is not None and model_ratio and ratio > 0:
            value = _clipped(name, getattr(params, name) * ratio / model_ratio)
            candidates.append((speed + " scale", name, value))
    lags = [real[s]["lag_s"] - (model[s]["lag_s"] or 0.0) for s in ("linear", "angular")
            if real[s]["lag_s"] is not None]
    if lags:
        value = _clipped("cmd_lag_s", params.cmd_lag_s + max(0.0, float(np.mean(lags))))
        candidates.append(("lag", "cmd_lag_s", value))
    causes = []
    for label, name, value in candidates:
        if value == getattr(params, name):
            continue
        corrected = dataclasses.replace(params, **{name: value})
        poses, _ = replay(grid, "kinematic", corrected, seed=seed, noise=noise)
        error = _errors(grid, poses)["ape"]["translation_m"]["rmse"]
        share = 0.0 if not base_error > 0 else max(0.0, (base_error - error) / base_error)
        causes.append({"name": label, "parameter": name, "value": value, "error_m": error,
                       "share": share})
    causes.sort(key=lambda cause: -cause["share"])
    return causes


def explain(summary: dict[str, Any], causes: list[dict[str, Any]], grid: GridRun,
            measured: FloatArray) -> list[str]:
    """Where the gap comes from, in sentences."""
    kinematic, dynamic = summary["kinematic"], summary["dynamic"]
    real, model = summary["real"]["speeds"], kinematic["speeds"]
    error = kinematic["ape"]["translation_m"]["rmse"]
    lines = [f"Over {grid.t_s[-1]:.1f} s the kinematic model ends "
             f"{kinematic['final']['position_m']:.3f} m and "
             f"{abs(math.degrees(kinematic['final']['heading_rad'])):.1f}° from the real robot "
             f"(position error {error:.3f} m RMSE, "
             f"{kinematic['ape']['aligned']['translation_m']['rmse']:.3f} m once the paths are "
             f"aligned); the dynamic model ends {dynamic['final']['position_m']:.3f} m away "
             f"({dynamic['ape']['translation_m']['rmse']:.3f} m RMSE)."]
    if error < 1e-6:
        lines.append("The kinematic model reproduces the real trajectory to rounding: nothing "
                     "to explain.")
        return lines
    for speed, what in (("linear", "drove {:.2f} m per commanded metre"),
                        ("angular", "turned {:.2f} rad per commanded radian")):
        ratio, lag = real[speed]["ratio"], real[speed]["lag_s"]
        if ratio is None:
            lines.append(f"The {speed} command never moved: its scale and lag are unknown.")
            continue
        lines.append(f"The real robot {what.format(ratio)} (the kinematic model "
                     f"{model[speed]['ratio'] or 0.0:.2f}), and its {speed} speed trails the "
                     f"command by {lag or 0.0:.2f} s (the model's by "
                     f"{model[speed]['lag_s'] or 0.0:.2f} s).")
    named = [cause for cause in causes if cause["share"] >= WORTH_SAYING]
    for cause in named:
        lines.append(f"Correcting the {cause['name']} alone ({cause['parameter']} = "
                     f"{cause['value']:.3g}) takes the kinematic model's error from {error:.3f} "
                     f"to {cause['error_m']:.3f} m RMSE: {100 * cause['share']:.0f} % of the "
                     "gap.")
    if named:
        lines.append(f"The largest part of the gap is the {named[0]['name']}. `websim fit` "
                     "estimates the scales, the lag and the acceleration limits together "
                     "and checks them on a part of the recording it did not see.")
    else:
        lines.append("No single scale or lag explains the gap: look at the plots for slip, a "
                     "collision, a ramp (acceleration limits, which `websim fit` estimates) "
                     "or odometry drift.")
    timeout_s = timeout_hint(grid, measured)
    if timeout_s is not None:
        lines.append(f"The real robot stood still once no command had come for {timeout_s:.2f} "
                     "s, though the last one asked for motion: its driver has a command "
                     f"timeout, which the models do not know; give --cmd-timeout {timeout_s:.2f}.")
    if len(measured) and abs(measured[0, 0]) > MOVING_AT_START_MPS:
        lines.append(f"The real robot was already moving at the window's start "
                     f"({measured[0, 0]:.2f} m/s): the models start at rest, so start the "
                     "window where the robot stands.")
    return lines
