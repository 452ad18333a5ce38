"""``websim fit RECORDING``: the robot's driver fitted to a real robot, as a parameter file.

Reads the recording as ``websim compare --real`` does (``websim.compare_real``'s options),
fits the command lag, the linear and angular scales and the acceleration limits on its first
part (``physics.command_fit``), checks them on the rest (the held-out part: speed errors and
the kinematic model's pose error there, before and after), flags implausible values with
their likely causes, and writes a parameter file (``--out``) that ``websim serve --params``,
``websim compare --params`` and ``websim grade --params`` take: the base parameters
(``--params``) with the fitted driver.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import yaml

from physics import ConfigError, PlatformParams, load_params
from physics.command_fit import FIT_SHARE, FITTED, FitResult, fit_driver
from physics.params import SHIPPED_PARAMS_FILE, field_unit
from physics.recorded_run import GridRun, on_grid, replay
from physics.trajectory_error import absolute_pose_error
from websim.compare_command import robot_with_overrides
from websim.compare_real import grid_from, read_from

DEFAULT_OUT = Path("fitted_params.yaml")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim fit`` (the recording's are ``compare_real``'s)."""
    parser.add_argument("real", metavar="RECORDING",
                        help="a real robot's recording: rosbag2 folder, .db3, .mcap, ROS 1 "
                             ".bag, or CSV (t_s, cmd_v, cmd_omega, x, y, yaw)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"the parameter file to write (default {DEFAULT_OUT})")
    parser.add_argument("--params", default=str(SHIPPED_PARAMS_FILE),
                        help="the robot's parameters before the fit; the file written is "
                             "these with the fitted driver (default: config/pi4b_params.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="NAME=VALUE",
                        help="override a parameter before the fit (repeatable)")
    parser.add_argument("--fit-share", type=float, default=FIT_SHARE, metavar="F",
                        help=f"share of the recording fitted; the rest checks the fit "
                             f"(default {FIT_SHARE:g})")


def run(args: argparse.Namespace) -> int:
    """Fit, check, print, write the parameter file."""
    if not 0.2 <= args.fit_share <= 0.95:
        raise ConfigError(f"--fit-share: expected 0.2 to 0.95, got {args.fit_share}")
    recording = read_from(args)
    platform = load_params(args.params)
    base = robot_with_overrides(platform.robot, args.overrides)
    grid = grid_from(args, recording)
    try:
        result = fit_driver(grid, base, args.fit_share)
    except ValueError as error:
        raise ConfigError(str(error)) from None
    held_out = held_out_pose_errors(args, recording, grid, base, result)
    fitted = dataclasses.replace(platform, robot=result.params)
    write_params(fitted, args.out, header(args, recording.info, result, held_out))
    load_params(args.out)  # what was written loads back
    print(report(result, base, held_out))
    print(f"wrote {args.out} (websim serve --params {args.out}; websim compare --real "
          f"{args.real} --params {args.out} --out DIR to see the gap that remains)")
    return 0


def held_out_pose_errors(args: argparse.Namespace, recording: Any, grid: GridRun,
                         base: Any, result: FitResult) -> dict[str, float] | None:
    """The kinematic model's pose error on the held-out part alone, before and after.

    The held-out part is replayed from its own first pose, at rest; None if it is too short.
    """
    split = round(grid.ticks * args.fit_share)
    start_s = grid.start_s + float(grid.t_s[split])
    try:
        part = on_grid(recording.run, grid.dt_s, args.cmd_timeout, start_s, args.end)
    except ConfigError:
        return None
    out = {}
    for name, params in (("before", base), ("after", result.params)):
        poses, _ = replay(part, "kinematic", params)
        error = absolute_pose_error(part.poses[part.measured], poses[part.measured])
        out[name] = error["translation_m"]["rmse"]
    return out


def report(result: FitResult, base: Any, held_out: dict[str, float] | None) -> str:
    """What ``websim fit`` prints: the values, the check on the held-out part, the flags."""
    lines = [f"fitted on {result.fit_ticks} ticks, checked on {result.held_out_ticks} held "
             "out:", f"  {'parameter':26} {'before':>10} {'fitted':>10}"]
    for name in FITTED:
        unit = field_unit(type(base), name)
        lines.append(f"  {name:26} {getattr(base, name):10.4g} {result.fitted[name]:10.4g} "
                     f"{unit}")
    lines.append("held-out part (the fit did not see it):   before      after")
    lines.append(f"  linear speed RMSE (m/s)            {result.before['linear_rmse_mps']:10.4f} "
                 f"{result.after['linear_rmse_mps']:10.4f}")
    lines.append(f"  angular speed RMSE (rad/s)         {result.before['angular_rmse_rps']:10.4f} "
                 f"{result.after['angular_rmse_rps']:10.4f}")
    if held_out is not None:
        lines.append(f"  kinematic APE translation RMSE (m) {held_out['before']:10.4f} "
                     f"{held_out['after']:10.4f}")
    for flag in result.flags:
        low, high = flag["plausible"]
        lines.append(f"implausible: {flag['name']} = {flag['value']:.4g} (usually {low:g} to "
                     f"{high:g}): {flag['why']}")
    if not result.flags:
        lines.append("every fitted value lies in the usual range of a small differential-drive "
                     "robot")
    worse = result.after["linear_rmse_mps"] > result.before["linear_rmse_mps"] and \
        result.after["angular_rmse_rps"] > result.before["angular_rmse_rps"]
    if worse:
        lines.append("the fitted model predicts the held-out part worse than the base one: "
                     "the two parts differ (a payload, a floor, a battery), or the fit found a "
                     "local optimum; try a longer recording or another --fit-share")
    return "\n".join(lines)


def header(args: argparse.Namespace, info: dict[str, Any], result: FitResult,
           held_out: dict[str, float] | None) -> str:
    """The comment at the top of the file written: where its values came from."""
    made = datetime.now(timezone.utc).isoformat(timespec="seconds")
    lines = [f"Written by websim fit on {made} from {info.get('path')} ({info.get('kind')}, "
             f"{' '.join(info.get('command_topic', []))} and "
             f"{' '.join(info.get('pose_topic', []))}, {info.get('stamps')} stamps),",
             f"starting from {args.params}. Fitted: {', '.join(FITTED)} on the first "
             f"{100 * args.fit_share:.0f} % ({result.fit_ticks} ticks).",
             f"Held out ({result.held_out_ticks} ticks), speed RMSE before -> after: linear "
             f"{result.before['linear_rmse_mps']:.4f} -> {result.after['linear_rmse_mps']:.4f} "
             f"m/s, angular {result.before['angular_rmse_rps']:.4f} -> "
             f"{result.after['angular_rmse_rps']:.4f} rad/s."]
    if held_out is not None:
        lines.append(f"Kinematic pose error there (APE RMSE): {held_out['before']:.4f} -> "
                     f"{held_out['after']:.4f} m.")
    lines += [f"Implausible: {flag['name']} = {flag['value']:.4g}: {flag['why']}"
              for flag in result.flags]
    return "".join(f"# {line}\n" for line in lines)


def write_params(platform: PlatformParams, path: Path, comment: str) -> Path:
    """Write every section of ``platform`` as a parameter file, ``comment`` on top."""
    document = {name: {key: _plain(value) for key, value in
                       dataclasses.asdict(getattr(platform, name)).items()}
                for name in ("robot", "lidar", "noise")}
    text = comment + yaml.safe_dump(document, sort_keys=False)
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{path}: cannot write: {error.strerror}") from None
    return path


def _plain(value: Any) -> Any:
    """A float rounded to 9 significant digits (the file is read by people too)."""
    if isinstance(value, float) and math.isfinite(value):
        return float(f"{value:.9g}")
    return value
