"""``websim compare``: one command file through both motion models, written to a directory.

Writes ``trajectory.csv`` (one row per tick and mode, columns ``TRAJECTORY_COLUMNS``),
``summary.json`` (``physics.compare.compare``'s summary) and, if matplotlib is installed,
``comparison.png`` (``--format svg|pdf`` for slides; paths over the world's walls, v(t) and
omega(t) commanded and measured, the heading and its setpoint for a PID run).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, Any

from tqdm import tqdm

from physics import TICK_PERIOD_S, ConfigError, RobotParams, World, load_params, load_world
from physics.compare import (
    COMMANDS_DIR,
    HEADING_FEEDBACK,
    MODES_COMPARED,
    TRAJECTORY_COLUMNS,
    Comparison,
    HeadingController,
    Segment,
    compare,
    load_commands,
)
from physics.pid import PidGains
from physics.shipped import CHECKOUT_DIR, FROM_CHECKOUT
from physics.validation import check_keys


def plots_hint(prefix: str = sys.prefix, from_checkout: bool = FROM_CHECKOUT,
               checkout: Path = CHECKOUT_DIR) -> str:
    """How to get matplotlib (``comparison.png``'s optional dependency) for this install.

    Not ``pip install 'websim[plots]'``: the package index's ``websim`` is another project.

    Args:
        prefix: the Python environment websim runs in (``sys.prefix``).
        from_checkout: websim runs from a checkout (an editable install of one).
        checkout: that checkout's folder.
    """
    if from_checkout:
        return f"pip install -e '{checkout}[plots]'"
    if "pipx" in Path(prefix).parts:
        return "pipx inject websim matplotlib"
    return f"{Path(prefix) / 'bin' / 'python'} -m pip install matplotlib"

PROGRESS_DELAY_S = 1.0
"""Wall time before the progress bar appears: a short run prints nothing."""

PROGRESS_REDRAW_S = 0.1
"""Shortest wall time between two redraws of the progress bar on a terminal."""

FIGURE_FORMATS = ("png", "svg", "pdf")
"""What ``--format`` may ask for."""

FIGURE_DPI = 200
"""Resolution of the figure (a slide's, projected)."""

MODE_STYLES = {"kinematic": ("tab:blue", "-"), "dynamic": ("tab:orange", "-")}
"""Line colour and style of each mode in the figure."""


def shipped_commands() -> list[str]:
    """The names of the shipped command files (``--commands step``)."""
    return sorted(path.stem for path in COMMANDS_DIR.glob("*.yaml"))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim compare`` (besides world, params and seed)."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--commands",
                        help="command file: a YAML list (or CSV) of segments with duration_s, "
                             "linear_mps, angular_rps and optional mass_kg, inertia_kg_m2; "
                             "or a shipped one by name: " + ", ".join(shipped_commands()))
    source.add_argument("--real", metavar="RECORDING",
                        help="a real robot's recording (rosbag2 folder, .db3, .mcap, ROS 1 "
                             ".bag, or CSV): replay its commands through both models and "
                             "measure the gap (docs/validation.md); also writes report.html")
    parser.add_argument("--out", required=True, type=Path,
                        help="directory for trajectory.csv, summary.json, comparison.png")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="NAME=VALUE",
                        help="override a robot parameter, e.g. --set mass_kg=2.4 (repeatable)")
    parser.add_argument("--format", dest="figure_format", choices=FIGURE_FORMATS,
                        default="png", help="the figure's format (default png; svg and pdf "
                                            f"for slides), at {FIGURE_DPI} dpi")
    control = parser.add_argument_group("heading controller (replaces angular_rps)")
    control.add_argument("--controller", choices=["pid"], default=None,
                         help="drive angular.z with the course's 10 Hz heading PID")
    defaults = PidGains()
    control.add_argument("--setpoint-deg", type=float, default=None,
                         help="heading to hold, odom frame (degrees; default 90)")
    control.add_argument("--kp", type=float, default=None, help=f"default {defaults.kp}")
    control.add_argument("--ki", type=float, default=None, help=f"default {defaults.ki}")
    control.add_argument("--kd", type=float, default=None, help=f"default {defaults.kd}")
    control.add_argument("--feedback", choices=HEADING_FEEDBACK, default=None,
                         help="heading the PID measures: odometry (/odom, default) or "
                              "ground_truth (the true heading, like an IMU)")


