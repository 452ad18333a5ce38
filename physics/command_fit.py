"""Fit the robot's driver (lag, scales, ramps) to a real robot's recording.

System identification as it is done for a mobile base: the response to logged velocity
commands is modelled as a dead time, a gain and a rate limit per speed
(``physics.command_pipeline``), and those five numbers are chosen to make the modelled speeds
match the measured ones in the least-squares sense (scipy's bounded ``least_squares``). The
fit uses the first part of the recording (``FIT_SHARE``); the rest is held out, and the error
there before and after the fit says whether the fitted model predicts, or only remembers.

Speeds, not poses, are fitted: a tick's speed depends on the driver alone, while a pose
carries every earlier error. The kinematic model's speed over a tick is exactly what the
driver gives the wheels, so the model is ``drive_sequence`` and no pose is integrated.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from physics.command_pipeline import drive_sequence
from physics.params import RobotParams, field_range
from physics.recorded_run import FloatArray, GridRun, clamped
from physics.snapshots import Command
from physics.trajectory_error import lag_by_xcorr, speed_ratio

FIT_SHARE = 0.7
"""Share of the recording's ticks the fit sees; the rest checks it."""

FITTED = ("cmd_lag_s", "linear_scale", "angular_scale", "linear_accel_limit_mps2",
          "angular_accel_limit_rps2")
"""The robot parameters the fit sets."""

NO_LIMIT_BELOW_S2 = 1e-3
"""A fitted time per unit of speed below this (s per m/s, or per rad/s) is no ramp at all:
an acceleration above 1000, the parameters' ceiling."""

MAX_TIME_PER_SPEED_S = 10.0
"""The slowest ramp the fit considers: 0.1 m/s^2 (or rad/s^2)."""

PLAUSIBLE = {
    "cmd_lag_s": (0.0, 0.4),
    "linear_scale": (0.85, 1.15),
    "angular_scale": (0.85, 1.15),
    "linear_accel_limit_mps2": (0.3, 1000.0),
    "angular_accel_limit_rps2": (1.0, 1000.0),
}
"""Where a small differential-drive robot's values usually lie; outside, the fit flags."""

WHY_IMPLAUSIBLE = {
    ("cmd_lag_s", "high"): "a dead time this long is Wi-Fi latency or a slow driver loop, or "
                           "the stamps of commands and odometry come from two clocks (try "
                           "--stamps receive)",
    ("linear_scale", "low"): "the robot drove less than it was told: wheel slip, a wheel "
                             "radius that is too small in the driver, a weak battery, or "
                             "commands beyond what the motors can do",
    ("linear_scale", "high"): "the odometry counts more than was commanded: a wheel radius "
                              "that is too large in the odometry, or an odometry that is "
                              "not the encoders' (a visual odometry's scale)",
    ("angular_scale", "low"): "the robot turned less than it was told: wheel slip in turns "
                              "(carpet, skid steering), or a gyro measuring yaw while the "
                              "driver turns by its encoders",
    ("angular_scale", "high"): "the robot turned more than it was told: a wheelbase that is "
                               "too small in the driver's odometry, or yaw from a gyro "
                               "with a wrong gain",
    ("linear_accel_limit_mps2", "low"): "a very slow start: a heavy payload, a low-pass "
                                        "filter in the driver, or a command timeout that "
                                        "stops the robot between sparse commands",
    ("angular_accel_limit_rps2", "low"): "a very slow turn-in: a filter in the driver, "
                                         "high friction of a caster, or a command timeout "
                                         "between sparse commands",
}


@dataclass(frozen=True)
class FitResult:
    """What the fit found and how well it predicts.

    Attributes:
        params: the base robot with the fitted driver.
        fitted: each fitted parameter's value.
        fit_ticks: ticks the fit used (the first part).
        held_out_ticks: ticks it was checked on (the rest).
        before: held-out speed errors with the base robot (``speed_errors``).
        after: the same with the fitted robot.
        flags: fitted values outside ``PLAUSIBLE``: {name, value, range, why}.
        cost: the fit's final least-squares cost (normalised speeds).
    """

    params: RobotParams
    fitted: dict[str, float]
    fit_ticks: int
    held_out_ticks: int
    before: dict[str, float]
    after: dict[str, float]
    flags: list[dict[str, Any]]
    cost: float


def model_speeds(commands: FloatArray, params: RobotParams, dt_s: float) -> FloatArray:
    """(N, 2) the kinematic model's speeds for each tick's (clamped) command."""
    given = [Command(v, w) for v, w in clamped(commands, params).tolist()]
    return np.array(drive_sequence(given, params, dt_s), dtype=float).reshape(-1, 2)


def speed_errors(measured: FloatArray, modelled: FloatArray,
                 valid: np.ndarray) -> dict[str, float]:
    """RMSE of the forward speed (m/s) and the yaw rate (rad/s) over the ``valid`` ticks."""
    diff = (modelled - measured)[valid]
    if len(diff) == 0:
        return {"linear_rmse_mps": math.nan, "angular_rmse_rps": math.nan}
    return {"linear_rmse_mps": float(np.sqrt(np.mean(diff[:, 0] ** 2))),
            "angular_rmse_rps": float(np.sqrt(np.mean(diff[:, 1] ** 2)))}


def with_driver(base: RobotParams, x: FloatArray) -> RobotParams:
    """``base`` with the driver the fit's vector x = (lag, scales, times per speed) says."""
    lag, linear_scale, angular_scale, linear_time, angular_time = (float(v) for v in x)
    return dataclasses.replace(
        base, cmd_lag_s=lag, linear_scale=linear_scale, angular_scale=angular_scale,
        linear_accel_limit_mps2=_accel(linear_time), angular_accel_limit_rps2=_accel(angular_time))