def robot_with_overrides(robot: RobotParams, overrides: Sequence[str]) -> RobotParams:
    """``robot`` with ``NAME=VALUE`` overrides applied and validated.

    Raises:
        ConfigError: a malformed override, an unknown name (with a "did you mean" hint) or a
            value ``RobotParams`` refuses; the message starts with ``--set``.
    """
    names = [item.name for item in dataclasses.fields(RobotParams)]
    values: dict[str, float] = {}
    for override in overrides:
        name, equals, text = override.partition("=")
        name = name.strip()
        if not equals or not name:
            raise ConfigError(f"--set {override!r}: expected NAME=VALUE, e.g. mass_kg=2.4")
        check_keys("--set", {name: text}, names)
        try:
            values[name] = float(text)
        except ValueError:
            raise ConfigError(f"--set {name}: expected a number, got {text!r}") from None
    try:
        return dataclasses.replace(robot, **values)
    except ConfigError as error:
        raise ConfigError(f"--set {error}") from None


def heading_controller(args: argparse.Namespace) -> HeadingController | None:
    """The heading PID the arguments ask for, or None."""
    tuning = {"--setpoint-deg": args.setpoint_deg, "--kp": args.kp, "--ki": args.ki,
              "--kd": args.kd, "--feedback": args.feedback}
    if args.controller is None:
        given = [flag for flag, value in tuning.items() if value is not None]
        if given:
            raise ConfigError(f"{given[0]} needs --controller pid")
        return None
    defaults = PidGains()
    gains = PidGains(kp=defaults.kp if args.kp is None else args.kp,
                     ki=defaults.ki if args.ki is None else args.ki,
                     kd=defaults.kd if args.kd is None else args.kd)
    setpoint_deg = 90.0 if args.setpoint_deg is None else args.setpoint_deg
    return HeadingController(gains, math.radians(setpoint_deg),
                             args.feedback or HEADING_FEEDBACK[0])


def run(args: argparse.Namespace) -> int:
    """Run the comparison and write its files; returns the exit code.

    Raises:
        ConfigError: a bad command, world or parameter file, override or output directory.
    """
    segments = load_commands(args.commands)
    world = load_world(args.world)
    platform = load_params(args.params)
    robot = robot_with_overrides(platform.robot, args.overrides)
    controller = heading_controller(args)
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"{out}: cannot create output directory: {error.strerror}") from None

    with progress_bar(len(MODES_COMPARED) * total_ticks(segments), sys.stderr) as progress:

        def tick() -> None:
            progress.update()

        result = compare(world, segments, robot, seed=args.seed, lidar=platform.lidar,
                         noise=world.noise_over(platform.noise), controller=controller,
                         on_tick=tick)

    written = [write_trajectory(result, out / "trajectory.csv"),
               write_summary(result, out / "summary.json")]
    figure_path = out / f"comparison.{args.figure_format}"
    title = figure_title(args, robot, world, controller)
    try:
        written.append(write_figure(result, world, segments, figure_path, title=title,
                                    controller=controller))
    except ImportError:
        print(f"websim: {figure_path.name} skipped, matplotlib is not installed: {plots_hint()}",
              file=sys.stderr)
    difference = result.summary["difference"]
    print(f"wrote {', '.join(str(path) for path in written)}")
    print(f"dynamic vs kinematic: final position {difference['final_position_m']:.4f} m apart, "
          f"max path deviation {difference['max_path_deviation_m']:.4f} m "
          f"at t = {difference['max_path_deviation_at_s']:.2f} s")
    return 0


def figure_title(args: argparse.Namespace, robot: RobotParams, world: World,
                 controller: HeadingController | None) -> str:
    """What made the figure: the command file, world, seed, payload and controller."""
    parts = [f"{Path(args.commands).name} in {world.name}", f"seed {args.seed}",
             f"mass {robot.mass_kg:g} kg", f"inertia {robot.inertia_kg_m2:g} kg m²"]
    if args.overrides:
        parts.append("set " + ", ".join(args.overrides))
    if controller is not None:
        parts.append(f"heading PID to {math.degrees(controller.setpoint_rad):g}° (Kp "
                     f"{controller.gains.kp:g}, Ki {controller.gains.ki:g}, Kd "
                     f"{controller.gains.kd:g}, {controller.feedback} feedback)")
    return "; ".join(parts)


def total_ticks(segments: Sequence[Segment]) -> int:
    """Ticks ``physics.compare.run_mode`` takes for ``segments`` in one mode."""
    return sum(max(1, round(segment.duration_s / TICK_PERIOD_S)) for segment in segments)


def progress_bar(total: int, stream: IO[str], delay_s: float = PROGRESS_DELAY_S) -> tqdm[Any]:
    """The run's progress bar (tqdm) on ``stream``, cleared at the end.

    It appears only once the run has taken ``delay_s``, and only on a terminal: a log file or
    CI gets none.
    """
    return tqdm(total=total, file=stream, delay=delay_s, mininterval=PROGRESS_REDRAW_S,
                desc="simulating", unit=" ticks", leave=False, disable=None)


def write_trajectory(result: Comparison, path: Path) -> Path:
    """Write every row, ground truth and odometry, one per tick and mode."""
    return write_table(path, TRAJECTORY_COLUMNS, result.rows)


def write_table(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """Write a CSV file: a header of ``columns``, then ``rows``."""
    with opened(path) as stream:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(rows)
    return path


def write_summary(result: Comparison, path: Path) -> Path:
    """Write ``result.summary`` as indented JSON."""
    with opened(path) as stream:
        json.dump(result.summary, stream, indent=2)
        stream.write("\n")
    return path


def opened(path: Path) -> IO[str]:
    """``path`` opened for writing text; a ConfigError naming it if it cannot be."""
    try:
        return path.open("w", encoding="utf-8", newline="")
    except OSError as error:
        raise ConfigError(f"{path}: cannot write: {error.strerror}") from None


def write_figure(result: Comparison, world: World, segments: Sequence[Segment],
                 path: Path, title: str = "",
                 controller: HeadingController | None = None) -> Path:
    """Draw the paths over the walls and the responses to ``path`` (its suffix: the format).

    The velocity panels, and for a heading PID run the heading with its setpoint; segments
    numbered on the time axis; ``title`` on top. 200 dpi.

    Raises:
        ImportError: matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    panels = 3 if controller is not None else 2
    figure = Figure(figsize=(12, 3.25 * panels), dpi=FIGURE_DPI, layout="constrained")
    FigureCanvasAgg(figure)
    if title:
        figure.suptitle(title, fontsize=10)
    grid = figure.add_gridspec(panels, 2, width_ratios=(1.0, 1.25))
    paths = figure.add_subplot(grid[:, 0])
    linear = figure.add_subplot(grid[0, 1])
    angular = figure.add_subplot(grid[1, 1], sharex=linear)

    for wall in world.walls:
        paths.plot([wall.x1, wall.x2], [wall.y1, wall.y2], color="0.25", linewidth=2.5,
                   solid_capstyle="round")
    for circle in world.circles:
        paths.add_patch(Circle((circle.x, circle.y), circle.radius_m, color="0.55"))
    xs: list[float] = []
    ys: list[float] = []
    for mode in MODES_COMPARED:
        rows = result.mode_rows(mode)
        colour, style = MODE_STYLES[mode]
        paths.plot([r.x for r in rows], [r.y for r in rows], color=colour, linestyle=style,
                   linewidth=2, label=f"{mode} (true path)")
        paths.plot(rows[-1].x, rows[-1].y, marker="o", color=colour)
        xs += [r.x for r in rows]
        ys += [r.y for r in rows]
    dynamic = result.mode_rows("dynamic")
    start = world.start
    cos, sin = math.cos(start.theta), math.sin(start.theta)
    paths.plot([start.x + r.odom_x * cos - r.odom_y * sin for r in dynamic],
               [start.y + r.odom_x * sin + r.odom_y * cos for r in dynamic],
               color=MODE_STYLES["dynamic"][0], linestyle=":", linewidth=1.5,
               label="dynamic (odometry)")
    paths.plot(start.x, start.y, marker="s", color="black", label="start")
    _zoom(paths, xs, ys)
    paths.set_aspect("equal", adjustable="box")
    paths.set(xlabel="x (m, map frame)", ylabel="y (m)", title=f"Paths in {world.name}")
    paths.grid(alpha=0.3)
    paths.legend(loc="best", fontsize=9)

    for axes, column, label in ((linear, "v", "v (m/s)"), (angular, "omega", "ω (rad/s)")):
        kinematic = result.mode_rows("kinematic")
        own_commands = any(r.cmd_omega != k.cmd_omega
                           for r, k in zip(dynamic, kinematic, strict=True))  # a PID's
        axes.step([r.t_s for r in kinematic], [getattr(r, f"cmd_{column}") for r in kinematic],
                  where="pre", color="black", linestyle="--", linewidth=1.2,
                  label="commanded (kinematic)" if own_commands else "commanded")
        if own_commands:
            axes.step([r.t_s for r in dynamic], [getattr(r, f"cmd_{column}") for r in dynamic],
                      where="pre", color="0.5", linestyle="--", linewidth=1.2,
                      label="commanded (dynamic)")
        for mode in MODES_COMPARED:
            rows = result.mode_rows(mode)
            colour, style = MODE_STYLES[mode]
            axes.plot([r.t_s for r in rows], [getattr(r, column) for r in rows], color=colour,
                      linestyle=style, linewidth=1.8, label=mode)
        _mark_segments(axes, segments)
        axes.set_ylabel(label)
        axes.grid(alpha=0.3)
        axes.legend(loc="best", fontsize=9)
    linear.set_title("Velocity response: commanded vs each mode (true velocity)")
    last = angular
    if controller is not None:
        last = figure.add_subplot(grid[2, 1], sharex=linear)
        _heading_panel(last, result, world, segments, controller)
    last.set_xlabel("t (s)")
    figure.savefig(path, format=path.suffix.lstrip(".") or "png", dpi=FIGURE_DPI)
    return path


def _heading_panel(axes: Any, result: Comparison, world: World, segments: Sequence[Segment],
                   controller: HeadingController) -> None:
    """Each mode's heading the PID measured (odometry or true, from spawn) and its setpoint."""
    setpoint_deg = math.degrees(controller.setpoint_rad)
    for mode in MODES_COMPARED:
        rows = result.mode_rows(mode)
        colour, style = MODE_STYLES[mode]
        headings = [r.odom_theta if controller.feedback == "odometry"
                    else r.theta - world.start.theta for r in rows]
        axes.plot([r.t_s for r in rows], _unwrapped_deg(headings), color=colour,
                  linestyle=style, linewidth=1.8, label=f"{mode} ({controller.feedback})")
    axes.axhline(setpoint_deg, color="tab:red", linestyle="--", linewidth=1.2,
                 label=f"setpoint {setpoint_deg:g}°")
    _mark_segments(axes, segments)
    axes.set_ylabel("θ (°)")
    axes.set_title("Heading: the PID's measurement and its setpoint", fontsize=10)
    axes.grid(alpha=0.3)
    axes.legend(loc="best", fontsize=9)


def _unwrapped_deg(angles_rad: Sequence[float]) -> list[float]:
    """Angles in degrees without ±180° jumps (each within half a turn of the one before)."""
    out: list[float] = []
    for angle in angles_rad:
        deg = math.degrees(angle)
        if out:
            deg = out[-1] + (deg - out[-1] + 180.0) % 360.0 - 180.0
        out.append(deg)
    return out


def _zoom(axes: Any, xs: Sequence[float], ys: Sequence[float]) -> None:
    """Frame the paths with a margin; walls out of view are clipped."""
    margin_m = 0.3
    span = max(max(xs) - min(xs), max(ys) - min(ys), 1.0)
    cx, cy = (max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2
    half = span / 2 + margin_m
    axes.set_xlim(cx - half, cx + half)
    axes.set_ylim(cy - half, cy + half)


def _mark_segments(axes: Any, segments: Sequence[Segment]) -> None:
    """Thin vertical lines at segment starts, each segment numbered; payload changes labelled."""
    t = 0.0
    for index, segment in enumerate(segments, start=1):
        if t > 0.0:
            axes.axvline(t, color="0.8", linewidth=0.8, zorder=0)
        axes.annotate(f"{index}", (t, 0.0), xycoords=("data", "axes fraction"),
                      xytext=(3, 3), textcoords="offset points", color="0.45", fontsize=7)
        if segment.mass_kg is not None or segment.inertia_kg_m2 is not None:
            axes.axvline(t, color="tab:red", linewidth=1.0, zorder=0)
            axes.annotate("payload", (t, 1.0), xycoords=("data", "axes fraction"),
                          xytext=(3, -12), textcoords="offset points", color="tab:red",
                          fontsize=8)
        t += max(1, round(segment.duration_s / TICK_PERIOD_S)) * TICK_PERIOD_S