def _accel(time_per_speed_s: float) -> float:
    return 0.0 if time_per_speed_s < NO_LIMIT_BELOW_S2 else 1.0 / time_per_speed_s


def _time_per_speed(accel: float) -> float:
    return 0.0 if accel <= 0.0 else min(1.0 / accel, MAX_TIME_PER_SPEED_S)


def fit_driver(grid: GridRun, base: RobotParams, fit_share: float = FIT_SHARE) -> FitResult:
    """Fit the driver on the first ``fit_share`` of ``grid``'s ticks, check it on the rest.

    Raises:
        ValueError: too few measured ticks, or commands that never change (nothing to fit).
    """
    from scipy.optimize import least_squares  # the fit's own dependency, loaded when fitting

    measured = grid.speeds()
    valid = grid.speeds_measured()
    split = round(grid.ticks * fit_share)
    fit_part = valid.copy()
    fit_part[split:] = False
    held_out = valid.copy()
    held_out[:split] = False
    if fit_part.sum() < 10 or held_out.sum() < 5:
        raise ValueError(f"{grid.source}: {int(valid.sum())} measured ticks are too few to fit "
                         "on a part and check on the rest (a fit needs some seconds of driving)")
    commands = clamped(grid.commands, base)
    if not np.any(np.diff(commands[:split], axis=0)):
        raise ValueError(f"{grid.source}: the command never changes in the part fitted: a "
                         "fit needs steps of speed (start, stop, turn)")
    scales = np.array([base.max_linear_mps, base.max_angular_rps])

    def residuals(x: FloatArray) -> FloatArray:
        speeds = model_speeds(commands[:split], with_driver(base, x), grid.dt_s)
        errors: FloatArray = ((speeds - measured[:split]) / scales)[fit_part[:split]]
        return errors.ravel()

    starts = _starting_points(commands[:split], measured[:split], grid.dt_s)
    low = [field_range(RobotParams, "cmd_lag_s")[0], field_range(RobotParams, "linear_scale")[0],
           field_range(RobotParams, "angular_scale")[0], 0.0, 0.0]
    high = [field_range(RobotParams, "cmd_lag_s")[1], field_range(RobotParams, "linear_scale")[1],
            field_range(RobotParams, "angular_scale")[1], MAX_TIME_PER_SPEED_S,
            MAX_TIME_PER_SPEED_S]
    best: Any = None
    for start in starts:
        start = np.clip(start, low, high)
        result = least_squares(residuals, start, bounds=(low, high), x_scale=[0.1, 0.1, 0.1,
                               0.1, 0.1], diff_step=1e-3, xtol=1e-10, ftol=1e-10)
        if best is None or result.cost < best.cost:
            best = result
    params = with_driver(base, best.x)
    fitted = {name: float(getattr(params, name)) for name in FITTED}
    before = speed_errors(measured, model_speeds(commands, base, grid.dt_s), held_out)
    after = speed_errors(measured, model_speeds(commands, params, grid.dt_s), held_out)
    return FitResult(params, fitted, int(fit_part.sum()), int(held_out.sum()), before, after,
                     plausibility_flags(fitted), float(best.cost))


def _starting_points(commands: FloatArray, measured: FloatArray,
                     dt_s: float) -> list[FloatArray]:
    """Where the search starts.

    The cross-correlation's lag and the speed ratios, with and without a ramp, and from no
    lag at all.
    """
    lags = [lag for lag in (lag_by_xcorr(commands[:, i], measured[:, i], dt_s) for i in (0, 1))
            if lag is not None]
    lag = float(np.mean(lags)) if lags else 0.0
    ratios = [speed_ratio(commands[:, i], measured[:, i], lag, dt_s) for i in (0, 1)]
    linear, angular = (1.0 if ratio is None or ratio <= 0 else ratio for ratio in ratios)
    return [np.array([lag, linear, angular, 0.0, 0.0]),
            np.array([lag, linear, angular, 0.3, 0.1]),
            np.array([0.0, linear, angular, 0.3, 0.1])]


def plausibility_flags(fitted: dict[str, float]) -> list[dict[str, Any]]:
    """The fitted values outside ``PLAUSIBLE``, each with the likely reasons."""
    flags = []
    for name, value in fitted.items():
        low, high = PLAUSIBLE[name]
        if name.endswith("_limit_mps2") or name.endswith("_limit_rps2"):
            if value == 0.0 or value >= low:
                continue  # no ramp, or a quick one
            side = "low"
        elif low <= value <= high:
            continue
        else:
            side = "low" if value < low else "high"
        flags.append({"name": name, "value": value, "plausible": [low, high],
                      "why": WHY_IMPLAUSIBLE.get((name, side), "")})
    return flags


def timeout_hint(grid: GridRun, measured: FloatArray, after_s: float = 0.3) -> float | None:
    """The command timeout the robot's driver seems to have, or None.

    Ticks where the last command is older than ``after_s`` and asks for motion, yet the robot
    stands: if most such ticks are like that, its driver stops when commands stop coming.
    Returns the shortest command age at which it was seen standing (s).
    """
    commands = grid.commands
    asking = (np.abs(commands[:, 0]) > 0.02) | (np.abs(commands[:, 1]) > 0.05)
    old = asking & (grid.command_age_s > after_s) & np.isfinite(grid.command_age_s)
    old &= grid.speeds_measured()
    if old.sum() < 5:
        return None
    standing = old & (np.abs(measured[:, 0]) < 0.01) & (np.abs(measured[:, 1]) < 0.02)
    if standing.sum() < 0.8 * old.sum():
        return None
    return float(np.min(grid.command_age_s[standing]))
